"""What importing ibik_pin and running `ibik --help` load and change, each in a fresh interpreter:
the help needs no plotting, synthetic data or experiment code, and only the `ibik` command (not a
program importing the library) sets OpenBLAS's thread count."""

from __future__ import annotations

import json
import os
import subprocess
import sys

import pytest

# Modules `ibik --help` must not load: plotting, the tracking pipeline and what it writes, the
# demo's synthetic data, the paper's experiments, Dask.
HEAVY_PREFIXES = ("matplotlib", "ibik_pin.synthetic", "ibik_pin.app.demo", "ibik_pin.app.track", "ibik_pin.app.outputs",
                  "ibik_pin.tracking", "ibik_pin.readahead", "ibik_pin.viz", "experiments", "paper", "dask",
                  "distributed")


def run_python(code: str) -> str:
    """The last line printed by `code` in a fresh interpreter whose environment lacks
    OPENBLAS_NUM_THREADS (the tests' conftest sets it for this process)."""
    environment = {name: value for name, value in os.environ.items() if name != "OPENBLAS_NUM_THREADS"}
    completed = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, env=environment,
                               timeout=60, check=True)
    return completed.stdout.strip().splitlines()[-1]


@pytest.mark.parametrize("command", [["--help"], ["track", "--help"], ["batch", "--help"], ["demo", "--help"]])
def test_help_loads_no_plotting_synthetic_data_tracking_or_experiment_code(command):
    code = (
        "import json, sys\n"
        "from ibik_pin.cli import main\n"
        "try:\n"
        f"    main({command!r})\n"
        "except SystemExit:\n"
        "    pass\n"
        "print(json.dumps(sorted(sys.modules)))\n"
    )

    modules = json.loads(run_python(code))

    assert "ibik_pin.cli" in modules  # the check below can fail: the probe did load the CLI
    assert [name for name in modules if name.startswith(HEAVY_PREFIXES)] == []


def test_importing_the_library_leaves_the_environment_alone():
    # Some dependencies change the environment on import (proxsuite sets KMP_DUPLICATE_LIB_OK, cv2
    # LD_LIBRARY_PATH): they are loaded before the snapshot, so that only the package is judged.
    code = (
        "import os, cv2, numpy, pinocchio, proxsuite, scipy\n"
        "before = dict(os.environ)\n"
        "import ibik_pin, ibik_pin.cli, ibik_pin.solvers\n"
        "print(dict(os.environ) == before, os.environ.get('OPENBLAS_NUM_THREADS'))\n"
    )

    assert run_python(code) == "True None"


def test_the_ibik_command_runs_openblas_on_one_thread_unless_the_user_says_otherwise():
    as_command = "import sys\nsys.argv[0] = '/usr/local/bin/ibik'\n"
    probe = "import ibik_pin.cli, os\nprint(os.environ.get('OPENBLAS_NUM_THREADS'))\n"

    assert run_python(as_command + probe) == "1"
    assert run_python(as_command + "import os\nos.environ['OPENBLAS_NUM_THREADS'] = '3'\n" + probe) == "3"


def test_the_criterion_choices_of_the_cli_are_the_trackers():
    from ibik_pin.cli import build_parser
    from ibik_pin.tracking.stack import CRITERIA

    track = build_parser()._subparsers._group_actions[0].choices["track"]
    criterion = next(action for action in track._actions if action.dest == "criterion")
    assert tuple(criterion.choices) == CRITERIA

"""The package as a user gets it: the wheel built, installed into a fresh venv, used from elsewhere.

An editable install hides what a wheel leaves out (the bundled data, the URDFs installed as
ibik_pin.models, the replay's HTML template, a module missing from the package list). Here the
wheel is built from a copy of the files it is made of (so no build/ or egg-info lands in the working
tree, and no stale build/ folder adds modules that are gone), installed with its dependencies from the
package index (pip's cache makes that quick after the first run) into a venv of its own, and run
from a directory outside the repository: the README's Python example, extracted from the README so
the two cannot drift, and `ibik demo`.

Slow (about a minute with a warm pip cache): deselect locally with ``-m "not slow"``; CI runs it.
"""

from __future__ import annotations

import ast
import os
import re
import shutil
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from tests.paths import REPOSITORY

if sys.version_info >= (3, 11):
    import tomllib
else:  # pragma: no cover - tomli is a dependency below Python 3.11
    import tomli as tomllib

pytestmark = pytest.mark.slow

README = REPOSITORY / "README.md"
EXAMPLE_HEADING = "## Use from Python"


def readme_example() -> tuple[str, str]:
    """The README's Python example and the output its text says it prints.

    Returns:
        (code, printed): the first ```python block under EXAMPLE_HEADING, and the text between
        backquotes after "prints" in the paragraph before it.
    """
    text = README.read_text(encoding="utf-8")
    section = text.split(EXAMPLE_HEADING, 1)[1].split("\n## ", 1)[0]
    code = re.search(r"```python\n(.*?)```", section, re.DOTALL)
    printed = re.search(r"prints `([^`]*)`", section)
    if code is None or printed is None:
        pytest.fail(f"README.md: expected a ```python block and 'prints `...`' under {EXAMPLE_HEADING!r}")
    return code.group(1), printed.group(1)


def parse_example_output(line: str) -> tuple[list[str], np.ndarray]:
    """(level statuses, q) from the example's line, e.g. "['solved', 'solved'] [ 0.905 -0.711]"."""
    match = re.fullmatch(r"(\[.*?\])\s+\[([^\]]*)\]", line.strip())
    if match is None:
        pytest.fail(f"expected '[statuses] [q values]', found {line!r}")
    return ast.literal_eval(match.group(1)), np.array(match.group(2).split(), dtype=float)


def wheel_sources(destination: Path) -> Path:
    """Copy what setuptools reads to build the wheel (pyproject, readme, package folders) to destination."""
    pyproject = tomllib.loads((REPOSITORY / "pyproject.toml").read_text(encoding="utf-8"))
    folders = {"ibik_pin", *pyproject["tool"]["setuptools"].get("package-dir", {}).values()}
    ignore = shutil.ignore_patterns("__pycache__", "*.pyc")
    for folder in sorted(folders):
        shutil.copytree(REPOSITORY / folder, destination / folder, ignore=ignore)
    for name in ("pyproject.toml", pyproject["project"]["readme"]):
        shutil.copy2(REPOSITORY / name, destination / name)
    return destination


def run(command: list[str], cwd: Path, timeout: float) -> subprocess.CompletedProcess:
    """Run a command; on a non-zero exit fail the test with its output."""
    # Neither the repository nor the test venv may leak in through the environment.
    environment = {key: value for key, value in os.environ.items() if key not in ("PYTHONPATH", "VIRTUAL_ENV")}
    environment["MPLBACKEND"] = "Agg"
    result = subprocess.run(command, cwd=cwd, env=environment, capture_output=True, text=True, timeout=timeout)
    if result.returncode != 0:
        pytest.fail(
            f"{' '.join(map(str, command))} exited with {result.returncode}\n"
            f"stdout:\n{result.stdout[-4000:]}\nstderr:\n{result.stderr[-4000:]}"
        )
    return result


@pytest.fixture(scope="module")
def installed(tmp_path_factory) -> tuple[Path, Path]:
    """(python of a fresh venv holding the installed wheel, a working directory outside the repository)."""
    root = tmp_path_factory.mktemp("wheel")
    source = wheel_sources(root / "source")
    run([sys.executable, "-m", "pip", "wheel", "--no-deps", "-q", "-w", str(root / "dist"), str(source)],
        cwd=root, timeout=600)
    wheels = sorted((root / "dist").glob("ibik_pin-*.whl"))
    assert len(wheels) == 1, f"expected one ibik_pin wheel, found {wheels}"
    run([sys.executable, "-m", "venv", str(root / "venv")], cwd=root, timeout=300)
    python = root / "venv" / "bin" / "python"
    run([str(python), "-m", "pip", "install", "-q", str(wheels[0])], cwd=root, timeout=1800)
    elsewhere = root / "elsewhere"
    elsewhere.mkdir()
    return python, elsewhere


def test_the_wheel_is_imported_from_the_venv_not_from_the_repository(installed):
    python, elsewhere = installed
    result = run([str(python), "-c", "import ibik_pin; print(ibik_pin.__file__)"], cwd=elsewhere, timeout=120)
    location = Path(result.stdout.strip()).resolve()
    assert python.parent.parent.resolve() in location.parents
    assert REPOSITORY not in location.parents


def test_the_readme_example_prints_what_the_readme_says(installed):
    python, elsewhere = installed
    code, printed = readme_example()
    script = elsewhere / "readme_example.py"
    script.write_text(code, encoding="utf-8")
    result = run([str(python), str(script)], cwd=elsewhere, timeout=300)
    lines = result.stdout.strip().splitlines()
    assert lines, "the README example printed nothing"
    statuses, q = parse_example_output(lines[-1])
    expected_statuses, expected_q = parse_example_output(printed)
    assert statuses == expected_statuses
    # The README shows q rounded to 3 decimals; allow one unit of that rounding across platforms.
    np.testing.assert_allclose(q, expected_q, rtol=0.0, atol=1.5e-3)


def test_ibik_demo_runs_from_the_installed_command(installed):
    python, elsewhere = installed
    ibik = python.parent / "ibik"
    out = elsewhere / "demo"
    result = run([str(ibik), "demo", "--out", str(out)], cwd=elsewhere, timeout=900)
    assert "IBIK" in result.stdout and "PIK" in result.stdout
    for variant in ("ibik", "pik"):
        assert (out / variant / "joints.trc").stat().st_size > 0
        assert (out / variant / "report.json").stat().st_size > 0

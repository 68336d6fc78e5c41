"""The README as a user reads it: its Python examples run, its commands parse, and it stays short.

Each ```python block runs in a fresh interpreter in a temporary folder; the `ibik` command lines of
its ```bash blocks are parsed by the CLI's own argparse parser (which knows every subcommand and
option, and checks choices), and every `--option` the README names in backquotes is one that
`ibik track` or `ibik batch` accepts.
"""

from __future__ import annotations

import argparse
import os
import re
import shlex
import subprocess
import sys

import pytest

from ibik_pin.cli import build_parser
from tests.paths import REPOSITORY

README = REPOSITORY / "README.md"
MAX_LINES = 250


def readme_text() -> str:
    return README.read_text(encoding="utf-8")


def code_blocks(language: str) -> list[str]:
    """The README's fenced blocks of one language, in order."""
    return re.findall(rf"```{language}\n(.*?)```", readme_text(), re.DOTALL)


def ibik_command_lines() -> list[list[str]]:
    """The arguments after `ibik` of every command in the README's bash blocks (continuations joined,
    `&&` chains split)."""
    commands = []
    for block in code_blocks("bash"):
        for line in block.replace("\\\n", " ").splitlines():
            for part in line.split("&&"):
                words = shlex.split(part, comments=True)
                if words and (words[0] == "ibik" or words[0].endswith("/ibik")):
                    commands.append(words[1:])
    return commands


def option_names(subcommand: str) -> set[str]:
    """Every option string a subcommand's parser accepts."""
    parser = build_parser()
    subparsers = next(action for action in parser._actions if isinstance(action, argparse._SubParsersAction))
    return {option for action in subparsers.choices[subcommand]._actions for option in action.option_strings}


def test_the_readme_is_at_most_250_lines():
    assert len(readme_text().splitlines()) <= MAX_LINES


def test_the_readme_starts_with_the_install_and_demo_command_and_the_test_command():
    first_block = readme_text().split("```bash\n", 1)[1].split("```", 1)[0].splitlines()
    assert first_block[0] == ("python3 -m venv .venv && .venv/bin/pip install -q -e . "
                              "&& .venv/bin/ibik demo --out out/demo")
    assert first_block[1] == ("python3 -m venv .venv && .venv/bin/pip install -q -e '.[test]' "
                              "&& .venv/bin/python -m pytest -q")


def test_ci_runs_the_readme_s_test_command():
    test_command = readme_text().split("```bash\n", 1)[1].splitlines()[1]
    assert test_command in (REPOSITORY / ".ci" / "run").read_text(encoding="utf-8")


def test_the_readme_shows_ibik_commands():
    assert {words[0] for words in ibik_command_lines()} >= {"demo", "track", "calibrate"}


@pytest.mark.parametrize("arguments", ibik_command_lines(), ids=" ".join)
def test_every_ibik_command_in_the_readme_parses(arguments):
    parsed = build_parser().parse_args(arguments)
    assert parsed.command == arguments[0]


def test_every_option_the_readme_names_is_an_option_of_ibik():
    known = option_names("track") | option_names("batch") | option_names("calibrate") | option_names("demo")
    named = set(re.findall(r"`(--[a-z][a-z0-9-]*)", readme_text()))
    # pip's own option in the install commands is not ibik's.
    unknown = sorted(named - known - {"--no-deps"})
    assert not unknown, f"README.md names options that ibik does not have: {unknown}"


@pytest.mark.parametrize("index", range(len(code_blocks("python"))))
def test_the_readme_s_python_example_runs(index, tmp_path):
    code = code_blocks("python")[index]
    script = tmp_path / f"readme_example_{index}.py"
    script.write_text(code, encoding="utf-8")
    result = subprocess.run([sys.executable, str(script)], cwd=tmp_path, capture_output=True, text=True,
                            timeout=120, env={**os.environ, "MPLBACKEND": "Agg"})
    assert result.returncode == 0, f"README example {index} failed:\n{result.stderr[-4000:]}"
    assert result.stdout.strip(), f"README example {index} printed nothing"


def test_the_fig7_example_prints_what_the_readme_says(tmp_path):
    section = readme_text().split("## Use from Python", 1)[1]
    printed = re.search(r"prints `([^`]*)`", section)
    assert printed is not None, "expected 'prints `...`' under '## Use from Python'"
    script = tmp_path / "fig7.py"
    script.write_text(code_blocks("python")[0], encoding="utf-8")
    result = subprocess.run([sys.executable, str(script)], cwd=tmp_path, capture_output=True, text=True,
                            timeout=120, check=True)
    statuses, values = printed.group(1).rsplit("] [", 1)
    line = result.stdout.strip().splitlines()[-1]
    assert line.startswith(statuses + "]")
    shown = [float(value) for value in values.rstrip("]").split()]
    got = [float(value) for value in line.rsplit("[", 1)[1].rstrip("]").split()]
    assert got == pytest.approx(shown, abs=1.5e-3)


def test_the_readme_s_results_table_is_the_one_in_docs_results_md():
    text = readme_text()
    section = text.split("## Results", 1)[1].split("\n## ", 1)[0]
    figures = re.findall(r"\| (\d+\.\d) \| (\d+\.\d) \|", section)
    assert len(figures) >= 4, "expected a results table of PIK and IBIK figures under '## Results'"
    results = (REPOSITORY / "docs" / "results.md").read_text(encoding="utf-8")
    missing = [figure for pair in figures for figure in pair if f" {figure} " not in results]
    assert not missing, f"README.md's results table has figures docs/results.md does not: {missing}"

"""The package's layout rules, checked on its source so that they hold from now on."""

from __future__ import annotations

import ast
from pathlib import Path

from tests.paths import REPOSITORY

PACKAGE = REPOSITORY / "ibik_pin"
MAX_LINES = 400
# A module may exceed MAX_LINES only if its docstring says why, in a sentence starting so.
LONG_MODULE_REASON = "This module is long because"


def long_modules_without_a_reason(package: Path = PACKAGE) -> dict[str, int]:
    """Modules under package over MAX_LINES whose docstring gives no reason: relative path -> lines."""
    offenders = {}
    for path in sorted(package.rglob("*.py")):
        text = path.read_text(encoding="utf-8")
        lines = len(text.splitlines())
        if lines <= MAX_LINES:
            continue
        docstring = ast.get_docstring(ast.parse(text, filename=str(path))) or ""
        if LONG_MODULE_REASON not in " ".join(docstring.split()):  # the sentence may wrap
            offenders[str(path.relative_to(package.parent))] = lines
    return offenders


def test_no_module_exceeds_400_lines_unless_its_docstring_says_why():
    offenders = long_modules_without_a_reason()
    assert not offenders, (
        f"modules over {MAX_LINES} lines: {offenders}; split them by concept, or say why in the module "
        f"docstring with a sentence starting {LONG_MODULE_REASON!r}"
    )


def test_the_length_rule_sees_every_module_of_the_package():
    modules = list(PACKAGE.rglob("*.py"))
    # The package's own sub-packages are all walked (a wrong root would pass the rule vacuously).
    assert {path.parent.name for path in modules} >= {"ibik_pin", "io", "solvers", "tasks", "vision"}
    assert len(modules) > 30


def test_a_long_module_passes_only_with_its_reason_in_the_docstring(tmp_path):
    package = tmp_path / "package"
    package.mkdir()
    body = "x = 1\n" * MAX_LINES
    (package / "short.py").write_text('"""Short."""\n' + "x = 1\n" * (MAX_LINES - 1))
    (package / "long.py").write_text('"""Long."""\n' + body)
    (package / "explained.py").write_text(
        '"""A reader.\n\nThis module is long\nbecause one format needs one parser."""\n' + body
    )
    (package / "reason_in_a_comment.py").write_text(
        '"""Long."""\n# This module is long because it says so in a comment only.\n' + body
    )
    assert long_modules_without_a_reason(package) == {
        "package/long.py": MAX_LINES + 1,
        "package/reason_in_a_comment.py": MAX_LINES + 2,
    }

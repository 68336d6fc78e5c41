"""The package's layout rules, checked on its source so that they hold from now on."""

from __future__ import annotations

import ast

from tests.paths import REPOSITORY

PACKAGE = REPOSITORY / "ibik_pin"
MAX_LINES = 400
# A module may exceed MAX_LINES only if its docstring says why, in a sentence starting so.
LONG_MODULE_REASON = "This module is long because"


def long_modules_without_a_reason() -> dict[str, int]:
    """Modules of ibik_pin over MAX_LINES whose docstring gives no reason: relative path -> lines."""
    offenders = {}
    for path in sorted(PACKAGE.rglob("*.py")):
        text = path.read_text(encoding="utf-8")
        lines = len(text.splitlines())
        if lines <= MAX_LINES:
            continue
        docstring = ast.get_docstring(ast.parse(text, filename=str(path))) or ""
        if LONG_MODULE_REASON not in " ".join(docstring.split()):  # the sentence may wrap
            offenders[str(path.relative_to(REPOSITORY))] = lines
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

"""The package's layers, read from its source with `ast`: no import cycle (imports inside functions
and under TYPE_CHECKING included), no layer importing one above it, the library never importing the
experiments, and the vision modules computing on arrays without opening files."""

from __future__ import annotations

import ast
from collections.abc import Iterator
from pathlib import Path

import pytest

import ibik_pin

PACKAGE = Path(ibik_pin.__file__).resolve().parent
EXPERIMENTS = PACKAGE.parent / "experiments"
# File-opening calls: builtins.open and Path.open, OpenCV's readers, numpy's loaders, Path's readers.
FILE_OPENING_CALLS = frozenset({"open", "imread", "imreadmulti", "VideoCapture", "load", "loadtxt", "genfromtxt",
                                "fromfile", "read_text", "read_bytes"})


def module_name(path: Path) -> str:
    parts = path.relative_to(PACKAGE.parent).with_suffix("").parts
    return ".".join(parts[:-1] if parts[-1] == "__init__" else parts)


def package_modules() -> dict[str, Path]:
    """Every module of ibik_pin by its dotted name (a package by its __init__.py)."""
    return {module_name(path): path for path in sorted(PACKAGE.rglob("*.py"))}


def imported_names(path: Path, name: str) -> Iterator[str]:
    """The dotted names of everything `path` (module `name`) imports, wherever in the file: for
    `from a import b`, a.b as well as a (b may be a module); relative forms resolved."""
    package = name if path.name == "__init__.py" else name.rpartition(".")[0]
    for node in ast.walk(ast.parse(path.read_text(encoding="utf-8"), str(path))):
        if isinstance(node, ast.Import):
            yield from (alias.name for alias in node.names)
        elif isinstance(node, ast.ImportFrom):
            if node.level:
                base = ".".join(package.split(".")[: len(package.split(".")) - node.level + 1])
                source = f"{base}.{node.module}" if node.module else base
            else:
                source = node.module or ""
            yield source
            yield from (f"{source}.{alias.name}" for alias in node.names)


def import_graph() -> dict[str, set[str]]:
    """Module -> the package modules it imports (the longest known prefix of each imported name)."""
    modules = package_modules()
    graph: dict[str, set[str]] = {}
    for name, path in modules.items():
        targets = set()
        for imported in imported_names(path, name):
            parts = imported.split(".")
            known = next((".".join(parts[:n]) for n in range(len(parts), 0, -1) if ".".join(parts[:n]) in modules),
                         None)
            if known is not None and known != name:
                targets.add(known)
        graph[name] = targets
    return graph


def find_cycle(graph: dict[str, set[str]]) -> list[str] | None:
    """One import cycle as [a, b, ..., a], or None (depth-first search, colours on the stack)."""
    state: dict[str, str] = {}  # "open" while on the path, "done" once every successor is explored
    path: list[str] = []

    def visit(module: str) -> list[str] | None:
        state[module] = "open"
        path.append(module)
        for successor in sorted(graph.get(module, ())):
            if state.get(successor) == "open":
                return path[path.index(successor):] + [successor]
            if successor not in state and (cycle := visit(successor)) is not None:
                return cycle
        path.pop()
        state[module] = "done"
        return None

    for module in sorted(graph):
        if module not in state and (cycle := visit(module)) is not None:
            return cycle
    return None


def test_the_cycle_finder_names_a_cycle_and_passes_a_layered_graph():
    assert find_cycle({"a": {"b"}, "b": {"c"}, "c": {"a"}, "d": {"a"}}) == ["a", "b", "c", "a"]
    assert find_cycle({"a": {"b", "c"}, "b": {"c"}, "c": set()}) is None


def test_relative_and_function_level_imports_are_read(tmp_path):
    source = tmp_path / "ibik_pin" / "app" / "track.py"
    source.parent.mkdir(parents=True)
    source.write_text("from . import job\nfrom ..tracking.tracker import Tracker\n"
                      "def run():\n    import ibik_pin.human\n", encoding="utf-8")

    names = set(imported_names(source, "ibik_pin.app.track"))

    assert {"ibik_pin.app.job", "ibik_pin.tracking.tracker", "ibik_pin.human"} <= names


def test_the_package_has_no_import_cycle():
    cycle = find_cycle(import_graph())

    assert cycle is None, "import cycle: " + " -> ".join(cycle or [])


@pytest.mark.parametrize(("importers", "imported"), [
    (("ibik_pin",), ("ibik_pin.app", "ibik_pin.cli")),  # the application and the CLI sit on top
    (("ibik_pin.readahead",), ("ibik_pin.tracking",)),  # the read-ahead serves the tracker from below
])
def test_a_layer_never_imports_the_layers_above_it(importers, imported):
    above = ("ibik_pin.app", "ibik_pin.cli")
    offenders = sorted(f"{module} imports {target}" for module, targets in import_graph().items()
                       if module.startswith(importers) and not module.startswith(above)
                       for target in targets if target.startswith(imported))

    assert offenders == []


def test_the_library_never_imports_the_experiments():
    experiment_names = {"experiments"} | {path.stem for path in EXPERIMENTS.iterdir()
                                          if path.suffix == ".py" or (path / "__init__.py").is_file()}
    offenders = sorted(f"{name} imports {imported}" for name, path in package_modules().items()
                       for imported in imported_names(path, name) if imported.split(".")[0] in experiment_names)

    assert offenders == []


def vision_modules() -> list[tuple[str, Path]]:
    return [(name, path) for name, path in package_modules().items() if name.startswith("ibik_pin.vision")]


@pytest.mark.parametrize(("name", "path"), vision_modules(), ids=[name for name, _ in vision_modules()])
def test_vision_computes_on_arrays_and_opens_no_file(name, path):
    tree = ast.parse(path.read_text(encoding="utf-8"), str(path))
    called = [(node.lineno, node.func.id if isinstance(node.func, ast.Name) else getattr(node.func, "attr", None))
              for node in ast.walk(tree) if isinstance(node, ast.Call)]
    opening = [f"line {line}: {function}" for line, function in called if function in FILE_OPENING_CALLS]
    readers = sorted(imported for imported in imported_names(path, name) if imported.startswith("ibik_pin.io"))

    assert opening == [], f"{name} opens files"
    assert readers == [], f"{name} imports file readers"

"""Priority stacks as data: which tasks the tracker solves, in which order, strict or weighted.

A stack is a list of levels, highest priority first; each level holds tasks of four kinds:

- ``position``: keypoints to bring onto their targets (a list, or ``"present"``: every target of
  the TRC that no other level names), with a weight and a gain;
- ``image``: the image criterion (``"paper"`` or ``"two-way"``), the cameras it reads and its
  largest step [rad];
- ``posture``: stay near a reference, the neutral pose or the previous frame's solution;
- ``com``: the centre of mass over the feet (tasks.com), for balance studies.

A strict level (the default) is its own priority level. Consecutive levels with ``strict = false``
are weighted into one least-squares level, each task's rows scaled by the square root of its weight,
as Pink weighs every task of its one QP. An image criterion alone in its solver level is followed
along its gradient with the solver's step adaptation; sharing a level with other tasks, it becomes
one weighted row asking for a step of `step` along its gradient (tasks.criterion_step).

A top-level ``qp_solver = "NAME"`` picks the QP backend of the "qp" scheme (TrackingSettings.qp_solver).

Stacks are read from TOML (``Stack.from_toml``; the format is in the README, "Priority stacks",
and ibik_pin/data/default_stack.toml is the stack `ibik track` uses by default). Every error names
the file, the level and the key.
"""

from __future__ import annotations

import math
import sys
from collections.abc import Iterable, Mapping
from dataclasses import dataclass
from importlib import resources
from pathlib import Path
from typing import Any

from ibik_pin.exceptions import FileFormatError, InputError
from ibik_pin.io.files import read_text
from ibik_pin.solvers import available_qp_solvers

if sys.version_info >= (3, 11):
    import tomllib
else:  # pragma: no cover - exercised on Python 3.10 only
    import tomli as tomllib

__all__ = ["CRITERIA", "PRESENT", "Stack", "StackError", "StackLevel", "TaskSpec", "TASK_KINDS"]

CRITERIA = ("paper", "two-way")
TASK_KINDS = ("position", "image", "posture", "com")
PRESENT = "present"  # position keypoints: every target of the TRC that no other level names
POSTURE_REFERENCES = ("neutral", "previous")
# The keys each task kind takes, besides `kind`.
TASK_KEYS = {
    "position": ("keypoints", "weight", "gain"),
    "image": ("criterion", "views", "step", "weight"),
    "posture": ("reference", "weight", "gain"),
    "com": ("feet", "weight", "gain"),
}
LEVEL_KEYS = ("name", "strict", "tasks")
DEFAULT_STACK_FILE = "default_stack.toml"


class StackError(InputError):
    """A stack file or stack that cannot be used; the message names the file, the level and the key."""


@dataclass(frozen=True)
class TaskSpec:
    """One task of a level. None means "the tracker's setting" (TrackingSettings) or the kind's default.

    Attributes:
        kind: "position", "image", "posture" or "com".
        keypoints: position: the target keypoints, or None for "present" (every target of the TRC
            that no other level names).
        weight: weight of the task's rows in its level (position, com: 1; posture:
            TrackingSettings.posture_weight; image: 1, used only when it shares a level).
        gain: fraction of the error corrected per step, in (0, 1] (position, posture, com).
        criterion: image: "paper" or "two-way" (None: TrackingSettings.criterion).
        views: image: the camera names it reads (None: every camera in use).
        step: image: largest step [rad] (None: TrackingSettings.image_step).
        reference: posture: "neutral" or "previous" (the previous frame's solution).
        feet: com: keypoints whose mean the centre of mass stays over (None: tasks.com's default).
    """

    kind: str
    keypoints: tuple[str, ...] | None = None
    weight: float | None = None
    gain: float = 1.0
    criterion: str | None = None
    views: tuple[str, ...] | None = None
    step: float | None = None
    reference: str = "neutral"
    feet: tuple[str, ...] | None = None


@dataclass(frozen=True)
class StackLevel:
    """A priority level: its name (the report's key), its tasks, strict or weighted with its neighbours."""

    name: str
    tasks: tuple[TaskSpec, ...]
    strict: bool = True


@dataclass(frozen=True)
class Stack:
    """The ordered levels, highest priority first, and where they were read from (for messages)."""

    levels: tuple[StackLevel, ...]
    source: str = "<stack>"
    qp_solver: str | None = None  # the top-level key `qp_solver`: TrackingSettings.qp_solver's override

    @classmethod
    def from_toml(cls, path: str | Path) -> Stack:
        """Read and check a stack file.

        Raises:
            StackError: unreadable file, TOML syntax, an empty stack, an unknown task kind or key,
                a keypoint in two levels, a weight that is not positive, two image tasks, ...;
                the message names the file, the level and the key.
        """
        try:
            document = tomllib.loads(read_text(path, "stack"))
        except FileFormatError as error:
            raise StackError(str(error)) from None
        except tomllib.TOMLDecodeError as error:
            raise StackError(f"stack file {str(path)!r}: expected valid TOML, found a syntax error: {error}") from None
        return cls.from_dict(document, source=f"stack file {str(path)!r}")

    @classmethod
    def default(cls) -> Stack:
        """The stack `ibik track` uses without --stack (ibik_pin/data/default_stack.toml): 1 pelvis
        and legs, 2 the other targets (trunk, head, arms), 3 the image, 4 a light posture prior."""
        return cls.packaged(DEFAULT_STACK_FILE)

    @classmethod
    def packaged(cls, file_name: str) -> Stack:
        """A stack file shipped in ibik_pin/data."""
        with resources.as_file(resources.files("ibik_pin").joinpath("data").joinpath(file_name)) as path:
            return cls.from_toml(path)

    @classmethod
    def from_dict(cls, document: Mapping[str, Any], source: str = "<stack>") -> Stack:
        """A stack from parsed TOML: ``{"level": [{"name": ..., "strict": ..., "tasks": [{...}]}]}``,
        and optionally ``"qp_solver": NAME`` (the QP backend, one of available_qp_solvers())."""
        unknown = [key for key in document if key not in ("level", "qp_solver")]
        if unknown:
            raise StackError(f"{source}: key {unknown[0]!r}: unknown top-level key; a stack holds [[level]] "
                             "tables and optionally qp_solver")
        qp_solver = document.get("qp_solver")
        if qp_solver is not None and qp_solver not in available_qp_solvers():
            raise StackError(f"{source}: key 'qp_solver': expected one of {', '.join(available_qp_solvers())}, "
                             f"found {qp_solver!r}")
        levels = document.get("level", [])
        if not isinstance(levels, list) or not levels:
            raise StackError(f"{source}: key 'level': the stack is empty; expected at least one [[level]] table")
        parsed = tuple(_level(source, index, table) for index, table in enumerate(levels, start=1))
        stack = cls(parsed, source, qp_solver)
        stack._check()
        return stack

    def where(self, level_index: int, key: str, task_index: int | None = None) -> str:
        """"<source>: level N ("name"), task M: key 'key'" for messages (1-based indices)."""
        level = self.levels[level_index]
        task = f", task {task_index + 1}" if task_index is not None else ""
        return f"{self.source}: level {level_index + 1} ({level.name!r}){task}: key {key!r}"

    def tasks(self, kind: str) -> Iterable[tuple[int, int, TaskSpec]]:
        """(level index, task index, task) of every task of that kind, in stack order."""
        for level_index, level in enumerate(self.levels):
            for task_index, task in enumerate(level.tasks):
                if task.kind == kind:
                    yield level_index, task_index, task

    @property
    def image(self) -> TaskSpec | None:
        """The stack's image task, if any (a stack holds at most one)."""
        return next((task for _, _, task in self.tasks("image")), None)

    def check_names(self, keypoints: Iterable[str], cameras: Iterable[str] | None = None) -> None:
        """Check the keypoint names against a body's keypoints, and the image's views against the
        cameras in use (None: not checked).

        Raises:
            StackError: an unknown keypoint or camera, naming the level and key.
        """
        known = list(keypoints)
        for kind, key in (("position", "keypoints"), ("com", "feet")):
            for level_index, task_index, task in self.tasks(kind):
                names = task.keypoints if kind == "position" else task.feet
                unknown = [name for name in names or () if name not in known]
                if unknown:
                    raise StackError(f"{self.where(level_index, key, task_index)}: unknown keypoint {unknown[0]!r}; "
                                     f"known keypoints: {', '.join(known)}")
        if cameras is None:
            return
        cameras = list(cameras)
        for level_index, task_index, task in self.tasks("image"):
            missing = [name for name in task.views or () if name not in cameras]
            if missing:
                raise StackError(f"{self.where(level_index, 'views', task_index)}: camera {missing[0]!r} is not "
                                 f"among the cameras in use ({', '.join(cameras) or 'none'})")

    def _check(self) -> None:
        """What a stack must hold whatever the body: distinct level names, each keypoint in one
        level, one "present" position task, one image task."""
        names: dict[str, int] = {}
        for index, level in enumerate(self.levels):
            if level.name in names:
                raise StackError(f"{self.where(index, 'name')}: the name of level {names[level.name] + 1} too; "
                                 "level names must differ (they key the report)")
            names[level.name] = index
        claimed: dict[str, int] = {}
        present: int | None = None
        for level_index, task_index, task in self.tasks("position"):
            if task.keypoints is None:
                if present is not None:
                    raise StackError(f"{self.where(level_index, 'keypoints', task_index)}: \"{PRESENT}\" in "
                                     f"level {present + 1} too; only one level may take the remaining targets")
                present = level_index
            for name in task.keypoints or ():
                if name in claimed:
                    other = "this level" if claimed[name] == level_index else f"level {claimed[name] + 1}"
                    raise StackError(f"{self.where(level_index, 'keypoints', task_index)}: keypoint {name!r} is "
                                     f"in {other} too; a keypoint may be in one level only")
                claimed[name] = level_index
        images = list(self.tasks("image"))
        if len(images) > 1:
            level_index, task_index, _ = images[1]
            raise StackError(f"{self.where(level_index, 'kind', task_index)}: a second image task; a stack "
                             f"holds one (level {images[0][0] + 1} has it)")


def _level(source: str, index: int, table: Any) -> StackLevel:
    where = f"{source}: level {index}"
    if not isinstance(table, dict):
        raise StackError(f"{where}: expected a [[level]] table, found {table!r}")
    name = table.get("name", f"level {index}")
    if not isinstance(name, str) or not name.strip():
        raise StackError(f"{where}: key 'name': expected a non-empty string, found {name!r}")
    where = f"{where} ({name!r})"
    unknown = [key for key in table if key not in LEVEL_KEYS]
    if unknown:
        raise StackError(f"{where}: key {unknown[0]!r}: unknown level key; expected {', '.join(LEVEL_KEYS)}")
    strict = table.get("strict", True)
    if not isinstance(strict, bool):
        raise StackError(f"{where}: key 'strict': expected true or false, found {strict!r}")
    tasks = table.get("tasks")
    if not isinstance(tasks, list) or not tasks:
        raise StackError(f"{where}: key 'tasks': expected at least one [[level.tasks]] table")
    return StackLevel(name, tuple(_task(f"{where}, task {number}", task)
                                  for number, task in enumerate(tasks, start=1)), strict)


def _task(where: str, table: Any) -> TaskSpec:
    if not isinstance(table, dict):
        raise StackError(f"{where}: expected a [[level.tasks]] table, found {table!r}")
    kind = table.get("kind")
    if kind not in TASK_KINDS:
        raise StackError(f"{where}: key 'kind': unknown task kind {kind!r}; expected one of {', '.join(TASK_KINDS)}")
    unknown = [key for key in table if key != "kind" and key not in TASK_KEYS[kind]]
    if unknown:
        raise StackError(f"{where}: key {unknown[0]!r}: not a key of a {kind} task; expected "
                         f"{', '.join(TASK_KEYS[kind])}")
    values: dict[str, Any] = {"kind": kind}
    if "weight" in table:
        values["weight"] = _positive(where, "weight", table["weight"])
    if "gain" in table:
        values["gain"] = _positive(where, "gain", table["gain"])
        if values["gain"] > 1.0:
            raise StackError(f"{where}: key 'gain': expected a number in (0, 1], found {table['gain']!r}")
    if "step" in table:
        values["step"] = _positive(where, "step", table["step"])
    if kind == "position" and table.get("keypoints", PRESENT) != PRESENT:
        values["keypoints"] = _names(where, "keypoints", table["keypoints"], f'or "{PRESENT}"')
    for key in ("views", "feet"):
        if key in table:
            values[key] = _names(where, key, table[key])
    if "criterion" in table:
        if table["criterion"] not in CRITERIA:
            raise StackError(f"{where}: key 'criterion': expected one of {', '.join(CRITERIA)}, "
                             f"found {table['criterion']!r}")
        values["criterion"] = table["criterion"]
    if "reference" in table:
        if table["reference"] not in POSTURE_REFERENCES:
            raise StackError(f"{where}: key 'reference': expected one of {', '.join(POSTURE_REFERENCES)}, "
                             f"found {table['reference']!r}")
        values["reference"] = table["reference"]
    return TaskSpec(**values)


def _positive(where: str, key: str, value: Any) -> float:
    if isinstance(value, bool) or not isinstance(value, (int, float)) or not math.isfinite(value) or value <= 0:
        raise StackError(f"{where}: key {key!r}: expected a positive number, found {value!r}")
    return float(value)


def _names(where: str, key: str, value: Any, alternative: str = "") -> tuple[str, ...]:
    if not isinstance(value, list) or not value or not all(isinstance(item, str) for item in value):
        raise StackError(f"{where}: key {key!r}: expected a non-empty list of names{' ' + alternative}, "
                         f"found {value!r}")
    duplicates = [item for index, item in enumerate(value) if item in value[:index]]
    if duplicates:
        raise StackError(f"{where}: key {key!r}: {duplicates[0]!r} is listed twice")
    return tuple(value)


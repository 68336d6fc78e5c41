"""The levels a solver is given, checked once per solve: a sequence of levels, each a sequence of
tasks (tasks.base.Task or GradientTask). A flat list of tasks is the usual slip; it is refused by
name rather than failing deep in a step."""

from __future__ import annotations

from collections.abc import Sequence

from ibik_pin.exceptions import InputError
from ibik_pin.tasks.base import GradientTask, Task

__all__ = ["checked_levels"]


def checked_levels(levels: object) -> Sequence[Sequence[Task | GradientTask]]:
    """`levels` itself once it is a sequence of sequences of tasks.

    Raises:
        InputError: `levels` is not a list or tuple; a level is a task itself (levels not nested:
            write [[task_a], [task_b]] for two levels, [[task_a, task_b]] for one), or not a list or
            tuple; an item of a level is not a task.
    """
    if not isinstance(levels, (list, tuple)):
        raise InputError(f"levels: expected a list of levels (each a list of tasks), found {type(levels).__name__}")
    for index, level in enumerate(levels):
        if isinstance(level, (Task, GradientTask)):
            raise InputError(f"levels[{index}]: expected a level (a list of tasks), found the task "
                             f"{type(level).__name__} itself; nest them: [[task_a], [task_b]] is two levels, "
                             "[[task_a, task_b]] one")
        if not isinstance(level, (list, tuple)):
            raise InputError(f"levels[{index}]: expected a list of tasks, found {type(level).__name__}")
        for position, task in enumerate(level):
            if not isinstance(task, (Task, GradientTask)):
                raise InputError(f"levels[{index}][{position}]: expected a task (ibik_pin.tasks), found "
                                 f"{type(task).__name__}")
    return levels

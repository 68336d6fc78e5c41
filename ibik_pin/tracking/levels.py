"""A stack's task objects, and the priority levels handed to the solver for one sequence.

`StackTasks` creates the tasks a stack (tracking.stack) describes, once per tracker: the position
task of every target keypoint (with its level's weight and gain), the posture and centre-of-mass
tasks, and the image criterion as the tracker built it. `StackTasks.plan` then lays them out for
a sequence's target names: one solver level per strict stack level, one per run of consecutive
weighted (non-strict) levels.
"""

from __future__ import annotations

import warnings
from collections.abc import Callable, Sequence
from dataclasses import dataclass

import numpy as np

from ibik_pin.configuration import Configuration
from ibik_pin.exceptions import IbikWarning
from ibik_pin.model import BodyModel
from ibik_pin.solvers import Solver
from ibik_pin.tasks import FramePositionTask, PostureTask
from ibik_pin.tasks.base import GradientTask, Task
from ibik_pin.tasks.com import CenterOfMassTask
from ibik_pin.tasks.criterion_step import CriterionStepTask
from ibik_pin.tracking.stack import Stack, TaskSpec

__all__ = ["StackPlan", "StackTasks"]

AnyTask = Task | GradientTask


@dataclass
class StackPlan:
    """The stack laid out for one sequence.

    Attributes:
        names: the stack levels solved, highest first (an image-only level is left out when the
            image is not used).
        level_tasks: per stack level, its tasks as the solver sees them (an image criterion that
            shares its solver level appears as its CriterionStepTask row).
        solver_levels: the levels handed to the solver, highest first.
        solver_index: per stack level, the solver level that holds it.
        image_level: the solver level holding the image criterion, or None.
        image_criterion: the image criterion followed (None without the image).
    """

    names: list[str]
    level_tasks: list[list[AnyTask]]
    solver_levels: list[list[AnyTask]]
    solver_index: list[int]
    image_level: int | None
    image_criterion: GradientTask | None

    def blind_levels(self) -> list[list[AnyTask]]:
        """The solver levels without the image: its level dropped when it is alone there, its row
        removed when it shares a level."""
        if self.image_level is None:
            return list(self.solver_levels)
        blind = []
        for index, level in enumerate(self.solver_levels):
            if index != self.image_level:
                blind.append(level)
            elif len(level) > 1:
                blind.append([task for task in level if not isinstance(task, CriterionStepTask)])
        return blind

    def with_level_above_image(self, tasks: Sequence[AnyTask]) -> list[Sequence[AnyTask]]:
        """The solver levels with one more level just above the image's (at the end without it)."""
        at = len(self.solver_levels) if self.image_level is None else self.image_level
        return [*self.solver_levels[:at], tasks, *self.solver_levels[at:]]

    def report_index(self, solver: Solver) -> list[int | None]:
        """Per stack level, the index of its level among the solver's reports (None: the scheme
        does not solve it). The ik and liegeois schemes regroup the levels (Solver.arrange)."""
        arranged = solver.arrange(self.solver_levels)
        if arranged is self.solver_levels:
            return list(self.solver_index)
        indices: list[int | None] = []
        for tasks in self.level_tasks:
            found = [index for index, level in enumerate(arranged) if any(task in level for task in tasks)]
            indices.append(found[0] if found else None)
        return indices


class StackTasks:
    """The task objects of a stack, for one body; target tasks are created on first use.

    Args:
        stack: the stack.
        body: the body model.
        image_criterion: the image level's criterion (None: the image is not used).
        posture_weight: the weight of a posture task that does not give one.
        driven_joints: keypoint name -> the joints its position task may move (None: all).
    """

    def __init__(self, stack: Stack, body: BodyModel, image_criterion: GradientTask | None, posture_weight: float,
                 driven_joints: Callable[[str], np.ndarray | None]) -> None:
        self.stack = stack
        self.body = body
        self.image_criterion = image_criterion
        self._driven_joints = driven_joints
        self.target_tasks: dict[str, FramePositionTask] = {}
        self._tasks: dict[tuple[int, int], AnyTask] = {}  # (level, task) -> the task of a non-position spec
        self._previous_frame_postures: list[PostureTask] = []
        for level_index, level in enumerate(stack.levels):
            for task_index, spec in enumerate(level.tasks):
                if spec.kind == "posture":
                    weight = posture_weight if spec.weight is None else spec.weight
                    posture = PostureTask(body.model, gain=spec.gain, weight=weight)
                    self._tasks[level_index, task_index] = posture
                    if spec.reference == "previous":
                        self._previous_frame_postures.append(posture)
                elif spec.kind == "com":
                    self._tasks[level_index, task_index] = CenterOfMassTask(
                        body, spec.feet, gain=spec.gain, weight=1.0 if spec.weight is None else spec.weight)

    def start_frame(self, configuration: Configuration) -> None:
        """Before a frame's solve: posture tasks on the previous frame take its solution (the first
        frame, the initial configuration) as their reference."""
        for posture in self._previous_frame_postures:
            posture.set_reference(configuration.q)

    def _target_task(self, name: str, spec: TaskSpec) -> FramePositionTask:
        if name not in self.target_tasks:
            self.target_tasks[name] = FramePositionTask(self.body.model, self.body.keypoints[name], gain=spec.gain,
                                                        weight=1.0 if spec.weight is None else spec.weight,
                                                        driven=self._driven_joints(name))
        return self.target_tasks[name]

    def plan(self, names: Sequence[str]) -> StackPlan:
        """The levels for a sequence whose targets are `names` (tasks in the order of `names`, so
        that a level's rows come in the TRC's order)."""
        listed = {name for _, _, spec in self.stack.tasks("position") for name in spec.keypoints or ()}
        kept_names: list[str] = []
        kept_tasks: list[list[AnyTask]] = []
        strict: list[bool] = []
        image_stack_level: int | None = None
        image_spec: TaskSpec | None = None
        for level_index, level in enumerate(self.stack.levels):
            tasks: list[AnyTask] = []
            for task_index, spec in enumerate(level.tasks):
                if spec.kind == "position":
                    chosen = [n for n in names if n not in listed] if spec.keypoints is None else \
                        [n for n in names if n in spec.keypoints]
                    tasks += [self._target_task(name, spec) for name in chosen]
                elif spec.kind == "image":
                    if self.image_criterion is not None:
                        tasks.append(self.image_criterion)
                        image_stack_level, image_spec = len(kept_names), spec
                else:
                    tasks.append(self._tasks[level_index, task_index])
            if not tasks and all(spec.kind == "image" for spec in level.tasks):
                continue  # the image level without the image
            kept_names.append(level.name)
            kept_tasks.append(tasks)
            strict.append(level.strict)
        unused = [name for name in names if name not in self.target_tasks]
        if unused:
            warnings.warn(f"{self.stack.source}: no level names the target(s) {', '.join(unused)}: nothing pulls "
                          "them (their residuals are still reported)", IbikWarning, stacklevel=3)
            for name in unused:  # measured, never solved
                self._target_task(name, TaskSpec("position"))
        # Consecutive weighted levels share one solver level.
        solver_index: list[int] = []
        for index in range(len(kept_names)):
            joins = index > 0 and not strict[index] and not strict[index - 1]
            solver_index.append(solver_index[-1] if joins else (solver_index[-1] + 1 if solver_index else 0))
        image_level = None if image_stack_level is None else solver_index[image_stack_level]
        shared = image_level is not None and sum(len(kept_tasks[k]) for k in range(len(kept_names))
                                                 if solver_index[k] == image_level) > 1
        if shared and image_stack_level is not None and image_spec is not None and self.image_criterion is not None:
            row = CriterionStepTask(self.image_criterion, step=self.image_criterion.max_step_size,
                                    weight=1.0 if image_spec.weight is None else image_spec.weight)
            kept_tasks[image_stack_level] = [row if task is self.image_criterion else task
                                             for task in kept_tasks[image_stack_level]]
        solver_levels: list[list[AnyTask]] = [[] for _ in range(solver_index[-1] + 1 if solver_index else 0)]
        for index, tasks in zip(solver_index, kept_tasks, strict=True):
            solver_levels[index].extend(tasks)
        return StackPlan(kept_names, kept_tasks, solver_levels, solver_index, image_level, self.image_criterion)

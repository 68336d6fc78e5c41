"""What each level of a stack got at a frame's solution: its status, residual, and sacrifice.

The solver reports each of its levels at its last step (solvers.LevelReport); this adds, at the
frame's solution, what a user studying priorities asks of each stack level:

- residual: sqrt(sum_i w_i |e_i|^2) over its least-squares tasks (position [m], posture [rad],
  centre of mass [m]); None for the image, whose criterion h(q) is given instead;
- sacrificed: how much of that residual the levels above keep the level from removing. With its
  rows A = sqrt(w) J and its weighted error r = sqrt(w) e (so residual = |r|): r_above - r_alone,
  where r_alone = |r - A A^+ r| is the part no joint motion can remove (a target out of reach of
  its own joints) and r_above = |r - AZ (AZ)^+ r| the part no motion in the null space Z of the
  levels above can; 0 <= sacrificed <= residual, in the residual's units. For the image level,
  which has no residual: 1 - |Z^T g| with g its unit gradient, the share of its ascent direction
  the levels above take (0: none, 1: all). First order, at the solution, joint limits and damping
  not counted; the levels above a weighted group are the solver levels above it (the group's own
  tasks trade by weight, not priority). At a converged solution a level has removed what the
  levels above allow, so most of a strict level's residual is either out of reach (residual -
  sacrificed) or sacrificed.
"""

from __future__ import annotations

import itertools
import math
from collections.abc import Sequence
from dataclasses import dataclass
from typing import cast

import numpy as np

from ibik_pin.configuration import Configuration
from ibik_pin.solvers.nullspace import RANK_TOLERANCE, damped_solve, range_residual, remove_direction
from ibik_pin.tasks.base import GradientTask, Task
from ibik_pin.tasks.criterion_step import CriterionStepTask
from ibik_pin.tracking.levels import StackPlan

__all__ = ["LevelOutcome", "level_outcomes"]

NEGLIGIBLE_ERROR = 1e-12  # a residual below this: the level asks for nothing, so nothing is sacrificed


@dataclass
class LevelOutcome:
    """One stack level at one frame (see the module docstring).

    Attributes:
        status: the solver's status of the level holding it at the frame solve's last step:
            "solved", "relaxed", "failed" or "empty" ("empty" too for a level the scheme does not
            solve: ik and liegeois ignore the levels below the image).
        residual: weighted error of its least-squares tasks at the solution; NaN without any.
        sacrificed: the part of the residual the levels above keep it from removing (image: the
            share of its gradient they take, in [0, 1]); NaN when undefined (no enabled task, or an
            image criterion without gradient).
        criterion: h(q) of its image criterion at the solution; NaN for other levels.
    """

    status: str
    residual: float
    sacrificed: float
    criterion: float


def _unexplained(matrix: np.ndarray, request: np.ndarray) -> float:
    """|request - its projection on the range of matrix|, ranks as the solvers count them."""
    if matrix.size == 0:
        return float(np.linalg.norm(request))
    return range_residual(matrix, request)


def _weighted_rows(tasks: Sequence, configuration: Configuration) -> tuple[np.ndarray, np.ndarray]:
    """(A, r): sqrt(w) J and sqrt(w) e of the enabled least-squares tasks stacked (image rows left out)."""
    chosen = [task for task in tasks if isinstance(task, Task) and task.enabled
              and not isinstance(task, CriterionStepTask)]
    if not chosen:
        return np.zeros((0, configuration.nv)), np.zeros(0)
    # sqrt(w) J is each task's compute_linear_system A: read class by class in one call (the
    # position targets' rows from one read of every frame's Jacobian, as the solvers read them).
    jacobians = [cast(type[Task], kind).stacked_linear_system(list(run), configuration)[0]
                 for kind, run in itertools.groupby(chosen, key=type)]
    errors = [math.sqrt(task.weight) * task.compute_error(configuration) for task in chosen]
    return (jacobians[0] if len(jacobians) == 1 else np.vstack(jacobians)), np.concatenate(errors)


def _outcome(tasks: Sequence, configuration: Configuration, null_basis: np.ndarray | None, status: str,
             rows: tuple[np.ndarray, np.ndarray]) -> LevelOutcome:
    """One stack level's outcome; `rows`: its _weighted_rows; `null_basis`: what the levels above
    leave free, None when no level above has taken anything (the whole space)."""
    images = [task.criterion if isinstance(task, CriterionStepTask) else task for task in tasks
              if isinstance(task, (GradientTask, CriterionStepTask))]
    if images:
        image = images[0]
        if not image.enabled:
            return LevelOutcome(status, float("nan"), float("nan"), float("nan"))
        direction = image.compute_direction(configuration)
        free = float(np.linalg.norm(direction if null_basis is None else null_basis.T @ direction))
        sacrificed = 1.0 - free if np.linalg.norm(direction) > 0.0 else float("nan")
        return LevelOutcome(status, float("nan"), float(np.clip(sacrificed, 0.0, 1.0)),
                            image.compute_value(configuration))
    A, error = rows
    if error.size == 0:
        return LevelOutcome(status, float("nan"), float("nan"), float("nan"))
    residual = float(np.linalg.norm(error))  # sqrt(sum w |e|^2)
    if residual <= NEGLIGIBLE_ERROR:
        return LevelOutcome(status, residual, 0.0, float("nan"))
    if null_basis is None:  # no level above: nothing taken (the same two residuals, 0 exactly)
        return LevelOutcome(status, residual, 0.0, float("nan"))
    lost = _unexplained(A @ null_basis, error) - _unexplained(A, error)
    return LevelOutcome(status, residual, float(np.clip(lost, 0.0, residual)), float("nan"))


def level_outcomes(plan: StackPlan, configuration: Configuration, statuses: Sequence[str],
                   report_index: Sequence[int | None], damping: float) -> list[LevelOutcome]:
    """Every stack level's outcome at the configuration (the frame's solution).

    Args:
        plan: the stack as solved.
        configuration: the frame's solution.
        statuses: the statuses of the solver's level reports (LevelReport.status) of the frame
            solve's last step.
        report_index: per stack level, its index in `statuses` (StackPlan.report_index).
        damping: the solver's damping, for the null spaces as the solver counts them.
    """
    outcomes: list[LevelOutcome | None] = [None] * len(plan.names)
    null_basis = np.eye(configuration.nv)
    whole_space = True  # null_basis is still the identity: no level above has taken anything
    last = len(plan.solver_levels) - 1
    for solver_level, tasks in enumerate(plan.solver_levels):
        level_rows = None  # a strict level's rows, which its null space reads too
        for index in range(len(plan.names)):
            if plan.solver_index[index] != solver_level:
                continue
            at = report_index[index]
            status = statuses[at] if at is not None and at < len(statuses) else "empty"
            rows = _weighted_rows(plan.level_tasks[index], configuration)
            outcomes[index] = _outcome(plan.level_tasks[index], configuration, None if whole_space else null_basis,
                                       status, rows)
            level_rows = rows if list(plan.level_tasks[index]) == list(tasks) else None
        # The freedom this solver level uses up, as the solvers remove it (none below the last).
        if null_basis.shape[1] == 0 or solver_level == last:
            continue
        enabled = [task for task in tasks if task.enabled]
        if len(enabled) == 1 and isinstance(enabled[0], GradientTask):
            reduced = null_basis.T @ enabled[0].compute_direction(configuration)
            if np.linalg.norm(reduced) > RANK_TOLERANCE:
                null_basis, whole_space = null_basis @ remove_direction(reduced), False
        elif enabled:
            if level_rows is not None and not any(isinstance(task, CriterionStepTask) for task in enabled):
                A = level_rows[0]  # the same rows: sqrt(w) J of each enabled task, in order
            else:
                A = np.vstack([task.compute_linear_system(configuration)[0] for task in enabled
                               if isinstance(task, Task)])
            _, remaining = damped_solve(A @ null_basis, np.zeros(A.shape[0]), damping)
            null_basis, whole_space = null_basis @ remaining, False
    return [outcome for outcome in outcomes if outcome is not None]

"""Null-space projection schemes: the strict priority stack, Liegeois (eq. 4) and plain IK (eq. 3).

The stack follows Baerlocher & Boulic (2004) in its recursive form
    dq_k = dq_{k-1} + (J_k P_{k-1})^+_damped (b_k - J_k dq_{k-1}),
    P_k  = P_{k-1} - (J_k P_{k-1})^+ (J_k P_{k-1}),
with P_k kept as an orthonormal basis Z_k of the remaining null space (P_k = Z_k Z_k^T): the same
projector, better conditioned, and the problem shrinks as levels use up freedom. A gradient level
adds step_size * P_{k-1} g / |P_{k-1} g| (the maximiser of g.dq - |dq|^2 / (2 step_size) over the null
space, the same objective the QP uses, with g normalised after projection so that the step keeps
its length when most of the gradient is spent against higher levels) and consumes the one direction
it used.

IK and Liegeois are this stack with the levels regrouped: every least-squares task above the first
gradient level merged into one primary task, then (Liegeois only) the gradient level.
"""

from __future__ import annotations

import functools

import numpy as np

from ibik_pin.configuration import Configuration
from ibik_pin.limits import JointLimits
from ibik_pin.solvers.base import (
    DEFAULT_DAMPING,
    LevelPlan,
    Levels,
    Solver,
    StepResult,
    build_levels,
    report_levels,
)
from ibik_pin.solvers.level_loop import PackedLevels, StepWorkspace
from ibik_pin.solvers.level_types import checked_levels
from ibik_pin.tasks.base import GradientTask, Task


class PriorityStackSolver(Solver):
    """Strict priority stack by recursive null-space projection with damped pseudo-inverses
    J^T (J J^T + damping^2 I)^-1; built as every solver, `PriorityStackSolver(limits=..., damping=...)`.
    """

    name = "stack"

    def __init__(self, *, limits: JointLimits | None = None, damping: float = DEFAULT_DAMPING) -> None:
        super().__init__(limits=limits, damping=damping)
        self._workspace = StepWorkspace()

    def arrange(self, levels: Levels) -> Levels:
        return checked_levels(levels)

    def compute_step(self, configuration: Configuration, levels: Levels, plan: LevelPlan | None = None) -> StepResult:
        planned = plan or LevelPlan.of(self.arrange(levels))
        built = build_levels(configuration, planned.levels, planned)
        nv = configuration.nv
        packed = self._workspace.packed(built, plan, self.step_adaptation, nv)
        if self.limits is None:
            dq = self._project(packed, np.zeros(nv), self._workspace.identity(nv))
        else:
            # Joint limits by clamping (Baerlocher & Boulic 2004): a coordinate whose step leaves its
            # bounds is locked on the bound and taken out of every level, and the stack is solved
            # again (a gradient level keeps the step norm of its first pass).
            lower, upper = self.limits.step_bounds(configuration.q)
            locked = np.zeros(nv, dtype=bool)
            fixed = np.zeros(nv)
            for _ in range(nv):
                dq = self._project(packed, fixed.copy(), np.eye(nv)[:, ~locked])
                leaving = ~locked & ((dq < lower) | (dq > upper))
                if not leaving.any():
                    break
                fixed[leaving] = np.clip(dq[leaving], lower[leaving], upper[leaving])
                locked |= leaving
            dq = np.clip(dq, lower, upper)
        packed.finish()
        return StepResult(dq, functools.partial(report_levels, built, dq.copy()), planned.criterion(built))

    def _project(self, packed: PackedLevels, dq: np.ndarray, null_basis: np.ndarray) -> np.ndarray:
        """The recursive stack from a partial step dq over the coordinates spanned by null_basis."""
        unbounded = np.zeros(0)
        dq, *_ = packed.solve(dq, null_basis, unbounded, unbounded, bounded=False, active_set=False,
                              damping=self.damping)
        return dq


def _merge_least_squares(levels: Levels) -> list[list]:
    """All least-squares tasks above the first gradient level, in one level."""
    primary: list[Task | GradientTask] = []
    for level in levels:
        if any(isinstance(task, GradientTask) for task in level):
            break
        primary.extend(level)
    return [primary]


def _first_gradient_level(levels: Levels) -> list[list]:
    for level in levels:
        if any(isinstance(task, GradientTask) for task in level):
            return [list(level)]
    return []


class LiegeoisSolver(PriorityStackSolver):
    """Eq. (4): dq = J^+ e + (I - J^+ J) alpha grad h.

    The primary task merges every least-squares task above the first gradient level; that gradient
    level is the secondary criterion. Levels below it are not part of eq. (4) and are ignored.
    """

    name = "liegeois"

    def arrange(self, levels: Levels) -> Levels:
        checked = checked_levels(levels)
        return _merge_least_squares(checked) + _first_gradient_level(checked)


class DampedLeastSquaresSolver(PriorityStackSolver):
    """Eq. (3), the blind IK baseline: damped least squares on every least-squares task above the
    first gradient level, merged; gradient levels and everything below them are ignored."""

    name = "ik"

    def arrange(self, levels: Levels) -> Levels:
        return _merge_least_squares(checked_levels(levels))

"""Hierarchical QP: the priority levels solved lexicographically, joint limits as bounds.

Level k searches its increment in the null space left by the higher levels, dq = dq_{k-1} + Z w
(Z orthonormal, as in the projection stack), which keeps every higher level's rows exactly where
they were, whatever the QP's tolerance. It solves
    least-squares level:  min |A_k (dq_{k-1} + Z w) - b_k|^2 + damping^2 |w|^2
    gradient level:       min -g.Z w + |w|^2 / (2 step_size)    (Z^T g of unit norm, as the stack)
subject to  lower - dq_{k-1} <= Z w <= upper - dq_{k-1}   (URDF position limits and per-step bounds),
the QP that :class:`~ibik_pin.solvers.qp_backends.LevelProblem` holds. Without an active bound this
is exactly the projection stack's step. Every level is feasible (w = 0 satisfies it); one whose
target the bounds or higher levels forbid ends with a residual, reported "relaxed" (LevelStatus).

A level whose unconstrained optimum (the projection stack's step, one factorisation away) already
respects every bound needs no QP, whatever the backend. The others go to the solver's one backend
(:mod:`ibik_pin.solvers.qp_backends`): "active_set" (the default, compiled, run inside the compiled
level loop), "proxsuite" (dense QP objects kept per level and size, warm-started), or any solver
qpsolvers has installed. A backend's failure on a level is a QPBackendError: raised with
`raise_on_failure`, else the level takes no step, leaves its null space to the levels below and is
reported "failed" with the backend's own status in LevelReport.detail. docs/method.md ("The level QP
and its backends") gives the measurements behind the default.
"""

from __future__ import annotations

import dataclasses
import functools

import numpy as np

from ibik_pin.configuration import Configuration
from ibik_pin.exceptions import QPBackendError
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
from ibik_pin.solvers.level_loop import StepWorkspace
from ibik_pin.solvers.level_types import checked_levels
from ibik_pin.solvers.qp_backends import FEASIBILITY, UNBOUNDED, LevelProblem, make_qp_backend

DEFAULT_QP_SOLVER = "active_set"


class HierarchicalQPSolver(Solver):
    """Lexicographic QP stack with joint limits as inequality constraints, on one QP backend.

    Built as every solver, with keyword arguments only; `damping` weighs damping^2 |w|^2 on each
    level's increment, as the stack's damping does.

    Args:
        limits: joint limits, or None.
        damping: lambda [m/rad] (see DEFAULT_DAMPING).
        qp_solver: the backend's name, one of `available_qp_solvers()` ("active_set", "proxsuite",
            qpsolvers' installed solvers).
        accuracy: proxsuite's absolute tolerance eps_abs ("proxsuite" and qpsolvers' "proxqp").
        max_qp_iterations: proxsuite's iteration cap per level.
        raise_on_failure: raise a backend's QPBackendError instead of reporting the level "failed".

    Attributes:
        backend: the QPBackend that solves the levels the bounds reach.

    Raises:
        UnknownNameError: an unknown qp_solver (the message lists the available ones).
        InputError: a damping that is not a positive finite number.
    """

    name = "qp"

    def __init__(
        self,
        *,
        limits: JointLimits | None = None,
        damping: float = DEFAULT_DAMPING,
        qp_solver: str = DEFAULT_QP_SOLVER,
        accuracy: float = 1e-11,
        max_qp_iterations: int = 1000,
        raise_on_failure: bool = False,
    ) -> None:
        super().__init__(limits=limits, damping=damping)
        self.backend = make_qp_backend(qp_solver, accuracy=accuracy, max_iterations=max_qp_iterations)
        self.raise_on_failure = bool(raise_on_failure)
        self._workspace = StepWorkspace()

    def arrange(self, levels: Levels) -> Levels:
        return checked_levels(levels)

    def compute_step(self, configuration: Configuration, levels: Levels, plan: LevelPlan | None = None) -> StepResult:
        return self._step(configuration, levels, plan, None)

    def level_problems(self, configuration: Configuration, levels: Levels) -> list[LevelProblem | None]:
        """Each level's QP at this configuration, highest first (None: an empty level, or none left
        of the null space).

        Level k's problem depends on the step of the levels above it (its Z, its bounds minus their
        dq), so building them solves each in turn with the backend: this is one step, every level
        posed as a QP (the step proper skips the QP of a level whose unconstrained optimum respects
        the bounds; both give the same optimum), and it advances the gradient levels' step
        adaptation as a step does.

        Args:
            configuration: the state the step starts from (not moved).
            levels: priority levels, highest first.

        Raises:
            QPBackendError: with raise_on_failure, a backend found no answer to a level.
        """
        problems: list[LevelProblem | None] = [None] * len(self.arrange(levels))
        self._step(configuration, levels, None, problems)
        return problems

    def _step(self, configuration: Configuration, levels: Levels, plan: LevelPlan | None,
              problems: list[LevelProblem | None] | None) -> StepResult:
        """compute_step; with `problems`, every level handed to the backend and its QP written there."""
        planned = plan or LevelPlan.of(self.arrange(levels))
        built = build_levels(configuration, planned.levels, planned)
        nv = configuration.nv
        if self.limits is not None:
            lower, upper = self.limits.step_bounds(configuration.q)
        else:
            lower, upper = np.full(nv, -UNBOUNDED), np.full(nv, UNBOUNDED)
        packed = self._workspace.packed(built, plan, self.step_adaptation, nv)
        # From no step, clipped into the bounds (a q outside its limits steps back in first).
        dq, null_basis = self._workspace.zeros(nv), self._workspace.identity(nv)
        failed: dict[int, str] = {}
        start = 0
        while start < len(built):
            dq, null_basis, stopped, hessian, linear, remaining = packed.solve(
                dq, null_basis, lower, upper, bounded=True, active_set=self.backend.in_loop,
                damping=self.damping, feasibility=FEASIBILITY, start=start, hand_back=problems is not None)
            if stopped == len(built):
                break
            problem = LevelProblem(stopped, hessian, linear, null_basis, lower - dq, upper - dq, dq)
            if problems is not None:  # its own copy of Z: the first level's is the workspace's identity
                problems[stopped] = problem = dataclasses.replace(problem, C=problem.C.copy())
            try:
                w = self.backend.solve(problem)
            except QPBackendError as error:
                if self.raise_on_failure:
                    raise
                failed[stopped] = f"{error.backend}: {error.status}"  # no step: its null space goes below
            else:
                # A backend meets the bounds to its tolerance; clip so the limits hold exactly.
                dq = problem.step(w).clip(lower, upper)
                if remaining.shape[0]:  # (0, 0) for the last level: nothing follows it
                    null_basis = null_basis @ remaining
            start = stopped + 1
        packed.finish()
        return StepResult(dq, functools.partial(report_levels, built, dq.copy(), failed), planned.criterion(built))

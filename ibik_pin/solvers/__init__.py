"""Solvers: plain IK (eq. 3), Liegeois (eq. 4), the strict priority stack and the hierarchical QP.

All take the same task objects arranged in priority levels; the scheme is the one argument that
changes.
"""

from __future__ import annotations

from ibik_pin.exceptions import UnknownNameError
from ibik_pin.limits import JointLimits
from ibik_pin.solvers.base import (
    DEFAULT_DAMPING,
    LevelReport,
    Solver,
    SolveResult,
    StepResult,
)
from ibik_pin.solvers.hqp import DEFAULT_QP_SOLVER, HierarchicalQPSolver
from ibik_pin.solvers.projection import (
    DampedLeastSquaresSolver,
    LiegeoisSolver,
    PriorityStackSolver,
)
from ibik_pin.solvers.qp_backends import LevelProblem, QPBackend, available_qp_solvers, qp_solver_available
from ibik_pin.solvers.status import LevelStatus
from ibik_pin.solvers.step_adaptation import StepAdaptation

SOLVERS = {
    "ik": DampedLeastSquaresSolver,
    "liegeois": LiegeoisSolver,
    "stack": PriorityStackSolver,
    "qp": HierarchicalQPSolver,
}


def make_solver(name: str, *, limits: JointLimits | None = None, damping: float = DEFAULT_DAMPING,
                qp_solver: str = DEFAULT_QP_SOLVER) -> Solver:
    """A solver by name, built as `SOLVERS[name](limits=limits, damping=damping)`.

    Args:
        name: "ik", "liegeois", "stack" or "qp".
        limits: joint limits, or None.
        damping: lambda [m/rad] of every level's damped least squares (see DEFAULT_DAMPING).
        qp_solver: the QP backend of "qp" (one of `available_qp_solvers()`); the other schemes
            solve no QP and ignore it.

    Raises:
        UnknownNameError: an unknown scheme or QP backend name (the message lists the available ones).
        InputError: a damping that is not a positive finite number.
    """
    if name not in SOLVERS:
        raise UnknownNameError(f"unknown solver {name!r}; available: {', '.join(SOLVERS)}")
    if not qp_solver_available(qp_solver):  # refused whatever the scheme, so no typo waits for "qp"
        raise UnknownNameError(f"unknown QP solver {qp_solver!r}; available: {', '.join(available_qp_solvers())}")
    if name == "qp":
        return HierarchicalQPSolver(limits=limits, damping=damping, qp_solver=qp_solver)
    return SOLVERS[name](limits=limits, damping=damping)


__all__ = [
    "Solver", "StepResult", "SolveResult", "LevelReport", "LevelStatus", "StepAdaptation", "SOLVERS", "make_solver",
    "DEFAULT_DAMPING", "DEFAULT_QP_SOLVER", "LevelProblem", "QPBackend", "available_qp_solvers", "qp_solver_available",
    "DampedLeastSquaresSolver", "LiegeoisSolver", "PriorityStackSolver", "HierarchicalQPSolver",
]

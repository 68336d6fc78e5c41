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
from ibik_pin.solvers.hqp import HierarchicalQPSolver
from ibik_pin.solvers.projection import (
    DampedLeastSquaresSolver,
    LiegeoisSolver,
    PriorityStackSolver,
)

SOLVERS = {
    "ik": DampedLeastSquaresSolver,
    "liegeois": LiegeoisSolver,
    "stack": PriorityStackSolver,
    "qp": HierarchicalQPSolver,
}


def make_solver(name: str, limits: JointLimits | None = None, damping: float = DEFAULT_DAMPING) -> Solver:
    """A solver by name: "ik", "liegeois", "stack" or "qp"."""
    if name not in SOLVERS:
        raise UnknownNameError(f"unknown solver {name!r}; available: {', '.join(SOLVERS)}")
    return SOLVERS[name](limits=limits, damping=damping)


__all__ = [
    "Solver", "StepResult", "SolveResult", "LevelReport", "SOLVERS", "make_solver",
    "DampedLeastSquaresSolver", "LiegeoisSolver", "PriorityStackSolver", "HierarchicalQPSolver",
]

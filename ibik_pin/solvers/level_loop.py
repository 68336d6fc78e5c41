"""The level loop shared by the projection stack and the hierarchical QP.

The levels, highest first, each in the null space of those above it
(:mod:`ibik_pin.solvers.nullspace`): a least-squares level's damped least squares, a gradient
level's step along its unit projected gradient with its norm adapted by Rprop
(:mod:`ibik_pin.solvers.step_adaptation`). With bounds (the QP), a level whose step leaves them is
solved again with them by the primal active-set method (:mod:`ibik_pin.solvers.active_set`); one
where that does not end is handed back to the caller (proxsuite's turn), which resumes the loop
below it. The whole loop is one compiled call (:func:`ibik_pin.solvers.kernels.solve_levels`);
`PackedLevels` lays the built levels out as the arrays it reads.
"""

from __future__ import annotations

import numpy as np

from ibik_pin.exceptions import SolverError
from ibik_pin.solvers.base import GradientLevel, LeastSquaresLevel
from ibik_pin.solvers.kernels import GRADIENT, LEAST_SQUARES, solve_levels
from ibik_pin.solvers.step_adaptation import StepAdaptation

__all__ = ["PackedLevels"]


class PackedLevels:
    """Built levels (solvers.base.build_levels) as the arrays `solve_levels` reads.

    Attributes:
        kinds, rows, targets, row_starts: the levels (see solve_levels).
        adaptation, previous: the gradient levels' step-adaptation state, copied from `source`.
        steps: (L,) the gradient levels' step norms of this step, 0 until taken.
    """

    def __init__(self, built: list, source: StepAdaptation, nv: int) -> None:
        self.built = built
        self.source = source
        self.kinds = np.zeros(len(built), dtype=np.int64)
        self.row_starts = np.zeros(len(built) + 1, dtype=np.int64)
        self.adaptation = np.zeros((len(built), 4))
        self.previous = np.zeros((len(built), nv))
        self.steps = np.zeros(len(built))
        blocks, targets = [], []
        for index, level in enumerate(built):
            if isinstance(level, LeastSquaresLevel):
                self.kinds[index] = LEAST_SQUARES
                blocks.append(level.A)
                targets.append(level.b)
            elif isinstance(level, GradientLevel):
                self.kinds[index] = GRADIENT
                blocks.append(level.direction[None])
                targets.append(np.zeros(1))
                self.adaptation[index], self.previous[index] = source.state(level.task, nv)
            self.row_starts[index + 1] = self.row_starts[index] + (blocks[-1].shape[0] if self.kinds[index] else 0)
        self.rows = np.ascontiguousarray(np.vstack(blocks) if blocks else np.zeros((0, nv)), dtype=np.float64)
        self.targets = np.ascontiguousarray(np.concatenate(targets) if targets else np.zeros(0), dtype=np.float64)

    def solve(self, dq: np.ndarray, null_basis: np.ndarray, lower: np.ndarray, upper: np.ndarray, *,
              bounded: bool, active_set: bool, damping: float, feasibility: float = 0.0, start: int = 0):
        """solve_levels on these levels; raises SolverError if a factorisation failed."""
        dq, null_basis, stopped, hessian, linear, remaining, ok = solve_levels(
            self.kinds, self.rows, self.targets, self.row_starts, self.adaptation, self.previous, self.steps,
            np.ascontiguousarray(dq, dtype=np.float64), np.ascontiguousarray(null_basis, dtype=np.float64),
            lower, upper, bounded, active_set, damping, feasibility, start)
        if not ok:
            raise SolverError(f"the factors of level {stopped}'s projected Jacobian failed "
                              "(a non-finite matrix?)")
        return dq, null_basis, stopped, hessian, linear, remaining

    def finish(self) -> None:
        """Write the gradient levels' adaptation back to their StepAdaptation, and their step norms
        to the built levels (for the reports)."""
        for index, level in enumerate(self.built):
            if isinstance(level, GradientLevel):
                state, previous = self.source.state(level.task, self.previous.shape[1])
                state[:], previous[:] = self.adaptation[index], self.previous[index]
                level.step_size = float(self.steps[index])

"""The level loop shared by the projection stack and the hierarchical QP, compiled (Numba).

The levels, highest first, each in the null space of those above it
(:mod:`ibik_pin.solvers.nullspace`): a least-squares level's damped least squares, a gradient
level's step along its unit projected gradient with its norm adapted by Rprop
(:mod:`ibik_pin.solvers.step_adaptation`). With bounds (the QP), a level whose step leaves them is
solved again with them by the primal active-set method (:mod:`ibik_pin.solvers.active_set`); one
where that does not end is handed back to the caller (proxsuite's turn), which resumes the loop
below it. The whole loop is one compiled call: on real boxing its levels' numpy and LAPACK calls,
each a few microseconds of wrapper, were a third of the QP's step.
"""

from __future__ import annotations

import numpy as np
from numba import njit

from ibik_pin.exceptions import SolverError
from ibik_pin.solvers.active_set import _active_set, within_bounds
from ibik_pin.solvers.base import GradientLevel, LeastSquaresLevel
from ibik_pin.solvers.nullspace import (
    RANK_TOLERANCE,
    _complement,
    _coordinate_solve,
    _damped_solve,
    _damped_step,
)
from ibik_pin.solvers.step_adaptation import StepAdaptation, adapt_step_size

__all__ = ["PackedLevels", "solve_levels"]

# The kinds of level in `solve_levels`.
EMPTY, LEAST_SQUARES, GRADIENT = 0, 1, 2


@njit(cache=True, nogil=True)
def solve_levels(kinds, rows, targets, row_starts, adaptation, previous, steps, dq, null_basis, lower, upper,
                 bounded, active_set, damping, feasibility, start):
    """The levels from `start` on, highest first, each in the null space of those above it.

    Args:
        kinds: (L,) EMPTY, LEAST_SQUARES or GRADIENT per level.
        rows, targets: (R, nv), (R,) every level's rows A and b stacked; a gradient level's one row
            is its unit direction (its target unused).
        row_starts: (L + 1,) where each level's rows start.
        adaptation, previous: (L, 4), (L, nv) a gradient level's step-adaptation state and previous
            direction (StepAdaptation.state), updated in place.
        steps: (L,) the step norm of each gradient level this step, 0 until it is taken; a level
            whose norm is already set (a second pass of the same step) keeps it.
        dq: (nv,) the higher levels' step; null_basis: (nv, r) Z, C-contiguous.
        lower, upper: (nv,) bounds on dq, used when `bounded` (then dq is clipped into them).
        active_set: solve a level that the bounds reach by the active-set method (else hand it back).
        damping: lambda of every level's damped least squares.
        feasibility: see primal_active_set.
        start: the first level to solve.

    Returns:
        dq; Z; the index of a level handed back (L when every level is done); for that level its
        QP's Hessian (r, r), linear term (r,) and the null space it leaves (r, r'); whether every
        factorisation held.
    """
    levels = kinds.shape[0]
    last = -1
    for index in range(levels):
        if kinds[index] != EMPTY:
            last = index
    nothing_2d, nothing_1d = np.zeros((0, 0)), np.zeros(0)
    for index in range(start, levels):
        size = null_basis.shape[1]
        if kinds[index] == EMPTY or size == 0:
            continue
        # (typed on every path)
        unit, projected, residual, remaining = nothing_1d, nothing_2d, nothing_1d, nothing_2d
        coordinate, free_columns = False, np.zeros(0, dtype=np.int64)
        if kinds[index] == GRADIENT:
            reduced = null_basis.T @ rows[row_starts[index]]
            norm = np.sqrt(reduced @ reduced)
            if norm <= RANK_TOLERANCE:
                continue  # nothing left to climb
            unit = reduced / norm
            if steps[index] == 0.0:
                steps[index] = adapt_step_size(adaptation[index], previous[index], null_basis @ unit)
            w = steps[index] * unit
            remaining = _complement(unit) if index != last else nothing_2d
        else:
            block = rows[row_starts[index]:row_starts[index + 1]]
            projected = block @ null_basis
            residual = targets[row_starts[index]:row_starts[index + 1]] - block @ dq
            w, free_columns, coordinate = _coordinate_solve(projected, residual, damping)
            ok = True
            if not coordinate and index == last:
                w, ok = _damped_step(projected, residual, damping)
            elif not coordinate:
                w, remaining, ok = _damped_solve(projected, residual, damping)
            if not ok:
                return dq, null_basis, index, nothing_2d, nothing_1d, nothing_2d, False
        if bounded:
            if not within_bounds(dq + null_basis @ w, lower, upper):
                if kinds[index] == GRADIENT:
                    hessian = np.eye(size) / steps[index]
                    linear = -unit
                else:
                    hessian = projected.T @ projected
                    for i in range(size):
                        hessian[i, i] += damping * damping
                    linear = -(projected.T @ residual)
                ended = False
                if active_set:
                    w, ended = _active_set(hessian, linear, null_basis, lower - dq, upper - dq, feasibility)
                if not ended:
                    if coordinate and index != last:
                        remaining = np.ascontiguousarray(np.eye(size)[:, free_columns])
                    return dq, null_basis, index, hessian, linear, remaining, True
            dq = np.minimum(np.maximum(dq + null_basis @ w, lower), upper)
        else:
            dq = dq + null_basis @ w
        if index == last:
            continue
        if coordinate:  # the selection of the columns left free
            null_basis = np.ascontiguousarray(null_basis[:, free_columns])
        else:
            null_basis = null_basis @ remaining
    return dq, null_basis, levels, nothing_2d, nothing_1d, nothing_2d, True


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

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
from ibik_pin.solvers.kernels import EMPTY, GRADIENT, LEAST_SQUARES, solve_levels
from ibik_pin.solvers.step_adaptation import StepAdaptation

__all__ = ["PackedLevels", "StepWorkspace"]

_NO_TARGET = np.zeros(1)  # a gradient level's (unused) target
_KEPT_LAYOUTS = 16  # layouts kept at most (a stack that keeps changing shape starts afresh)


def layout_of(built: list) -> tuple:
    """Per built level, its kind and row count (Python ints): what PackedLevels' arrays depend on."""
    return tuple((LEAST_SQUARES, level.A.shape[0]) if isinstance(level, LeastSquaresLevel) else
                 (GRADIENT, 1) if isinstance(level, GradientLevel) else (EMPTY, 0) for level in built)


class PackedLevels:
    """Built levels (solvers.base.build_levels) as the arrays `solve_levels` reads.

    Attributes:
        kinds, rows, targets, row_starts: the levels (see solve_levels).
        adaptation, previous: the gradient levels' step-adaptation state, copied from `source`.
        steps: (L,) the gradient levels' step norms of this step, 0 until taken.
    """

    def __init__(self, built: list, source: StepAdaptation, nv: int) -> None:
        self.source = source
        # Per level, its kind and row count, as Python ints: `load` checks the next step's against them.
        self._layout = layout_of(built)
        self._gradient_levels = [index for index, (kind, _) in enumerate(self._layout) if kind == GRADIENT]
        self.kinds = np.array([kind for kind, _ in self._layout], dtype=np.int64)
        self.row_starts = np.concatenate([[0], np.cumsum([count for _, count in self._layout])]).astype(np.int64)
        self.adaptation = np.zeros((len(built), 4))
        self.previous = np.zeros((len(built), nv))
        self.steps = np.zeros(len(built))
        self.rows = np.zeros((int(self.row_starts[-1]), nv))
        self.targets = np.zeros(int(self.row_starts[-1]))
        self.load(built)

    def load(self, built: list) -> bool:
        """Take the rows of newly built levels (the next step of the same plan) into the arrays.

        Returns:
            False, with nothing changed, when their layout is not this one's (a rebuild is needed).
        """
        if len(built) != len(self._layout):
            return False
        blocks, targets = [], []
        for (kind, count), level in zip(self._layout, built, strict=True):
            if kind == LEAST_SQUARES:
                if not isinstance(level, LeastSquaresLevel) or level.A.shape[0] != count:
                    return False
                blocks.append(level.A)
                targets.append(level.b)
            elif kind == GRADIENT:
                if not isinstance(level, GradientLevel):
                    return False
                blocks.append(level.direction[None])
                targets.append(_NO_TARGET)
            elif level is not None:
                return False
        if blocks:  # one copy of every level's rows into the arrays the compiled loop reads
            np.concatenate(blocks, axis=0, out=self.rows)
            np.concatenate(targets, out=self.targets)
        nv = self.previous.shape[1]
        for index in self._gradient_levels:
            self.adaptation[index], self.previous[index] = self.source.state(built[index].task, nv)
        self.steps.fill(0.0)
        self.built = built
        return True

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
        nv = self.previous.shape[1]
        for index in self._gradient_levels:
            level = self.built[index]
            state, previous = self.source.state(level.task, nv)
            state[:], previous[:] = self.adaptation[index], self.previous[index]
            level.step_size = float(self.steps[index])


class StepWorkspace:
    """What a solver keeps between steps: the PackedLevels of every layout of levels it solved (its
    arrays refilled at each step instead of allocated; the tracker's frame alternates three
    solves of different layouts) and an identity per size."""

    def __init__(self) -> None:
        self._by_layout: dict[tuple, PackedLevels] = {}
        self._identities: dict[int, np.ndarray] = {}

    def packed(self, built: list, plan: object, source: StepAdaptation, nv: int) -> PackedLevels:
        """`built` packed: in the arrays kept for its layout (the previous step of its solve, or an
        earlier solve of the same shape), else in new ones, kept (a step without a plan keeps none)."""
        layout = layout_of(built)
        packed = self._by_layout.get(layout)
        if packed is None or packed.source is not source or packed.previous.shape[1] != nv or not packed.load(built):
            packed = PackedLevels(built, source, nv)
            if plan is not None:
                if len(self._by_layout) >= _KEPT_LAYOUTS:
                    self._by_layout.clear()
                self._by_layout[layout] = packed
        return packed

    def identity(self, nv: int) -> np.ndarray:
        """The (nv, nv) identity, shared: the level loop only reads it."""
        identity = self._identities.get(nv)
        if identity is None:
            identity = self._identities[nv] = np.eye(nv)
        return identity

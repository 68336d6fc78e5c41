"""The level loop shared by the projection stack and the hierarchical QP.

The levels, highest first, each in the null space of those above it
(:mod:`ibik_pin.solvers.nullspace`): a least-squares level's damped least squares, a gradient
level's step along its unit projected gradient with its norm adapted by Rprop
(:mod:`ibik_pin.solvers.step_adaptation`). With bounds (the QP), a level whose step leaves them is
solved again with them by the primal active-set method (:mod:`ibik_pin.solvers.active_set`) when
that is the QP's backend, else handed back to the caller with its QP (the backend's turn; also one
where the active-set method does not end), which resumes the loop below it. The whole loop is one
compiled call (:func:`ibik_pin.solvers.kernels.solve_levels`);
`PackedLevels` lays the built levels out as the arrays it reads.
"""

from __future__ import annotations

import numpy as np

from ibik_pin.exceptions import SolverError
from ibik_pin.solvers.base import GradientLevel, LeastSquaresLevel
from ibik_pin.solvers.kernels import EMPTY, GRADIENT, LEAST_SQUARES, solve_levels, solve_levels_step
from ibik_pin.solvers.step_adaptation import StepAdaptation

__all__ = ["PackedLevels", "StepWorkspace"]

_KEPT_LAYOUTS = 16  # layouts kept at most (a stack that keeps changing shape starts afresh)


def layout_of(built: list) -> tuple:
    """Per built level, its kind and row count (Python ints): what PackedLevels' arrays depend on."""
    return tuple((LEAST_SQUARES, level.A.shape[0]) if isinstance(level, LeastSquaresLevel) else
                 (GRADIENT, 1) if isinstance(level, GradientLevel) else (EMPTY, 0) for level in built)


class PackedLevels:
    """Built levels (solvers.base.build_levels) as the arrays `solve_levels` reads.

    The gradient levels' step-adaptation state lives in `adaptation` and `previous` while the
    packing is in use: its StepAdaptation holds it there (StepAdaptation.hold), so the compiled loop
    updates the source's state in place.

    Attributes:
        kinds, rows, targets, row_starts: the levels (see solve_levels).
        adaptation, previous: the gradient levels' step-adaptation state (StepAdaptation.state).
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
        # Per level, the views its rows are written to at every step (a slice assignment each, where
        # a concatenation of all levels cost twice as much), and a gradient level's state rows.
        self._row_views = [self.rows[a:b] for a, b in zip(self.row_starts[:-1], self.row_starts[1:], strict=True)]
        self._target_views = [self.targets[a:b] for a, b in zip(self.row_starts[:-1], self.row_starts[1:], strict=True)]
        self._state_rows = [(self.adaptation[index], self.previous[index]) for index in range(len(built))]
        self.load(built)

    def load(self, built: list) -> bool:
        """Take the rows of newly built levels (the next step of the same plan) into the arrays.

        Returns:
            False when their layout is not this one's (a rebuild is needed); the rows may then be
            partly overwritten (the next load rewrites them all).
        """
        if len(built) != len(self._layout):
            return False
        for index, ((kind, count), level) in enumerate(zip(self._layout, built, strict=True)):
            if kind == LEAST_SQUARES:
                if type(level) is not LeastSquaresLevel or level.A.shape[0] != count:
                    return False
                self._row_views[index][:] = level.A
                self._target_views[index][:] = level.b
            elif kind == GRADIENT:
                if type(level) is not GradientLevel:
                    return False
                self._row_views[index][0] = level.direction
            elif level is not None:
                return False
        for index in self._gradient_levels:
            state, previous = self._state_rows[index]
            task = built[index].task
            if self.source.state(task, previous.size)[0] is not state:  # held elsewhere, or reset
                self.source.hold(task, state, previous)
        self.steps.fill(0.0)
        self.built = built
        return True

    def solve(self, dq: np.ndarray, null_basis: np.ndarray, lower: np.ndarray, upper: np.ndarray, *,
              bounded: bool, active_set: bool, damping: float, feasibility: float = 0.0, start: int = 0,
              hand_back: bool = False):
        """solve_levels on these levels; raises SolverError if a factorisation failed.

        Returns:
            dq, null_basis, the level handed back (L when every level is done) and, for that level,
            its QP's Hessian, linear term and the null space it leaves (None when every level is done).
        """
        arguments = (self.kinds, self.rows, self.targets, self.row_starts, self.adaptation, self.previous,
                     self.steps, np.ascontiguousarray(dq, dtype=np.float64),
                     np.ascontiguousarray(null_basis, dtype=np.float64), lower, upper, bounded, active_set,
                     hand_back, damping, feasibility, start)
        dq, stopped, ok = solve_levels_step(*arguments)
        if not ok:
            raise SolverError(f"the factors of level {stopped}'s projected Jacobian failed "
                              "(a non-finite matrix?)")
        if stopped == self.kinds.shape[0]:
            return dq, None, stopped, None, None, None
        dq, null_basis, stopped, hessian, linear, remaining, _ = solve_levels(*arguments)
        return dq, null_basis, stopped, hessian, linear, remaining

    def finish(self) -> None:
        """Write the gradient levels' step norms to the built levels (for the reports)."""
        for index in self._gradient_levels:
            self.built[index].step_size = float(self.steps[index])


class StepWorkspace:
    """What a solver keeps between steps: the PackedLevels of every layout of levels it solved (its
    arrays refilled at each step instead of allocated; the tracker's frame alternates three
    solves of different layouts) and an identity per size."""

    def __init__(self) -> None:
        self._by_layout: dict[tuple, PackedLevels] = {}
        self._identities: dict[int, np.ndarray] = {}
        self._zeros: dict[int, np.ndarray] = {}
        self._last: tuple[object, PackedLevels] | None = None  # the last plan and its packing

    def packed(self, built: list, plan: object, source: StepAdaptation, nv: int) -> PackedLevels:
        """`built` packed: in the arrays kept for its layout (the previous step of its solve, or an
        earlier solve of the same shape), else in new ones, kept (a step without a plan keeps none)."""
        if plan is not None and self._last is not None and self._last[0] is plan:
            last = self._last[1]  # the step before's, whose layout the next step almost always has
            if last.source is source and last.previous.shape[1] == nv and last.load(built):
                return last
        layout = layout_of(built)
        kept = self._by_layout.get(layout)
        if kept is not None and kept.source is source and kept.previous.shape[1] == nv and kept.load(built):
            packed = kept
        else:
            packed = PackedLevels(built, source, nv)
            if plan is not None:
                if len(self._by_layout) >= _KEPT_LAYOUTS:
                    self._by_layout.clear()
                self._by_layout[layout] = packed
        if plan is not None:
            self._last = (plan, packed)
        return packed

    def zeros(self, nv: int) -> np.ndarray:
        """(nv,) zeros, shared: the level loop only reads it."""
        zeros = self._zeros.get(nv)
        if zeros is None:
            zeros = self._zeros[nv] = np.zeros(nv)
        return zeros

    def identity(self, nv: int) -> np.ndarray:
        """The (nv, nv) identity, shared: the level loop only reads it."""
        identity = self._identities.get(nv)
        if identity is None:
            identity = self._identities[nv] = np.eye(nv)
        return identity

"""Hierarchical QP: the priority levels solved lexicographically with proxsuite, joint limits as boxes.

Level k solves
    least-squares level:  min |A_k dq - b_k|^2 + damping^2 |dq|^2
    gradient level:       min -g.dq + |dq|^2 / (2 step_size)      (g the unit ascent direction)
subject to  A_i dq = A_i dq*_{k-1}  for every higher level i  (keep their optimum)
and         lower <= dq <= upper    (URDF position limits and per-step bounds, at every level).
Without active bounds this is exactly the projection stack's step (same damping, same gradient
objective). Each level is always feasible: the previous level's solution satisfies its constraints.

One proxsuite dense QP object per level is created once and updated, warm-started from its previous
result across iterations and frames; it is rebuilt only when a level's constraint count changes
(a target dropped for a frame). A backend failure skips that level (reported "failed"), never raises.
"""

from __future__ import annotations

import numpy as np
import proxsuite

from ..configuration import Configuration
from ..exceptions import InputError
from ..limits import JointLimits
from .base import DEFAULT_DAMPING, GradientLevel, Levels, Solver, StepResult, build_levels, report_levels

UNBOUNDED = 1e20  # proxsuite's stand-in for an infinite bound
_SOLVED = {
    proxsuite.proxqp.QPSolverOutput.PROXQP_SOLVED,
    proxsuite.proxqp.QPSolverOutput.PROXQP_SOLVED_CLOSEST_PRIMAL_FEASIBLE,
}


class HierarchicalQPSolver(Solver):
    """Lexicographic QP stack on proxsuite with joint limits as box constraints.

    Attributes:
        damping: regulariser weight is damping^2, as the projection stack's damping.
        accuracy: proxsuite's absolute tolerance eps_abs.
        max_qp_iterations: proxsuite's iteration cap per level.
    """

    name = "qp"

    def __init__(
        self,
        limits: JointLimits | None = None,
        damping: float = DEFAULT_DAMPING,
        accuracy: float = 1e-9,
        max_qp_iterations: int = 1000,
    ) -> None:
        super().__init__(limits)
        if not (damping > 0 and np.isfinite(damping)):
            raise InputError(f"damping must be a positive finite number, got {damping}")
        self.damping = float(damping)
        self.accuracy = float(accuracy)
        self.max_qp_iterations = int(max_qp_iterations)
        self._qps: dict[int, tuple[int, int, object]] = {}  # level -> (nv, n_eq, QP)

    def _qp(self, level: int, nv: int, n_eq: int):
        """The level's QP object: reused while its dimensions hold (returns it and 'is new')."""
        cached = self._qps.get(level)
        if cached is not None and cached[0] == nv and cached[1] == n_eq:
            return cached[2], False
        qp = proxsuite.proxqp.dense.QP(nv, n_eq, 0, True)
        qp.settings.eps_abs = self.accuracy
        qp.settings.eps_rel = 0.0
        qp.settings.max_iter = self.max_qp_iterations
        qp.settings.initial_guess = proxsuite.proxqp.InitialGuess.WARM_START_WITH_PREVIOUS_RESULT
        qp.settings.verbose = False
        self._qps[level] = (nv, n_eq, qp)
        return qp, True

    def compute_step(self, configuration: Configuration, levels: Levels) -> StepResult:
        built = build_levels(configuration, self.arrange(levels))
        nv = configuration.nv
        if self.limits is not None:
            lower, upper = self.limits.step_bounds(configuration.q)
        else:
            lower, upper = np.full(nv, -UNBOUNDED), np.full(nv, UNBOUNDED)
        dq = np.clip(np.zeros(nv), lower, upper)
        kept_rows: list[np.ndarray] = []  # rows whose values higher levels fixed
        failed: set[int] = set()
        identity = np.eye(nv)
        for index, level in enumerate(built):
            if level is None:
                continue
            if isinstance(level, GradientLevel):
                if level.step_size == 0.0:
                    continue
                hessian = identity / level.step_size
                linear = -level.direction
                rows = level.direction[None, :]
            else:
                hessian = level.A.T @ level.A + self.damping**2 * identity
                linear = -level.A.T @ level.b
                rows = level.A
            equality = np.vstack(kept_rows) if kept_rows else None
            equality_values = equality @ dq if kept_rows else None
            n_eq = 0 if equality is None else equality.shape[0]
            qp, is_new = self._qp(index, nv, n_eq)
            arguments = (hessian, linear, equality, equality_values, None, None, None, lower, upper)
            try:
                if is_new:
                    qp.init(*arguments)
                else:
                    qp.update(*arguments)
                qp.solve()
                solved = qp.results.info.status in _SOLVED and np.all(np.isfinite(qp.results.x))
            except (RuntimeError, ValueError):
                solved = False
            if not solved:
                failed.add(index)
                self._qps.pop(index, None)  # start afresh next time
                continue
            # proxsuite meets the box to eps_abs; clip so limits hold exactly.
            dq = np.clip(qp.results.x, lower, upper)
            kept_rows.append(rows)
        return StepResult(dq, report_levels(built, dq, failed))

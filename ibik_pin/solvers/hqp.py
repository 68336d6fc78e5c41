"""Hierarchical QP: the priority levels solved lexicographically with proxsuite, joint limits as bounds.

Level k searches its increment in the null space left by the higher levels, dq = dq_{k-1} + Z w
(Z orthonormal, as in the projection stack), which keeps every higher level's rows exactly where
they were, whatever the QP's tolerance. It solves
    least-squares level:  min |A_k (dq_{k-1} + Z w) - b_k|^2 + damping^2 |w|^2
    gradient level:       min -g.Z w + |w|^2 / (2 step_size)    (Z^T g of unit norm, as the stack)
subject to  lower - dq_{k-1} <= Z w <= upper - dq_{k-1}   (URDF position limits and per-step bounds).
Without an active bound this is exactly the projection stack's step. Every level is feasible
(w = 0 satisfies it); one whose target the bounds or higher levels forbid ends with a residual,
reported "relaxed" (the least-squares relaxation).

A level whose unconstrained optimum (the projection stack's step, one factorisation away) already respects
every bound needs no QP. Otherwise a primal active-set method solves it first (from w = 0, which is
feasible; one KKT solve per bound added or dropped; compiled, :mod:`ibik_pin.solvers.active_set`):
on real boxing it solved every level, in about 0.04 ms against proxsuite's 0.4 ms, and spared the
warm-started proxsuite solves that stalled for up to 1.4 s on nearly flat levels. Should it not
end, one proxsuite dense QP object per level, created once and updated, warm-started from its
previous result across iterations and frames, solves the level. Objects are kept per level and
size, so stacks of different shapes solved in turn (a tracker's targets-only steps, then its steps
with the image; a target dropped for a frame) each keep theirs. A backend failure
skips that level (reported "failed"), never raises.
"""

from __future__ import annotations

import functools

import numpy as np
import proxsuite

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
from ibik_pin.solvers.level_loop import StepWorkspace

UNBOUNDED = 1e20  # proxsuite's stand-in for an infinite bound
# How far [rad, m] the active-set answer may leave a bound: as proxsuite's, a bound on a coordinate
# that the higher levels have all but frozen (a null-space row of norm 1e-17..1e-12) must not block.
_FEASIBILITY = 1e-10
_SOLVED = {
    proxsuite.proxqp.QPSolverOutput.PROXQP_SOLVED,
    proxsuite.proxqp.QPSolverOutput.PROXQP_SOLVED_CLOSEST_PRIMAL_FEASIBLE,
}


class HierarchicalQPSolver(Solver):
    """Lexicographic QP stack on proxsuite with joint limits as inequality constraints.

    Built as every solver, with keyword arguments only; `damping` weighs damping^2 |w|^2 on each
    level's increment, as the stack's damping does.

    Attributes:
        accuracy: proxsuite's absolute tolerance eps_abs.
        max_qp_iterations: proxsuite's iteration cap per level.
        active_set: solve each level by the primal active-set method first (False: proxsuite on
            every level that a bound reaches).
    """

    name = "qp"

    def __init__(
        self,
        *,
        limits: JointLimits | None = None,
        damping: float = DEFAULT_DAMPING,
        accuracy: float = 1e-11,
        max_qp_iterations: int = 1000,
        active_set: bool = True,
    ) -> None:
        super().__init__(limits=limits, damping=damping)
        self.accuracy = float(accuracy)
        self.max_qp_iterations = int(max_qp_iterations)
        self.active_set = bool(active_set)
        self._qps: dict[tuple[int, int, int], object] = {}  # (level, n, n_in) -> QP
        self._workspace = StepWorkspace()

    def _qp(self, level: int, n: int, n_in: int):
        """The QP object of this level and size, created once; returns it and whether it is new."""
        cached = self._qps.get((level, n, n_in))
        if cached is not None:
            return cached, False
        qp = proxsuite.proxqp.dense.QP(n, 0, n_in)
        qp.settings.eps_abs = self.accuracy
        qp.settings.eps_rel = 0.0
        qp.settings.max_iter = self.max_qp_iterations
        qp.settings.initial_guess = proxsuite.proxqp.InitialGuess.WARM_START_WITH_PREVIOUS_RESULT
        qp.settings.verbose = False
        # Bounds active on coordinates that the level's rows barely move make proxsuite declare a
        # feasible problem "primal infeasible"; this mode returns the closest feasible point instead.
        qp.settings.primal_infeasibility_solving = True
        self._qps[(level, n, n_in)] = qp
        return qp, True

    def compute_step(self, configuration: Configuration, levels: Levels, plan: LevelPlan | None = None) -> StepResult:
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
                dq, null_basis, lower, upper, bounded=True, active_set=self.active_set, damping=self.damping,
                feasibility=_FEASIBILITY, start=start)
            if stopped == len(built):
                break
            # The active-set method did not end on this level (or is switched off): proxsuite's turn.
            w = self._solve_level(stopped, hessian, linear, null_basis, lower - dq, upper - dq)
            if w is None:
                failed[stopped] = "proxsuite: no solution"  # skipped: its null space is left to the levels below
            else:
                # proxsuite meets the bounds to eps_abs; clip so the limits hold exactly.
                dq = (dq + null_basis @ w).clip(lower, upper)
                if remaining.shape[0]:  # (0, 0) for the last level: nothing follows it
                    null_basis = null_basis @ remaining
            start = stopped + 1
        packed.finish()
        return StepResult(dq, functools.partial(report_levels, built, dq.copy(), failed), planned.criterion(built))

    def _solve_level(self, index, hessian, linear, constraint, lower, upper) -> np.ndarray | None:
        """proxsuite solve of min 1/2 w'Hw + g'w s.t. lower <= C w <= upper; None if it failed.

        A warm start from a distant previous answer occasionally stalls; the level is then solved
        once more from a fresh QP object before it counts as failed.
        """
        arguments = (hessian, linear, None, None, constraint, lower, upper)
        for _ in range(2):
            try:
                qp, is_new = self._qp(index, hessian.shape[0], constraint.shape[0])
                if is_new:
                    qp.init(*arguments)
                else:
                    qp.update(*arguments)
                qp.solve()
                w = qp.results.x
                if qp.results.info.status in _SOLVED and np.all(np.isfinite(w)):
                    return _polish(w, qp.results.z, hessian, linear, constraint, lower, upper)
            except (RuntimeError, ValueError):
                pass
            self._qps.pop((index, hessian.shape[0], constraint.shape[0]), None)
        return None


def _independent_rows(constraint: np.ndarray, candidates: list[int]) -> list[int]:
    """The candidates, in order, whose rows are linearly independent of the earlier ones.

    |R_jj| of the QR factorisation of the rows (as columns) is the distance of row j to the span of
    the rows before it.
    """
    if not candidates:
        return []
    rows = constraint[candidates]
    diagonal = np.abs(np.diag(np.linalg.qr(rows.T, mode="r")))
    scale = np.linalg.norm(rows, axis=1)[: diagonal.size]
    return [index for index, distance, norm in zip(candidates, diagonal, scale, strict=False) if distance > 1e-9 * norm]


def _polish(w, multipliers, hessian, linear, constraint, lower, upper, rounds: int = 6) -> np.ndarray:
    """Re-solve on proxsuite's active set to rounding precision.

    With the damping as the Hessian's smallest eigenvalue, proxsuite's tolerance on the dual
    residual leaves w accurate to about eps_abs / damping^2 only (1e-6 here), and near-dependent
    active bounds can leave it off by much more. Starting from proxsuite's active set (independent
    rows, largest multipliers first), a few active-set rounds solve the KKT system exactly, drop a
    bound whose multiplier has the wrong sign, add the most violated one. A feasible answer with
    right-signed multipliers is the optimum; if none is found, proxsuite's answer stands.
    """
    values = constraint @ w
    candidates = np.flatnonzero(
        ((multipliers > 0) & (upper - values < 1e-6)) | ((multipliers < 0) & (values - lower < 1e-6))
    )
    candidates = candidates[np.argsort(-np.abs(multipliers[candidates]))]
    chosen = _independent_rows(constraint, candidates.tolist())
    side_is_upper = {int(i): bool(multipliers[i] > 0) for i in chosen}
    n = hessian.shape[0]
    for _ in range(rounds):
        m = len(chosen)
        rows = constraint[chosen]
        kkt = np.zeros((n + m, n + m))
        kkt[:n, :n] = hessian
        kkt[:n, n:] = rows.T
        kkt[n:, :n] = rows
        upper_side = np.array([side_is_upper[i] for i in chosen], dtype=bool)
        targets = np.where(upper_side, upper[chosen], lower[chosen])
        try:
            solution = np.linalg.solve(kkt, np.concatenate([-linear, targets]))
        except np.linalg.LinAlgError:
            break
        polished, duals = solution[:n], solution[n:]
        # Multiplier sign: positive pushes against an upper bound, negative against a lower one.
        wrong_sign = np.where(upper_side, -duals, duals)
        if m and wrong_sign.max() > 1e-10:
            chosen.pop(int(np.argmax(wrong_sign)))
            continue
        polished_values = constraint @ polished
        violation = np.maximum(polished_values - upper, lower - polished_values)
        worst = int(np.argmax(violation))
        if violation[worst] <= 1e-10:
            return polished
        if worst in chosen or len(_independent_rows(constraint, chosen + [worst])) == len(chosen):
            break
        chosen.append(worst)
        side_is_upper[worst] = bool(polished_values[worst] > upper[worst])
    return w.copy()

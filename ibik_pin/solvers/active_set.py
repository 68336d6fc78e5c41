"""The primal active-set method of a bounded QP level, compiled (Numba).

Real motion touches the joint limits on most frames, so the hierarchical QP solves a bounded level
at about every other step. Each iteration of the method is a small KKT solve and a few products;
in numpy every one of them paid a wrapper's microseconds (np.linalg.solve alone 29 us), and the
method took 190 us a call on real boxing. Compiled, the same arithmetic runs in one call.
Compiled on first use and cached on disk, as the image kernels (:mod:`ibik_pin.vision.kernels`).
"""

from __future__ import annotations

import numpy as np
from numba import njit

__all__ = ["primal_active_set", "within_bounds"]


@njit(cache=True, nogil=True)
def within_bounds(values, lower, upper):
    """Whether lower <= values <= upper holds everywhere: the test, at every level of every step,
    of whether the active-set method is needed at all (numpy's comparisons and reductions cost five
    times this call)."""
    for i in range(values.shape[0]):  # noqa: SIM110 (Numba compiles the loop, not a generator)
        if not lower[i] <= values[i] <= upper[i]:
            return False
    return True


@njit(cache=True, nogil=True)
def _active_set(hessian, linear, constraint, lower, upper, feasibility):
    """The method on contiguous float64 arrays; returns (w, ended)."""
    n, rows = hessian.shape[0], constraint.shape[0]
    w = np.zeros(n)
    held = np.empty(rows, dtype=np.int64)
    held_upper = np.empty(rows, dtype=np.bool_)  # which side of each held bound
    m = 0
    for _ in range(2 * (n + rows)):
        kkt = np.zeros((n + m, n + m))
        kkt[:n, :n] = hessian
        for j in range(m):
            kkt[:n, n + j] = constraint[held[j]]
            kkt[n + j, :n] = constraint[held[j]]
        right = np.zeros(n + m)
        right[:n] = -(hessian @ w + linear)
        try:
            solution = np.linalg.solve(kkt, right)
        except Exception:  # singular KKT system: proxsuite takes the level
            return w, False
        step = solution[:n]
        if np.sqrt(step @ step) <= 1e-12 * (1.0 + np.sqrt(w @ w)):
            # Multiplier sign: positive pushes against an upper bound, negative against a lower one.
            release, worst = -1, 1e-10
            for j in range(m):
                wrong_sign = -solution[n + j] if held_upper[j] else solution[n + j]
                if wrong_sign > worst:
                    release, worst = j, wrong_sign
            if release < 0:
                return w, True
            for j in range(release, m - 1):
                held[j] = held[j + 1]
                held_upper[j] = held_upper[j + 1]
            m -= 1
            continue
        values = constraint @ w
        moves = constraint @ step
        blocking, smallest = -1, np.inf
        for row in range(rows):
            is_held = False
            for j in range(m):
                if held[j] == row:
                    is_held = True
                    break
            if is_held:
                continue
            moved = values[row] + moves[row]
            if moves[row] > 0.0 and moved - upper[row] > feasibility:
                ratio = (upper[row] - values[row]) / moves[row]
            elif moves[row] < 0.0 and lower[row] - moved > feasibility:
                ratio = (lower[row] - values[row]) / moves[row]
            else:
                continue
            if ratio < smallest:
                blocking, smallest = row, ratio
        if blocking < 0 or smallest >= 1.0:
            w = w + step
            continue
        w = w + max(smallest, 0.0) * step
        held[m] = blocking
        held_upper[m] = moves[blocking] > 0.0
        m += 1
    return w, False


def primal_active_set(hessian: np.ndarray, linear: np.ndarray, constraint: np.ndarray, lower: np.ndarray,
                      upper: np.ndarray, feasibility: float) -> np.ndarray | None:
    """min 1/2 w'Hw + g'w s.t. lower <= C w <= upper by the primal active-set method; None if it
    does not end (then proxsuite solves the level).

    From w = 0 (feasible: the higher levels' step lies within the bounds), each iteration solves the
    KKT system of the bounds held, steps toward its answer until a bound blocks (then held) or
    reaches it; there, the held bound whose multiplier pulls most the wrong way is released, and
    with none w is the optimum (H is positive definite: the optimum is unique). A bound that a
    blocked step would leave by no more than `feasibility` never blocks, so held rows stay
    independent of each other and the KKT system regular.

    Args:
        hessian: H (n, n), positive definite; linear: g (n,); constraint: C (rows, n);
        lower, upper: (rows,) bounds with lower <= 0 <= upper (w = 0 feasible).
        feasibility: how far a blocked step may leave a bound without blocking.
    """
    w, ended = _active_set(np.ascontiguousarray(hessian, dtype=np.float64),
                           np.ascontiguousarray(linear, dtype=np.float64),
                           np.ascontiguousarray(constraint, dtype=np.float64),
                           np.ascontiguousarray(lower, dtype=np.float64),
                           np.ascontiguousarray(upper, dtype=np.float64), float(feasibility))
    return w if ended else None

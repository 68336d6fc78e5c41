"""The primal active-set method of a bounded QP level, compiled (Numba).

Real motion touches the joint limits on most frames, so the hierarchical QP solves a bounded level
at about every other step. Each iteration of the method is a small KKT solve (through the Schur
complement of the held bounds, H factored once) and a few products; in numpy every one of them paid
a wrapper's microseconds (np.linalg.solve alone 29 us), and the method took 190 us a call on real
boxing. Compiled, the same arithmetic runs in one call.
The compiled method is :func:`ibik_pin.solvers.kernels.active_set_method` (with `within_bounds`, the
test of whether a level needs it); the level loop calls it there.
"""

from __future__ import annotations

import numpy as np

from ibik_pin.solvers.kernels import active_set_method, within_bounds

__all__ = ["primal_active_set", "within_bounds"]


def primal_active_set(hessian: np.ndarray, linear: np.ndarray, constraint: np.ndarray, lower: np.ndarray,
                      upper: np.ndarray, feasibility: float) -> np.ndarray | None:
    """min 1/2 w'Hw + g'w s.t. lower <= C w <= upper by the primal active-set method; None if it
    does not end (the level is then reported "failed": ActiveSetBackend).

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
    w, ended = active_set_method(np.ascontiguousarray(hessian, dtype=np.float64),
                                 np.ascontiguousarray(linear, dtype=np.float64),
                                 np.ascontiguousarray(constraint, dtype=np.float64),
                                 np.ascontiguousarray(lower, dtype=np.float64),
                                 np.ascontiguousarray(upper, dtype=np.float64), float(feasibility))
    return w if ended else None

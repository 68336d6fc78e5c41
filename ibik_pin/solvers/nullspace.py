"""Null-space bookkeeping shared by the projection stack and the hierarchical QP.

The projector P_k of the recursive stack is kept as an orthonormal basis Z_k of the remaining null
space (P_k = Z_k Z_k^T), computed from one column-pivoted QR factorisation of each level's
projected Jacobian J_k Z_{k-1} (the last level, which leaves nothing to lower ones, needs only its
damped least squares: one Cholesky solve).
"""

from __future__ import annotations

import numpy as np
from scipy.linalg import lapack

from ibik_pin.exceptions import SolverError
from ibik_pin.solvers.base import GradientLevel, vector_norm

# Directions of a level's matrix weaker than RANK_TOLERANCE * max(1, its largest) count as its null
# space (the diagonal of the pivoted QR's R, as a singular value would): small enough that lower
# levels leak < 1e-8 into higher ones, while damping keeps the steps bounded.
RANK_TOLERANCE = 1e-10


def _factor(projected: np.ndarray, damping: float) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """What damped_solve needs of a level's projected Jacobian M (m, r): Q_k (r, k), (M Q_k)^T
    (k, m), the Cholesky factor of (M Q_k)^T (M Q_k) + damping^2 I (k, k) and the basis (r, r') of
    M's null space (all read-only: a memo may hand them out again).

    Column-pivoted QR of M^T (LAPACK's geqp3), M^T P = Q R: the first k columns of Q (k the rank,
    the diagonal of R above RANK_TOLERANCE) span the range of M^T, where the damped least squares
    lives, and the others M's null space. With w = Q_k y the problem is
    min |M Q_k y - residual|^2 + damping^2 |y|^2, a k x k Cholesky solve. On the stack's levels
    (21 x 28, 18 x 18) about half the SVD's time, the same step and null space to rounding.
    """
    rows, size = projected.shape
    packed, _, reflectors, _, info = lapack.dgeqp3(np.asfortranarray(projected.T))
    if info != 0:
        raise SolverError(f"the QR factorisation of a level's projected Jacobian {projected.shape} failed: "
                          f"LAPACK's geqp3 returned {info}")
    diagonal = np.abs(packed.diagonal())  # non-increasing: each pivot takes the largest column left
    rank = int(np.count_nonzero(diagonal > RANK_TOLERANCE * max(1.0, diagonal[0] if diagonal.size else 0.0)))
    if rows < size:  # Q is r x r: the reflectors past the m-th are identities
        square = np.zeros((size, size), order="F")
        square[:, :rows] = packed
        reflectors = np.concatenate([reflectors, np.zeros(size - rows)])
    else:
        square = packed[:, :size]
    q, _, info = lapack.dorgqr(square, reflectors)
    basis = np.ascontiguousarray(q[:, :rank])
    reduced = basis.T @ projected.T  # (M Q_k)^T = R_k P^T
    normal = reduced @ reduced.T
    normal.flat[::rank + 1] += damping**2  # the diagonal
    cholesky, info_cholesky = lapack.dpotrf(normal)
    if info != 0 or info_cholesky != 0:
        raise SolverError(f"the factors of a level's projected Jacobian {projected.shape} failed: LAPACK's "
                          f"orgqr returned {info}, potrf {info_cholesky}")
    factors = (basis, reduced, cholesky, np.ascontiguousarray(q[:, rank:]))
    for array in factors:
        array.flags.writeable = False
    return factors


class FactorMemo:
    """The factors of the last matrix of each shape, given again while the same matrix (to the bit)
    comes back.

    The first level of a step sees the whole null space, so its matrix is its tasks' rows alone:
    the tracker's trunk hold tops every image step with the same rows (2004 of 2005 steps on
    boxing_a, 2 views), and a factorisation costs tens of microseconds where a comparison costs one.
    """

    def __init__(self) -> None:
        self._factors: dict[tuple[tuple[int, ...], float], tuple[bytes, tuple]] = {}

    def factor(self, projected: np.ndarray, damping: float) -> tuple:
        key, content = (projected.shape, damping), projected.tobytes()
        kept = self._factors.get(key)
        if kept is None or kept[0] != content:
            kept = self._factors[key] = (content, _factor(projected, damping))
        return kept[1]


def damped_solve(
    projected: np.ndarray, residual: np.ndarray, damping: float, memo: FactorMemo | None = None
) -> tuple[np.ndarray, np.ndarray]:
    """Damped least squares in null-space coordinates, and the null space left after it.

    Args:
        projected: J_k Z_{k-1}, shape (m, r).
        residual: b_k - J_k dq_{k-1}, shape (m,).
        damping: lambda of (JZ)^T ((JZ)(JZ)^T + lambda^2 I)^-1.
        memo: where the factors of a matrix that comes back are kept (None: computed every call).

    Returns:
        w: the step in null-space coordinates, shape (r,).
        remaining: orthonormal basis of null(J_k Z_{k-1}) in those coordinates, shape (r, r'),
            read-only.

    Raises:
        SolverError: LAPACK failed to factor the matrix.
    """
    basis, reduced, cholesky, remaining = (_factor(projected, damping) if memo is None
                                           else memo.factor(projected, damping))
    if not basis.shape[1]:
        return np.zeros(projected.shape[1]), remaining
    return basis @ lapack.dpotrs(cholesky, reduced @ residual)[0], remaining


def damped_step(projected: np.ndarray, residual: np.ndarray, damping: float) -> np.ndarray:
    """w of damped_solve alone, for a level that leaves no null space to lower ones (the last):
    one Cholesky solve of the smaller normal equations, M^T (M M^T + damping^2 I)^-1 residual.

    Raises:
        SolverError: the normal equations are not positive definite (a non-finite matrix).
    """
    rows, size = projected.shape
    if rows <= size:
        normal, right = projected @ projected.T, residual
    else:
        normal, right = projected.T @ projected, projected.T @ residual
    normal.flat[::normal.shape[0] + 1] += damping**2  # the diagonal
    _, solution, info = lapack.dposv(normal, right)
    if info != 0:
        raise SolverError(f"the damped normal equations of a level's projected Jacobian {projected.shape} "
                          f"failed: LAPACK's posv returned {info}")
    return projected.T @ solution if rows <= size else solution


def remove_direction(reduced: np.ndarray) -> np.ndarray:
    """Orthonormal basis of the complement of one direction, shape (r, r - 1) (or (r, r) if zero)."""
    norm = vector_norm(reduced)
    if norm <= RANK_TOLERANCE:
        return np.eye(reduced.size)
    _, _, vt, _ = lapack.dgesdd(reduced[None, :] / norm, compute_uv=1, full_matrices=1)
    return np.ascontiguousarray(vt[1:].T)


def unit_reduced_direction(null_basis: np.ndarray, direction: np.ndarray) -> np.ndarray | None:
    """Z^T g / |Z^T g|: a gradient in null-space coordinates, of unit norm; None if it vanishes."""
    reduced = null_basis.T @ direction
    norm = vector_norm(reduced)
    return None if norm <= RANK_TOLERANCE else reduced / norm


def unconstrained_level_step(level, null_basis: np.ndarray, dq: np.ndarray, damping: float,
                             memo: FactorMemo | None = None, last: bool = False):
    """A level's optimum without bounds, in null-space coordinates, and the null space it leaves.

    Args:
        level: a LeastSquaresLevel (damped least squares) or a GradientLevel (its adapted step size
            along the unit projected gradient).
        null_basis: Z, shape (nv, r); dq: the higher levels' step, shape (nv,).
        memo: kept factors of a least-squares level's matrix (see FactorMemo).
        last: no level follows, so the null space left is not needed (None) and a least-squares
            level's step is one Cholesky solve (damped_step).

    Returns:
        (w (r,), remaining (r, r') or None when last), or None when a gradient level has nothing
        to climb.
    """
    if isinstance(level, GradientLevel):
        reduced = unit_reduced_direction(null_basis, level.direction)
        if reduced is None:
            return None
        step_size = level.step_size_along(null_basis @ reduced)
        return step_size * reduced, None if last else remove_direction(reduced)
    projected, residual = level.A @ null_basis, level.b - level.A @ dq
    if last:
        return damped_step(projected, residual, damping), None
    return damped_solve(projected, residual, damping, memo)

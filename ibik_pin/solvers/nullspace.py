"""Null-space bookkeeping shared by the projection stack and the hierarchical QP.

The projector P_k of the recursive stack is kept as an orthonormal basis Z_k of the remaining null
space (P_k = Z_k Z_k^T), computed from one SVD of each level's projected Jacobian J_k Z_{k-1}.
"""

from __future__ import annotations

import numpy as np
from scipy.linalg import lapack

from ibik_pin.exceptions import SolverError
from ibik_pin.solvers.base import GradientLevel, vector_norm

# Singular values below RANK_TOLERANCE * max(1, sigma_max) count as zero for the null space: small
# enough that lower levels leak < 1e-8 into higher ones, while damping keeps the steps bounded.
RANK_TOLERANCE = 1e-10


def _svd(matrix: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray, int]:
    """U, sigma, V^T (full) and LAPACK's status of a small matrix: the gesdd that np.linalg.svd
    calls, called directly, which spares numpy's wrapper a quarter of the time on these sizes.
    U and V^T come back in C order, as numpy's: the products that use them then round alike."""
    u, sigma, vt, info = lapack.dgesdd(matrix, compute_uv=1, full_matrices=1)
    return np.ascontiguousarray(u), sigma, np.ascontiguousarray(vt), info


def _factor(projected: np.ndarray, damping: float) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """What damped_solve needs of a level's projected Jacobian: U_r^T, the damped inverse singular
    values, V_r (r = its rank) and the basis of its null space (read-only: a memo may hand them out
    again)."""
    u, sigma, vt, info = _svd(projected)
    if info != 0:
        raise SolverError(f"the SVD of a level's projected Jacobian {projected.shape} failed: LAPACK's gesdd "
                          f"returned {info}")
    rank = np.count_nonzero(sigma > RANK_TOLERANCE * max(1.0, sigma[0] if sigma.size else 0.0))
    damped = sigma[:rank] / (sigma[:rank] ** 2 + damping**2)
    for array in (u, vt, damped):
        array.flags.writeable = False
    return u[:, :rank].T, damped, vt[:rank].T, vt[rank:].T


class FactorMemo:
    """The factors of the last matrix of each shape, given again while the same matrix (to the bit)
    comes back.

    The first level of a step sees the whole null space, so its matrix is its tasks' rows alone:
    the tracker's trunk hold tops every image step with the same rows (2004 of 2005 steps on
    boxing_a, 2 views), and an SVD costs tens of microseconds where a comparison costs one.
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
        SolverError: LAPACK's SVD did not converge.
    """
    u_rank_t, damped, v_rank, remaining = (_factor(projected, damping) if memo is None
                                           else memo.factor(projected, damping))
    return v_rank @ (damped * (u_rank_t @ residual)), remaining


def remove_direction(reduced: np.ndarray) -> np.ndarray:
    """Orthonormal basis of the complement of one direction, shape (r, r - 1) (or (r, r) if zero)."""
    norm = vector_norm(reduced)
    if norm <= RANK_TOLERANCE:
        return np.eye(reduced.size)
    _, _, vt, _ = _svd(reduced[None, :] / norm)
    return vt[1:].T


def unit_reduced_direction(null_basis: np.ndarray, direction: np.ndarray) -> np.ndarray | None:
    """Z^T g / |Z^T g|: a gradient in null-space coordinates, of unit norm; None if it vanishes."""
    reduced = null_basis.T @ direction
    norm = vector_norm(reduced)
    return None if norm <= RANK_TOLERANCE else reduced / norm


def unconstrained_level_step(level, null_basis: np.ndarray, dq: np.ndarray, damping: float,
                             memo: FactorMemo | None = None):
    """A level's optimum without bounds, in null-space coordinates, and the null space it leaves.

    Args:
        level: a LeastSquaresLevel (damped least squares) or a GradientLevel (its adapted step size
            along the unit projected gradient).
        null_basis: Z, shape (nv, r); dq: the higher levels' step, shape (nv,).
        memo: kept factors of a least-squares level's matrix (see FactorMemo).

    Returns:
        (w (r,), remaining (r, r')), or None when a gradient level has nothing to climb.
    """
    if isinstance(level, GradientLevel):
        reduced = unit_reduced_direction(null_basis, level.direction)
        if reduced is None:
            return None
        step_size = level.step_size_along(null_basis @ reduced)
        return step_size * reduced, remove_direction(reduced)
    return damped_solve(level.A @ null_basis, level.b - level.A @ dq, damping, memo)

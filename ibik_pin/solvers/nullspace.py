"""Null-space factorisations of the levels.

Level k of the projection stack and the hierarchical QP searches its increment in the null space
left by the higher levels, dq = dq_{k-1} + Z w, with Z an orthonormal basis of that null space (the
projector of the recursive stack is Z Z^T). A least-squares level takes the damped least squares of
(J_k Z) w = b_k - J_k dq_{k-1}; its step and the null space it leaves come from one
column-pivoted Householder QR of (J_k Z)^T and a Cholesky solve; columns that the rows leave at
zero stay free without being factored. The last level, which leaves nothing below it, needs the
Cholesky solve of its smaller normal equations only; rows that each hold one coordinate need no
factorisation. A gradient level uses up one direction. The arithmetic is compiled, in
:mod:`ibik_pin.solvers.kernels` with the level loop that calls it; these are its entry points from
Python (the level outcomes' reports, tests).
"""

from __future__ import annotations

import numpy as np

from ibik_pin.exceptions import SolverError
from ibik_pin.solvers import kernels
from ibik_pin.solvers.kernels import RANK_TOLERANCE

__all__ = ["RANK_TOLERANCE", "damped_solve", "damped_step", "range_residual", "remove_direction"]


def damped_solve(projected: np.ndarray, residual: np.ndarray, damping: float) -> tuple[np.ndarray, np.ndarray]:
    """Damped least squares in null-space coordinates, and the null space left after it.

    Args:
        projected: J_k Z_{k-1}, shape (m, r).
        residual: b_k - J_k dq_{k-1}, shape (m,).
        damping: lambda of (JZ)^T ((JZ)(JZ)^T + lambda^2 I)^-1.

    Returns:
        w: the step in null-space coordinates, shape (r,).
        remaining: orthonormal basis of null(J_k Z_{k-1}) in those coordinates, shape (r, r').

    Raises:
        SolverError: the matrix could not be factored (non-finite).
    """
    w, remaining, ok = kernels.damped_solve(np.ascontiguousarray(projected, dtype=np.float64),
                                           np.ascontiguousarray(residual, dtype=np.float64), float(damping))
    if not ok:
        raise SolverError(f"the factors of a level's projected Jacobian {projected.shape} failed "
                          "(a non-finite matrix?)")
    return w, remaining


def damped_step(projected: np.ndarray, residual: np.ndarray, damping: float) -> np.ndarray:
    """w of damped_solve alone, for a level that leaves no null space to lower ones (the last).

    Raises:
        SolverError: the normal equations are not positive definite (a non-finite matrix).
    """
    w, ok = kernels.damped_step(np.ascontiguousarray(projected, dtype=np.float64),
                                np.ascontiguousarray(residual, dtype=np.float64), float(damping))
    if not ok:
        raise SolverError(f"the damped normal equations of a level's projected Jacobian {projected.shape} "
                          "are not positive definite (a non-finite matrix?)")
    return w


def range_residual(matrix: np.ndarray, vector: np.ndarray) -> float:
    """|vector - its projection on the range of a matrix (m, n)|, the matrix's rank counted as the
    levels' factorisation counts it (the column-pivoted QR of damped_solve, here of the matrix's
    transpose), the basis never formed.

    Raises:
        SolverError: the matrix or the vector is not finite.
    """
    matrix = np.ascontiguousarray(np.transpose(matrix), dtype=np.float64)
    vector = np.ascontiguousarray(vector, dtype=np.float64)
    if not (np.isfinite(matrix).all() and np.isfinite(vector).all()):
        raise SolverError(f"the range of a {matrix.shape[::-1]} matrix: expected finite numbers")
    return float(kernels.range_residual(matrix, vector))


def remove_direction(reduced: np.ndarray) -> np.ndarray:
    """Orthonormal basis of the complement of one direction, shape (r, r - 1) (or (r, r) if zero)."""
    reduced = np.ascontiguousarray(reduced, dtype=np.float64)
    norm = float(np.sqrt(reduced @ reduced))
    if norm <= RANK_TOLERANCE:
        return np.eye(reduced.size)
    return kernels.complement(reduced / norm)

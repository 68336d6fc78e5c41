"""Null-space factorisations of the levels, compiled (Numba).

Level k of the projection stack and the hierarchical QP searches its increment in the null space
left by the higher levels, dq = dq_{k-1} + Z w, with Z an orthonormal basis of that null space (the
projector of the recursive stack is Z Z^T). A least-squares level takes the damped least squares of
(J_k Z) w = b_k - J_k dq_{k-1}; its step and the null space it leaves come from one
column-pivoted Householder QR of (J_k Z)^T and a Cholesky solve (`_factor`). The last level, which
leaves nothing below it, needs the Cholesky solve of its smaller normal equations only
(`_damped_step`); rows that each hold one coordinate need no factorisation (`_coordinate_solve`). A
gradient level uses up one direction (`_complement`). The loop over the levels that calls them is
:mod:`ibik_pin.solvers.level_loop`.

Why compiled: the levels are small (at most 44 columns and 38 rows on the human), and on real
boxing each of their numpy and LAPACK calls cost microseconds of wrapper around a few hundred
nanoseconds of arithmetic.
"""

from __future__ import annotations

import numpy as np
from numba import njit

from ibik_pin.exceptions import SolverError

# Directions of a level's matrix weaker than RANK_TOLERANCE * max(1, its largest) count as its null
# space (the diagonal of the pivoted QR's R, as a singular value would): small enough that lower
# levels leak < 1e-8 into higher ones, while damping keeps the steps bounded.
RANK_TOLERANCE = 1e-10


@njit(cache=True, nogil=True)
def _cholesky(matrix):
    """Lower Cholesky factor L of a symmetric matrix, and whether it is positive definite."""
    n = matrix.shape[0]
    factor = np.zeros((n, n))
    for j in range(n):
        pivot = matrix[j, j]
        for k in range(j):
            pivot -= factor[j, k] * factor[j, k]
        if not pivot > 0.0:  # also NaN
            return factor, False
        diagonal = np.sqrt(pivot)
        factor[j, j] = diagonal
        for i in range(j + 1, n):
            value = matrix[i, j]
            for k in range(j):
                value -= factor[i, k] * factor[j, k]
            factor[i, j] = value / diagonal
    return factor, True


@njit(cache=True, nogil=True)
def _cholesky_solve(factor, right):
    """x of L L^T x = right."""
    n = factor.shape[0]
    x = right.copy()
    for i in range(n):
        value = x[i]
        for k in range(i):
            value -= factor[i, k] * x[k]
        x[i] = value / factor[i, i]
    for i in range(n - 1, -1, -1):
        value = x[i]
        for k in range(i + 1, n):
            value -= factor[k, i] * x[k]
        x[i] = value / factor[i, i]
    return x


@njit(cache=True, nogil=True)
def _factor(projected, damping):
    """The damped least squares' factors of a level's projected Jacobian M (m, r), and its null space.

    Column-pivoted Householder QR of M^T, M^T P = Q R: the first k columns of Q (k the rank, the
    diagonal of R above RANK_TOLERANCE) span the range of M^T, where the damped least squares
    lives, and the others M's null space. With w = Q_k y the problem is
    min |M Q_k y - residual|^2 + damping^2 |y|^2, a k x k Cholesky solve.

    Returns:
        Q_k (r, k), (M Q_k)^T (k, m), the Cholesky factor of (M Q_k)^T (M Q_k) + damping^2 I
        (k, k), the null-space basis (r, r - k), and whether the factorisation held.
    """
    rows, size = projected.shape
    # M^T's columns are M's rows: Householder on rows of a copy keeps every inner loop contiguous.
    # After step j, row c holds R[:j+1, c] in its first entries and, for c <= j, the reflector
    # v_j = (1, work[j, j+1:]) past the diagonal.
    work = projected.copy()
    pivots = np.arange(rows)
    taus = np.zeros(min(rows, size))
    rank, largest = 0, 0.0
    for j in range(min(rows, size)):
        best, best_squared = j, -1.0  # the remaining column of largest norm, as LAPACK's geqp3
        for c in range(j, rows):
            squared = 0.0
            for i in range(j, size):
                squared += work[c, i] * work[c, i]
            if squared > best_squared:
                best, best_squared = c, squared
        norm = np.sqrt(best_squared)
        if j == 0:
            largest = norm
        if norm <= RANK_TOLERANCE * max(1.0, largest):
            break  # the norms left only decrease: the rank is j
        if best != j:
            for i in range(size):
                work[j, i], work[best, i] = work[best, i], work[j, i]
            pivots[j], pivots[best] = pivots[best], pivots[j]
        alpha = work[j, j]
        beta = -norm if alpha >= 0.0 else norm  # the sign that avoids cancellation
        scale = 1.0 / (alpha - beta)
        for i in range(j + 1, size):
            work[j, i] *= scale
        taus[j] = (beta - alpha) / beta
        work[j, j] = beta
        for c in range(j + 1, rows):  # H_j = I - tau v v^T on the columns to the right
            dot = work[c, j]
            for i in range(j + 1, size):
                dot += work[j, i] * work[c, i]
            dot *= taus[j]
            work[c, j] -= dot
            for i in range(j + 1, size):
                work[c, i] -= dot * work[j, i]
        rank = j + 1
    # Q = H_0 ... H_{k-1}, accumulated backwards on its transpose (rows of qt are columns of Q):
    # before H_j, the columns left of j are still those of the identity, which H_j leaves alone.
    qt = np.eye(size)
    for j in range(rank - 1, -1, -1):
        for c in range(j, size):
            dot = qt[c, j]
            for i in range(j + 1, size):
                dot += work[j, i] * qt[c, i]
            dot *= taus[j]
            qt[c, j] -= dot
            for i in range(j + 1, size):
                qt[c, i] -= dot * work[j, i]
    reduced = np.zeros((rank, rows))  # (M Q_k)^T = R_k P^T
    for c in range(rows):
        for i in range(min(c + 1, rank)):
            reduced[i, pivots[c]] = work[c, i]
    normal = reduced @ reduced.T
    for i in range(rank):
        normal[i, i] += damping * damping
    cholesky, ok = _cholesky(normal)
    return (np.ascontiguousarray(qt[:rank].T), reduced, cholesky, np.ascontiguousarray(qt[rank:].T),
            ok and np.isfinite(work).all())


@njit(cache=True, nogil=True)
def _damped_solve(projected, residual, damping):
    """w of the damped least squares and the null space left (see `damped_solve`), and success."""
    basis, reduced, cholesky, remaining, ok = _factor(projected, damping)
    if not ok or basis.shape[1] == 0:
        return np.zeros(projected.shape[1]), remaining, ok
    return basis @ _cholesky_solve(cholesky, reduced @ residual), remaining, ok


@njit(cache=True, nogil=True)
def _coordinate_solve(projected, residual, damping):
    """The damped least squares of a matrix whose rows are each a multiple of a distinct unit
    vector (a posture task on some coordinates, over coordinates as yet untouched): w and the
    columns it leaves free; both empty (and False) for any other matrix.

    The matrix is its own QR factorisation: the rank test and the step of `_factor`, without its
    arithmetic (the tracker's trunk hold tops every image step).
    """
    rows, size = projected.shape
    columns = np.full(rows, -1)
    used = np.zeros(size, dtype=np.bool_)
    largest = 0.0
    for i in range(rows):
        for j in range(size):
            if projected[i, j] != 0.0:
                if columns[i] >= 0 or used[j]:
                    return np.zeros(0), np.zeros(0, dtype=np.int64), False
                columns[i], used[j] = j, True
                largest = max(largest, abs(projected[i, j]))
    w = np.zeros(size)
    free = np.ones(size, dtype=np.bool_)
    for i in range(rows):
        if columns[i] >= 0:
            scale = projected[i, columns[i]]
            if abs(scale) > RANK_TOLERANCE * max(1.0, largest):
                w[columns[i]] = scale * residual[i] / (scale * scale + damping * damping)
                free[columns[i]] = False
    return w, np.flatnonzero(free), True


@njit(cache=True, nogil=True)
def _damped_step(projected, residual, damping):
    """w of the damped least squares alone, M^T (M M^T + damping^2 I)^-1 residual, from the smaller
    normal equations; and success."""
    rows, size = projected.shape
    if rows <= size:
        normal, right = projected @ projected.T, residual.copy()
    else:
        normal, right = projected.T @ projected, projected.T @ residual
    for i in range(normal.shape[0]):
        normal[i, i] += damping * damping
    cholesky, ok = _cholesky(normal)
    if not ok:
        return np.zeros(size), False
    solution = _cholesky_solve(cholesky, right)
    return (projected.T @ solution if rows <= size else solution), True


@njit(cache=True, nogil=True)
def _complement(unit):
    """Orthonormal basis (r, r - 1) of the directions orthogonal to a unit vector: the columns past
    the first of the Householder reflection that takes the vector to the first axis."""
    size = unit.shape[0]
    v = unit.copy()
    v[0] += 1.0 if unit[0] >= 0.0 else -1.0
    scale = 2.0 / (v @ v)
    basis = np.empty((size, size - 1))
    for i in range(size):
        for c in range(1, size):
            basis[i, c - 1] = (1.0 if i == c else 0.0) - scale * v[i] * v[c]
    return basis


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
    w, remaining, ok = _damped_solve(np.ascontiguousarray(projected, dtype=np.float64),
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
    w, ok = _damped_step(np.ascontiguousarray(projected, dtype=np.float64),
                         np.ascontiguousarray(residual, dtype=np.float64), float(damping))
    if not ok:
        raise SolverError(f"the damped normal equations of a level's projected Jacobian {projected.shape} "
                          "are not positive definite (a non-finite matrix?)")
    return w


def remove_direction(reduced: np.ndarray) -> np.ndarray:
    """Orthonormal basis of the complement of one direction, shape (r, r - 1) (or (r, r) if zero)."""
    reduced = np.ascontiguousarray(reduced, dtype=np.float64)
    norm = float(np.sqrt(reduced @ reduced))
    if norm <= RANK_TOLERANCE:
        return np.eye(reduced.size)
    return _complement(reduced / norm)

"""The solvers' compiled code (Numba): the level loop and everything it calls.

- :func:`solve_levels`: the levels of the projection stack and the hierarchical QP, highest first,
  each in the null space of those above it (:mod:`ibik_pin.solvers.level_loop` packs them), and
  :func:`solve_levels_step`, its step alone;
- :func:`factor`, :func:`damped_solve`, :func:`damped_step`, :func:`coordinate_solve`,
  :func:`complement`: a level's damped least squares and the null space it leaves
  (:mod:`ibik_pin.solvers.nullspace`);
- :func:`active_set_method`, :func:`within_bounds`: a bounded QP level by the primal active-set method
  (:mod:`ibik_pin.solvers.active_set`);
- :func:`adapt_step_size`: the image step's Rprop rule (:mod:`ibik_pin.solvers.step_adaptation`).

Why compiled: the levels are small (at most 44 columns and 38 rows on the human), and on real
boxing each of their numpy and LAPACK calls cost microseconds of wrapper around a few hundred
nanoseconds of arithmetic: the level loop was a third of the QP's step. Compiled on first use and
cached on disk, as the image kernels (:mod:`ibik_pin.vision.kernels`); the loop with all it calls
takes about 17 s to compile on a 2-core machine, once. The Cholesky factors are LAPACK's (numpy's
cholesky, which Numba compiles to potrf: a hand-written one measured no faster on the real step);
the pivoted QR is a compiled copy of geqp3's (see `householder`).

This module is long because Numba's on-disk cache checks only the file of the function it compiles:
with the loop in one file and a function it calls in another, a change to the latter would leave
the loop's cached code stale. Everything the loop calls lives here.
"""

from __future__ import annotations

import numpy as np
from numba import njit

# Directions of a level's matrix weaker than RANK_TOLERANCE * max(1, its largest) count as its null
# space (the diagonal of the pivoted QR's R, as a singular value would): small enough that lower
# levels leak < 1e-8 into higher ones, while damping keeps the steps bounded.
RANK_TOLERANCE = 1e-10


@njit(cache=True, nogil=True)
def cholesky(matrix):
    """Lower Cholesky triangle L of a symmetric matrix (LAPACK's potrf, as numpy's), and whether it
    is positive definite (False also for NaN or infinity)."""
    try:
        triangle = np.linalg.cholesky(matrix)
    except Exception:  # numpy's LinAlgError; Numba catches exceptions by base class only
        return np.zeros_like(matrix), False
    # Numba's potrf does not check finiteness: a NaN or infinity below the diagonal reaches L's
    # diagonal in its row.
    return triangle, np.isfinite(np.diag(triangle)).all()


@njit(cache=True, nogil=True)
def cholesky_solve(triangle, right):
    """x of L L^T x = right: the two triangular solves of LAPACK's potrs (scipy's cho_solve),
    written out: Numba offers no triangular solve, and a general one (np.linalg.solve) would
    factor L again."""
    n = triangle.shape[0]
    x = right.copy()
    for i in range(n):
        value = x[i]
        for k in range(i):
            value -= triangle[i, k] * x[k]
        x[i] = value / triangle[i, i]
    for i in range(n - 1, -1, -1):
        value = x[i]
        for k in range(i + 1, n):
            value -= triangle[k, i] * x[k]
        x[i] = value / triangle[i, i]
    return x


@njit(cache=True, nogil=True, inline="always")
def reflect(row, reflector, j, tau):
    """row[j:] (I - tau v v^T), v = (1, reflector[j + 1:]): the Householder reflection H_j applied to
    a vector stored as a row, in place."""
    dot = row[j]
    for i in range(j + 1, row.shape[0]):
        dot += reflector[i] * row[i]
    dot *= tau
    row[j] -= dot
    for i in range(j + 1, row.shape[0]):
        row[i] -= dot * reflector[i]


@njit(cache=True, nogil=True)
def householder(work):
    """Column-pivoted Householder QR of work^T, in place, as LAPACK's geqp3 pivots, stopped at the
    rank (the first remaining column norm at or below RANK_TOLERANCE times the largest, or 1).

    A compiled copy because it runs inside the compiled level loop at every least-squares level:
    scipy.linalg.qr(pivoting=True) called from Python cost 155-265 us on the levels' sizes (12 x 26
    to 9 x 44) against 31-43 us here (tests/test_solver_kernels.py checks it against scipy's).

    work^T's columns are work's rows: Householder on rows keeps every inner loop contiguous. After
    step j, row c holds R[:j+1, c] in its first entries and, for c <= j, the reflector
    v_j = (1, work[j, j+1:]) past the diagonal.

    Returns:
        the row permutation (pivots), the reflectors' taus and the rank k.
    """
    rows, size = work.shape
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
        for c in range(j + 1, rows):  # H_j on the columns to the right
            reflect(work[c], work[j], j, taus[j])
        rank = j + 1
    return pivots, taus, rank


@njit(cache=True, nogil=True)
def range_residual(columns, vector):
    """|vector - its projection on the span of the rows of `columns`| (n, m), the rank counted as
    `factor` counts it, without forming the basis: the reflectors of `householder` applied to the
    vector leave its component outside the span in its entries past the rank."""
    work = columns.copy()
    _, taus, rank = householder(work)
    rest = vector.copy()
    for j in range(rank):
        reflect(rest, work[j], j, taus[j])
    total = 0.0
    for i in range(rank, rest.shape[0]):
        total += rest[i] * rest[i]
    return np.sqrt(total)


@njit(cache=True, nogil=True)
def factor(projected, damping):
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
    work = projected.copy()
    pivots, taus, rank = householder(work)
    # Q = H_0 ... H_{k-1}, accumulated backwards on its transpose (rows of qt are columns of Q):
    # before H_j, the columns left of j are still those of the identity, which H_j leaves alone.
    qt = np.eye(size)
    for j in range(rank - 1, -1, -1):
        for c in range(j, size):
            reflect(qt[c], work[j], j, taus[j])
    reduced = np.zeros((rank, rows))  # (M Q_k)^T = R_k P^T
    for c in range(rows):
        for i in range(min(c + 1, rank)):
            reduced[i, pivots[c]] = work[c, i]
    normal = reduced @ reduced.T
    for i in range(rank):
        normal[i, i] += damping * damping
    triangle, ok = cholesky(normal)
    return (np.ascontiguousarray(qt[:rank].T), reduced, triangle, np.ascontiguousarray(qt[rank:].T),
            ok and np.isfinite(work).all())


@njit(cache=True, nogil=True)
def damped_solve(projected, residual, damping):
    """w of the damped least squares and the null space left (see nullspace.damped_solve), and
    success.

    Columns of the matrix that are zero (directions the level's rows do not move: the legs for the
    hands' targets) take no step and stay free; only the others are factored. On the tracker's
    levels this halves the factorisation's size.
    """
    rows, size = projected.shape
    moved = np.zeros(size, dtype=np.bool_)
    for i in range(rows):
        for j in range(size):
            if projected[i, j] != 0.0:
                moved[j] = True
    if moved.all():
        return factored_solve(projected, residual, damping)
    columns = np.flatnonzero(moved)
    w_moved, remaining_moved, ok = factored_solve(np.ascontiguousarray(projected[:, columns]), residual, damping)
    w = np.zeros(size)
    w[columns] = w_moved
    # The null space: that of the moved columns, embedded, then every column left alone.
    kept = remaining_moved.shape[1]
    remaining = np.zeros((size, kept + size - columns.size))
    for i in range(columns.size):
        remaining[columns[i], :kept] = remaining_moved[i]
    free = kept
    for j in range(size):
        if not moved[j]:
            remaining[j, free] = 1.0
            free += 1
    return w, remaining, ok


@njit(cache=True, nogil=True)
def factored_solve(projected, residual, damping):
    """damped_solve by the factorisation of the whole matrix."""
    basis, reduced, triangle, remaining, ok = factor(projected, damping)
    if not ok or basis.shape[1] == 0:
        return np.zeros(projected.shape[1]), remaining, ok
    return basis @ cholesky_solve(triangle, reduced @ residual), remaining, ok


@njit(cache=True, nogil=True)
def coordinate_solve(projected, residual, damping):
    """The damped least squares of a matrix whose rows are each a multiple of a distinct unit
    vector (a posture task on some coordinates, over coordinates as yet untouched): w and the
    columns it leaves free; both empty (and False) for any other matrix.

    The matrix is its own QR factorisation: the rank test and the step of `factor`, without its
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
def damped_step(projected, residual, damping):
    """w of the damped least squares alone, M^T (M M^T + damping^2 I)^-1 residual, from the smaller
    normal equations; and success."""
    rows, size = projected.shape
    if rows <= size:
        normal, right = projected @ projected.T, residual.copy()
    else:
        normal, right = projected.T @ projected, projected.T @ residual
    for i in range(normal.shape[0]):
        normal[i, i] += damping * damping
    triangle, ok = cholesky(normal)
    if not ok:
        return np.zeros(size), False
    solution = cholesky_solve(triangle, right)
    return (projected.T @ solution if rows <= size else solution), True


@njit(cache=True, nogil=True)
def complement(unit):
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
def active_set_method(hessian, linear, constraint, lower, upper, feasibility):
    """The method on contiguous float64 arrays; returns (w, ended).

    Each iteration's KKT system [H C_A^T; C_A 0] [p; y] = [-(H w + g); 0] is solved through H's
    Cholesky factor, computed once, and the Schur complement S = C_A H^-1 C_A^T of the held rows:
    with u = H^-1 (H w + g) = w + H^-1 g, y = -S^-1 C_A u and p = -(u + H^-1 C_A^T y). H^-1 g is
    solved once, and H^-1 c once per row when it is held. A full KKT solve per iteration cost 8 us
    of LAPACK for 44 variables; at a frame's first targets-only steps on real boxing the method runs
    at every level, and took 91 of such a step's 141 us.
    """
    n, rows = hessian.shape[0], constraint.shape[0]
    w = np.zeros(n)
    triangle, ok = cholesky(hessian)
    if not ok:  # H is positive definite by construction; NaN or a broken level: not ended
        return w, False
    held = np.empty(rows, dtype=np.int64)
    held_upper = np.empty(rows, dtype=np.bool_)  # which side of each held bound
    held_solved = np.empty((rows, n))  # H^-1 c for each held row c, in the order held
    unconstrained = cholesky_solve(triangle, linear)  # H^-1 g: H^-1 (H w + g) = w + H^-1 g
    m = 0
    for _ in range(2 * (n + rows)):
        free_step = w + unconstrained
        multipliers = np.zeros(m)
        if m:
            schur = np.empty((m, m))
            right = np.empty(m)
            for a in range(m):
                row = constraint[held[a]]
                right[a] = -(row @ free_step)
                for b in range(m):
                    schur[a, b] = row @ held_solved[b]
            schur_triangle, ok = cholesky(schur)
            if not ok:  # held rows (nearly) dependent, beyond what the feasibility margin prevents
                return w, False
            multipliers = cholesky_solve(schur_triangle, right)
        if m == n:  # the held rows fix w
            step = np.zeros(n)
        else:
            step = -free_step
            for a in range(m):
                step -= multipliers[a] * held_solved[a]
        # The step is a difference of u and H^-1 C_A^T y: where it should vanish, what remains is
        # their rounding (a few 1e-12 on seeded levels of 12 variables, with |u| near 0.5).
        if np.sqrt(step @ step) <= 1e-12 * (1.0 + np.sqrt(w @ w)) + 1e-10 * np.sqrt(free_step @ free_step):
            # Multiplier sign: positive pushes against an upper bound, negative against a lower one.
            release, worst = -1, 1e-10
            for j in range(m):
                wrong_sign = -multipliers[j] if held_upper[j] else multipliers[j]
                if wrong_sign > worst:
                    release, worst = j, wrong_sign
            if release < 0:
                return w, True
            for j in range(release, m - 1):
                held[j] = held[j + 1]
                held_upper[j] = held_upper[j + 1]
                held_solved[j] = held_solved[j + 1]
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
        held_solved[m] = cholesky_solve(triangle, constraint[blocking])
        m += 1
    return w, False


# Rprop's factors (Riedmiller & Braun 1993 use 0.5 and 1.2).
SHRINK = 0.5
GROW = 1.2

# The columns of a task's state row.
STEP_SIZE, MIN_STEP_SIZE, MAX_STEP_SIZE, HAS_PREVIOUS = range(4)


@njit(cache=True, nogil=True)
def adapt_step_size(state, previous, taken):
    """The step norm along `taken` (nv,) for this iteration, adapted to the previous iteration's.

    `state` is a task's row [step size, min, max, has previous (0/1)] and `previous` (nv,) the
    direction of its previous step; both are updated in place.
    """
    if state[HAS_PREVIOUS] > 0.0:
        if taken @ previous < 0.0:
            state[STEP_SIZE] = max(SHRINK * state[STEP_SIZE], state[MIN_STEP_SIZE])
        else:
            state[STEP_SIZE] = min(GROW * state[STEP_SIZE], state[MAX_STEP_SIZE])
    previous[:] = taken
    state[HAS_PREVIOUS] = 1.0
    return state[STEP_SIZE]


# The kinds of level in `solve_levels`.
EMPTY, LEAST_SQUARES, GRADIENT = 0, 1, 2


@njit(cache=True, nogil=True)
def solve_levels(kinds, rows, targets, row_starts, adaptation, previous, steps, dq, null_basis, lower, upper,
                 bounded, active_set, hand_back, damping, feasibility, start):
    """The levels from `start` on, highest first, each in the null space of those above it.

    Args:
        kinds: (L,) EMPTY, LEAST_SQUARES or GRADIENT per level.
        rows, targets: (R, nv), (R,) every level's rows A and b stacked; a gradient level's one row
            is its unit direction (its target unused).
        row_starts: (L + 1,) where each level's rows start.
        adaptation, previous: (L, 4), (L, nv) a gradient level's step-adaptation state and previous
            direction (StepAdaptation.state), updated in place.
        steps: (L,) the step norm of each gradient level this step, 0 until it is taken; a level
            whose norm is already set (a second pass of the same step) keeps it.
        dq: (nv,) the higher levels' step; null_basis: (nv, r) Z, C-contiguous.
        lower, upper: (nv,) bounds on dq, used when `bounded` (then dq is clipped into them, the
            given dq first).
        active_set: solve a level that the bounds reach by the active-set method (else hand it back).
        hand_back: hand back every level with a null space left, bounded or not (with `bounded`;
            HierarchicalQPSolver.level_problems).
        damping: lambda of every level's damped least squares.
        feasibility: see primal_active_set.
        start: the first level to solve.

    Returns:
        dq; Z; the index of a level handed back (L when every level is done); for that level its
        QP's Hessian (r, r), linear term (r,) and the null space it leaves (r, r'); whether every
        factorisation held.
    """
    levels = kinds.shape[0]
    last = -1
    for index in range(levels):
        if kinds[index] != EMPTY:
            last = index
    nothing_2d, nothing_1d = np.zeros((0, 0)), np.zeros(0)
    if bounded:
        dq = np.minimum(np.maximum(dq, lower), upper)
    for index in range(start, levels):
        size = null_basis.shape[1]
        if kinds[index] == EMPTY or size == 0:
            continue
        # (typed on every path)
        unit, projected, residual, remaining = nothing_1d, nothing_2d, nothing_1d, nothing_2d
        coordinate, free_columns = False, np.zeros(0, dtype=np.int64)
        if kinds[index] == GRADIENT:
            reduced = null_basis.T @ rows[row_starts[index]]
            norm = np.sqrt(reduced @ reduced)
            if norm <= RANK_TOLERANCE:
                continue  # nothing left to climb
            unit = reduced / norm
            if steps[index] == 0.0:
                steps[index] = adapt_step_size(adaptation[index], previous[index], null_basis @ unit)
            w = steps[index] * unit
            remaining = complement(unit) if index != last else nothing_2d
        else:
            block = rows[row_starts[index]:row_starts[index + 1]]
            projected = block @ null_basis
            residual = targets[row_starts[index]:row_starts[index + 1]] - block @ dq
            w, free_columns, coordinate = coordinate_solve(projected, residual, damping)
            ok = True
            if not coordinate and index == last:
                w, ok = damped_step(projected, residual, damping)
            elif not coordinate:
                w, remaining, ok = damped_solve(projected, residual, damping)
            if not ok:
                return dq, null_basis, index, nothing_2d, nothing_1d, nothing_2d, False
        if bounded:
            if hand_back or not within_bounds(dq + null_basis @ w, lower, upper):
                if kinds[index] == GRADIENT:
                    hessian = np.eye(size) / steps[index]
                    linear = -unit
                else:
                    hessian = projected.T @ projected
                    for i in range(size):
                        hessian[i, i] += damping * damping
                    linear = -(projected.T @ residual)
                ended = False
                if active_set and not hand_back:
                    w, ended = active_set_method(hessian, linear, null_basis, lower - dq, upper - dq, feasibility)
                if not ended:
                    if coordinate and index != last:
                        remaining = np.ascontiguousarray(np.eye(size)[:, free_columns])
                    return dq, null_basis, index, hessian, linear, remaining, True
            dq = np.minimum(np.maximum(dq + null_basis @ w, lower), upper)
        else:
            dq = dq + null_basis @ w
        if index == last:
            continue
        if coordinate:  # the selection of the columns left free
            null_basis = np.ascontiguousarray(null_basis[:, free_columns])
        else:
            null_basis = null_basis @ remaining
    return dq, null_basis, levels, nothing_2d, nothing_1d, nothing_2d, True


@njit(cache=True, nogil=True)
def solve_levels_step(kinds, rows, targets, row_starts, adaptation, previous, steps, dq, null_basis, lower, upper,
                      bounded, active_set, hand_back, damping, feasibility, start):
    """solve_levels' dq, the level handed back and success, without the arrays of a level handed
    back: what a step reads when every level is done (as almost always). Returning those unused
    arrays to Python cost 1.6 us a call; a caller that gets a level back calls solve_levels again
    with the same arguments (a level's step norm, once set in `steps`, is kept, so the second call
    repeats the first)."""
    result = solve_levels(kinds, rows, targets, row_starts, adaptation, previous, steps, dq, null_basis, lower,
                          upper, bounded, active_set, hand_back, damping, feasibility, start)
    return result[0], result[2], result[6]

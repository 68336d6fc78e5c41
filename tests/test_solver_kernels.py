"""The solvers' compiled linear algebra (ibik_pin.solvers.kernels) against numpy's and scipy's."""

import numpy as np
import pytest
import scipy.linalg

from ibik_pin.solvers.kernels import RANK_TOLERANCE, cholesky, cholesky_solve, householder


@pytest.mark.parametrize("size", [1, 6, 26, 44])
def test_the_cholesky_factor_and_solve_are_lapacks(rng, size):
    rows = rng.normal(size=(size + 3, size))
    matrix = rows.T @ rows + 9e-4 * np.eye(size)
    right = rng.normal(size=size)
    triangle, ok = cholesky(matrix)
    assert ok
    np.testing.assert_allclose(triangle, scipy.linalg.cholesky(matrix, lower=True), rtol=0, atol=1e-12)
    expected = scipy.linalg.cho_solve(scipy.linalg.cho_factor(matrix, lower=True), right)
    np.testing.assert_allclose(cholesky_solve(triangle, right), expected, rtol=1e-10, atol=1e-12)


def test_a_matrix_that_is_not_positive_definite_or_not_finite_has_no_cholesky_factor(rng):
    indefinite = np.diag([1.0, -1.0, 2.0])
    assert not cholesky(indefinite)[1]
    broken = np.eye(3)
    broken[1, 1] = np.nan
    assert not cholesky(broken)[1]


@pytest.mark.parametrize(("shape", "rank"), [((9, 44), 9), ((18, 44), 18), ((38, 44), 38), ((12, 26), 7)])
def test_the_pivoted_householder_qr_pivots_and_factors_as_lapacks_geqp3(rng, shape, rank):
    """Same pivots and |R| as scipy.linalg.qr(pivoting=True) up to the rank, where it stops."""
    rows, size = shape
    matrix = rng.normal(size=(rows, rank)) @ rng.normal(size=(rank, size))  # rank-deficient when rank < rows
    work = matrix.copy()
    pivots, _, found = householder(work)
    assert found == rank
    reference, reference_pivots = scipy.linalg.qr(matrix.T, mode="r", pivoting=True)
    np.testing.assert_array_equal(pivots[:rank], reference_pivots[:rank])
    # Row c of work holds R[:j+1, c]: |R| of the pivoted columns as geqp3's (signs may differ; past
    # the rank the two order the columns left differently).
    computed = np.array([[work[c, i] if i <= c else 0.0 for c in range(rows)] for i in range(rank)])
    np.testing.assert_allclose(np.abs(computed[:, :rank]), np.abs(reference[:rank, :rank]), rtol=0, atol=1e-9)
    assert np.all(np.abs(np.diag(reference))[rank:] <= 1e-9 * np.abs(reference[0, 0]) + RANK_TOLERANCE)

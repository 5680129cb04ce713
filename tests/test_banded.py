"""Tests for cnt_env.rod.banded (banded storage, pivoted banded LU)."""

import numpy as np
import pytest
from scipy.linalg import lapack

from cnt_env.rod.banded import (
    KL,
    KU,
    KV,
    LDAB,
    band_add,
    band_add_block,
    band_add_block_contig,
    band_alloc,
    band_fix_dof,
    band_lu_factor,
    band_lu_solve,
    band_matvec,
    band_to_dense,
    band_zero,
    dense_to_band,
)

SIZES = [1, 5, 31, 200]


def random_band(n, rng, pivoting, dominant=False):
    """Random nonsymmetric KL/KU band matrix.

    pivoting=True zeroes about a third of the diagonal (and makes the diagonal
    small elsewhere) so partial pivoting is required.
    """
    i, j = np.indices((n, n))
    inband = (i - j <= KL) & (j - i <= KU)
    A = np.where(inband, rng.standard_normal((n, n)), 0.0)
    if dominant:
        A[np.diag_indices(n)] += np.sign(np.diag(A)) * 25.0
    elif pivoting:
        d = 0.01 * rng.standard_normal(n)
        d[rng.random(n) < 0.35] = 0.0
        A[np.diag_indices(n)] = d
    else:
        A[np.diag_indices(n)] += 4.0 * np.sign(np.diag(A) + 1e-300)
    return A


def well_conditioned(n, rng, pivoting, dominant=False, max_cond=1e6):
    for _ in range(50):
        A = random_band(n, rng, pivoting, dominant)
        if n == 1 and A[0, 0] == 0.0:
            continue
        c = np.linalg.cond(A)
        if c < max_cond:
            return A, c
    raise RuntimeError("could not draw a well-conditioned matrix")


def factor_solve(A, b):
    n = A.shape[0]
    ab = dense_to_band(A)
    ipiv = np.zeros(n, dtype=np.int32)
    info = band_lu_factor(ab, n, ipiv)
    x = b.copy()
    if info == 0:
        band_lu_solve(ab, n, ipiv, x)
    return info, ab, ipiv, x


def test_constants():
    assert (KL, KU, KV, LDAB) == (10, 10, 20, 31)


@pytest.mark.parametrize("n", SIZES)
@pytest.mark.parametrize("pivoting", [False, True])
def test_solve_vs_numpy(n, pivoting):
    rng = np.random.default_rng(1000 * n + pivoting)
    A, cond = well_conditioned(n, rng, pivoting)
    xref = rng.standard_normal(n)
    b = A @ xref
    info, _, ipiv, x = factor_solve(A, b)
    assert info == 0
    if pivoting and n > 1:
        assert np.any(ipiv != np.arange(n))  # pivoting actually happened
    xnp = np.linalg.solve(A, b)
    tol = 1e-13 * cond
    assert np.linalg.norm(x - xnp) <= tol * np.linalg.norm(xnp)
    assert np.linalg.norm(x - xref) <= tol * np.linalg.norm(xref)
    # backward error via band_matvec
    r = np.empty(n)
    band_matvec(dense_to_band(A), n, x, r)
    assert np.linalg.norm(r - b) <= 1e-13 * np.linalg.norm(A, 1) * np.linalg.norm(x) * n


@pytest.mark.parametrize("n", SIZES)
@pytest.mark.parametrize("pivoting", [False, True])
def test_factors_match_lapack_dgbsv(n, pivoting):
    rng = np.random.default_rng(7 + 10 * n + pivoting)
    A, _ = well_conditioned(n, rng, pivoting)
    b = rng.standard_normal(n)
    info, ab, ipiv, x = factor_solve(A, b)
    assert info == 0
    lub, piv, xl, infol = lapack.dgbsv(KL, KU, dense_to_band(A), b[:, None])
    assert infol == 0
    # same pivot choice (ties are measure-zero for random data) -> same factors
    np.testing.assert_array_equal(ipiv, piv)
    # LAPACK leaves garbage-free zeros in unused fill-in slots, compare all
    np.testing.assert_allclose(ab, lub, rtol=1e-12, atol=1e-12 * np.abs(lub).max())
    np.testing.assert_allclose(x, xl[:, 0], rtol=1e-10, atol=1e-12 * np.abs(xl).max())


def test_factor_ignores_stale_workspace():
    """Garbage in the fill-in rows (e.g. from a previous factorisation) must not matter."""
    n = 60
    rng = np.random.default_rng(3)
    A, _ = well_conditioned(n, rng, pivoting=True)
    b = rng.standard_normal(n)
    ab = dense_to_band(A)
    ab[:KL, :] = rng.standard_normal((KL, n))
    ipiv = np.zeros(n, dtype=np.int32)
    assert band_lu_factor(ab, n, ipiv) == 0
    x = b.copy()
    band_lu_solve(ab, n, ipiv, x)
    np.testing.assert_allclose(x, np.linalg.solve(A, b), rtol=1e-9, atol=1e-12)


def test_used_columns_subset_and_c_order():
    """n smaller than the buffer; C-ordered ab works too."""
    n, cap = 40, 57
    rng = np.random.default_rng(5)
    A, _ = well_conditioned(n, rng, pivoting=True)
    b = rng.standard_normal(n)
    for order in "CF":
        ab = np.full((LDAB, cap), 123.0, order=order)
        band_zero(ab, n)
        assert np.all(ab[:, :n] == 0.0) and np.all(ab[:, n:] == 123.0)
        ab[:, :n] = dense_to_band(A)
        ipiv = np.zeros(cap, dtype=np.int64)
        assert band_lu_factor(ab, n, ipiv) == 0
        x = np.concatenate([b, np.full(cap - n, 7.0)])
        band_lu_solve(ab, n, ipiv, x)
        np.testing.assert_allclose(x[:n], np.linalg.solve(A, b), rtol=1e-9, atol=1e-12)
        assert np.all(x[n:] == 7.0) and np.all(ab[:, n:] == 123.0)


@pytest.mark.parametrize("pivoting", [False, True])
def test_fix_dof_exact_zero(pivoting):
    n = 120
    rng = np.random.default_rng(11 + pivoting)
    A, _ = well_conditioned(n, rng, pivoting)
    fixed = [0, 1, 2, 37, 38, 59, n - 2, n - 1]
    ab = dense_to_band(A)
    for i in fixed:
        band_fix_dof(ab, n, i)
    Af = band_to_dense(ab, n)
    for i in fixed:
        e = np.zeros(n)
        e[i] = 1.0
        np.testing.assert_array_equal(Af[i], e)
        np.testing.assert_array_equal(Af[:, i], e)
    b = rng.standard_normal(n)
    b[fixed] = 0.0
    ipiv = np.zeros(n, dtype=np.int32)
    assert band_lu_factor(ab, n, ipiv) == 0
    x = b.copy()
    band_lu_solve(ab, n, ipiv, x)
    assert np.all(x[fixed] == 0.0)
    # same as eliminating the fixed DOFs from the dense system
    free = np.setdiff1d(np.arange(n), fixed)
    xr = np.linalg.solve(A[np.ix_(free, free)], b[free])
    np.testing.assert_allclose(x[free], xr, rtol=1e-9, atol=1e-11)


@pytest.mark.parametrize("n", [1, 5, 50])
def test_singular_reports_info(n):
    rng = np.random.default_rng(n)
    A, _ = well_conditioned(n, rng, pivoting=False)
    k = n // 2
    A[:, k] = 0.0  # exactly singular column
    ab = dense_to_band(A)
    ipiv = np.zeros(n, dtype=np.int32)
    info = band_lu_factor(ab, n, ipiv)
    assert 1 <= info <= n
    assert np.all(np.isfinite(ab))
    _, _, _, infol = lapack.dgbsv(KL, KU, dense_to_band(A), np.ones((n, 1)))
    assert info == infol  # LAPACK reports the first exactly-zero pivot too


def test_singular_zero_matrix_and_rank_deficient():
    n = 30
    ab = band_alloc(n)
    ipiv = np.zeros(n, dtype=np.int32)
    assert band_lu_factor(ab, n, ipiv) == 1
    # a zero row stays exactly zero under elimination (multipliers 0) and is
    # pushed down by the interchanges until it yields an exactly zero pivot
    rng = np.random.default_rng(2)
    A, _ = well_conditioned(n, rng, pivoting=True)
    A[11] = 0.0
    ab = dense_to_band(A)
    info = band_lu_factor(ab, n, ipiv)
    assert info > 0
    assert np.all(np.isfinite(ab))
    _, _, _, infol = lapack.dgbsv(KL, KU, dense_to_band(A), np.ones((n, 1)))
    assert infol > 0


@pytest.mark.parametrize("bad", [np.nan, np.inf, -np.inf])
def test_non_finite_reports_info(bad):
    n = 40
    rng = np.random.default_rng(9)
    A, _ = well_conditioned(n, rng, pivoting=True)
    for i, j in [(0, 0), (25, 20), (20, 25), (n - 1, n - 1), (n - 1, n - 11)]:
        ab = dense_to_band(A)
        band_add(ab, i, j, bad)
        ipiv = np.zeros(n, dtype=np.int32)
        info = band_lu_factor(ab, n, ipiv)
        assert info > 0, (i, j)


def test_subnormal_pivot_reports_info():
    ab = dense_to_band(np.array([[1e-310]]))
    assert band_lu_factor(ab, 1, np.zeros(1, dtype=np.int32)) == 1


def test_band_add_matvec_round_trip():
    n = 77
    rng = np.random.default_rng(4)
    ab = band_alloc(n)
    A = np.zeros((n, n))
    for _ in range(3000):
        i = int(rng.integers(n))
        j = int(np.clip(i + rng.integers(-10, 11), 0, n - 1))
        v = rng.standard_normal()
        band_add(ab, i, j, v)
        A[i, j] += v
    np.testing.assert_array_equal(band_to_dense(ab, n), A)
    np.testing.assert_array_equal(dense_to_band(A), ab)
    x = rng.standard_normal(n)
    y = np.full(n, np.nan)
    band_matvec(ab, n, x, y)
    np.testing.assert_allclose(y, A @ x, rtol=1e-13, atol=1e-13)
    band_zero(ab, n)
    assert not ab.any()


@pytest.mark.parametrize("k", [3, 6, 11])
def test_band_add_block(k):
    n = 4 * 12 - 1
    rng = np.random.default_rng(k)
    ab1 = band_alloc(n)
    ab2 = band_alloc(n)
    A = np.zeros((n, n))
    for first in range(0, n - k + 1, 4):
        blk = rng.standard_normal((k, k))
        dofs = np.arange(first, first + k)
        band_add_block(ab1, dofs, blk)
        band_add_block_contig(ab2, first, blk)
        A[np.ix_(dofs, dofs)] += blk
    np.testing.assert_array_equal(band_to_dense(ab1, n), A)
    np.testing.assert_array_equal(ab1, ab2)
    # non-contiguous dofs
    dofs = np.array([3, 5, 9, 12])
    blk = rng.standard_normal((4, 4))
    band_add_block(ab1, dofs, blk)
    A[np.ix_(dofs, dofs)] += blk
    np.testing.assert_allclose(band_to_dense(ab1, n), A, rtol=0, atol=0)


def test_dense_to_band_rejects_out_of_band():
    A = np.zeros((15, 15))
    A[12, 0] = 1.0
    with pytest.raises(ValueError):
        dense_to_band(A)


def _dgbtf2_reference(ab: np.ndarray, n: int) -> np.ndarray:
    """band_lu_factor's algorithm in plain Python with every rank-1 update done in full
    (no skipped zeros): the reference for the sparse-column shortcuts."""
    ipiv = np.zeros(n, dtype=np.int64)
    ju = 0
    for j in range(n):
        km = min(KL, n - 1 - j)
        col = np.abs(ab[KV : KV + km + 1, j])
        jp = int(np.argmax(col))
        ipiv[j] = j + jp
        ju = max(ju, min(j + KU + jp, n - 1))
        if jp != 0:
            for c in range(j, ju + 1):
                ra = KV + j - c
                ab[ra, c], ab[ra + jp, c] = ab[ra + jp, c], ab[ra, c]
        pinv = 1.0 / ab[KV, j]
        for r in range(km):
            ab[KV + 1 + r, j] *= pinv
        for c in range(j + 1, ju + 1):
            ru = KV + j - c
            u = ab[ru, c]
            for r in range(km):
                ab[ru + 1 + r, c] -= ab[KV + 1 + r, j] * u
    return ipiv


@pytest.mark.parametrize("pivoting", [False, True])
def test_sparse_columns_factor_to_the_same_bits(pivoting: bool) -> None:
    """Columns whose multipliers end in zeros (a block coupled only to its two
    neighbours, like the z-only DOFs of a deposited tail in the free-DOF system) take
    the short update: the factors and pivots equal the full update's bit for bit."""
    rng = np.random.default_rng(11 + pivoting)
    n = 120
    A = random_band(n, rng, pivoting)
    i, j = np.indices((n, n))
    A[40:90, 40:90] = np.where(np.abs(i - j)[40:90, 40:90] <= 2, A[40:90, 40:90], 0.0)
    A[40:90, :40] = 0.0  # the sparse block couples to the dense part only at its edges
    A[:40, 40:90] = 0.0
    A[38:40, 40:42] = rng.standard_normal((2, 2))
    A[40:42, 38:40] = rng.standard_normal((2, 2))
    ab = dense_to_band(A)
    ref = ab.copy()
    ipiv = np.zeros(n, dtype=np.int64)
    assert band_lu_factor(ab, n, ipiv) == 0
    ipiv_ref = _dgbtf2_reference(ref, n)
    np.testing.assert_array_equal(ipiv, ipiv_ref)
    np.testing.assert_array_equal(ab, ref)

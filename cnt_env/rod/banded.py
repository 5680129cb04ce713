"""Banded Jacobian storage and pivoted banded LU (numba kernels).

Storage is LAPACK general-band storage with ``KL = KU = 10`` (see
``cnt_env/rod/__init__.py``): ``ab`` has shape ``(LDAB, n_dof)`` with
``LDAB = 2*KL + KU + 1 = 31`` and the matrix entry A[i, j] (``|i - j| <= 10``)
is stored at ``ab[KL + KU + i - j, j]``.  Rows ``0 .. KL-1`` of ``ab`` are
workspace for the fill-in created by row interchanges in the LU factorisation;
after :func:`band_lu_factor` the upper factor U (bandwidth ``KL + KU``) occupies
rows ``0 .. KL+KU`` and the multipliers of L occupy rows ``KL+KU+1 .. LDAB-1``.

Every kernel accepts C- or Fortran-ordered ``ab``, but Fortran order
(``band_alloc``) keeps each band column contiguous, which is what the
factorisation, the solve and LAPACK want; use it for anything hot.

``ipiv`` is an integer array of length >= n holding 0-based row indices: at
step j row j was interchanged with row ``ipiv[j]`` (LAPACK's IPIV minus one,
the same convention as ``scipy.linalg.lapack.dgbsv``).  Only the pair
``band_lu_factor`` / ``band_lu_solve`` needs to agree on it.

All kernels are ``@njit(cache=True)``, serial, no fastmath, and allocate
nothing; the caller owns every array.  ``n`` (number of used columns) may be
smaller than ``ab.shape[1]`` so one buffer can serve several rod sizes.
"""

from __future__ import annotations

import numpy as np
from numba import njit

KL = 10
"""Number of sub-diagonals stored."""
KU = 10
"""Number of super-diagonals stored (of the matrix before factorisation)."""
KV = KL + KU
"""Row of ``ab`` holding the main diagonal (= 20)."""
LDAB = 2 * KL + KU + 1
"""Leading dimension (number of rows) of ``ab`` (= 31)."""


def band_alloc(n: int) -> np.ndarray:
    """Return a zeroed Fortran-ordered ``(LDAB, n)`` band array (not a kernel)."""
    return np.zeros((LDAB, n), dtype=np.float64, order="F")


# --------------------------------------------------------------------------
# assembly
# --------------------------------------------------------------------------


@njit(cache=True)
def band_zero(ab, n):
    """Zero columns ``0 .. n-1`` of ``ab`` (all LDAB rows, workspace included)."""
    for j in range(n):
        for r in range(LDAB):
            ab[r, j] = 0.0


@njit(cache=True, inline="always")
def band_add(ab, i, j, value):
    """``A[i, j] += value``.

    Requires ``|i - j| <= 10`` and ``0 <= i, j < n``; this is NOT checked:
    numba does no bounds checking, so an out-of-band pair silently writes into
    the LU workspace rows, another column, or outside the array.  Inlined
    into the caller (``inline="always"``).
    """
    ab[KV + i - j, j] += value


@njit(cache=True)
def band_add_block(ab, dofs, block):
    """``A[dofs[a], dofs[b]] += block[a, b]`` for a k x k dense ``block``.

    ``dofs`` is an integer array of length k; all pairwise index differences
    must be ``<= 10`` in magnitude (not checked).  Column-major traversal so a
    Fortran-ordered ``ab`` is written contiguously.
    """
    k = dofs.shape[0]
    for b in range(k):
        j = dofs[b]
        for a in range(k):
            ab[KV + dofs[a] - j, j] += block[a, b]


@njit(cache=True)
def band_add_block_contig(ab, first_dof, block):
    """``A[first_dof + a, first_dof + b] += block[a, b]`` for a k x k ``block``.

    Contiguous-DOF special case of :func:`band_add_block` (the DER stencils:
    k = 6 or 11); requires ``k <= 11`` and ``first_dof + k <= n`` (not checked).
    """
    k = block.shape[0]
    # constant trip counts for the two DER stencil sizes let LLVM unroll
    # (measured ~1.5x faster than the generic loop)
    if k == 11:
        for b in range(11):
            col = ab[KV - b :, first_dof + b]  # col[a] is A[first_dof + a, first_dof + b]
            for a in range(11):
                col[a] += block[a, b]
    elif k == 6:
        for b in range(6):
            col = ab[KV - b :, first_dof + b]
            for a in range(6):
                col[a] += block[a, b]
    else:
        for b in range(k):
            col = ab[KV - b :, first_dof + b]
            for a in range(k):
                col[a] += block[a, b]


@njit(cache=True)
def band_fix_dof(ab, n, i):
    """Make DOF ``i`` a homogeneous constraint: row i := e_i^T, column i := e_i.

    The caller sets ``rhs[i] = 0``.  Zeroing the column as well as the row
    does not change the solution of the system (x_i = 0 anyway) but decouples
    DOF i completely, so the solve returns exactly ``x[i] == 0`` even when the
    LU pivots, and a symmetric Jacobian stays symmetric.  Only in-band
    entries are touched; the band layout is unchanged.
    """
    jlo = max(0, i - KL)
    jhi = min(n - 1, i + KU)
    for j in range(jlo, jhi + 1):
        ab[KV + i - j, j] = 0.0  # A[i, j]
    ilo = max(0, i - KU)
    ihi = min(n - 1, i + KL)
    for r in range(ilo, ihi + 1):
        ab[KV + r - i, i] = 0.0  # A[r, i]
    ab[KV, i] = 1.0


@njit(cache=True)
def band_matvec(ab, n, x, out):
    """``out[:n] = A @ x[:n]`` from (unfactored) band storage."""
    for i in range(n):
        out[i] = 0.0
    for j in range(n):
        xj = x[j]
        ilo = max(0, j - KU)
        ihi = min(n - 1, j + KL)
        for i in range(ilo, ihi + 1):
            out[i] += ab[KV + i - j, j] * xj


# --------------------------------------------------------------------------
# LU factorisation and solve
# --------------------------------------------------------------------------


@njit(cache=True)
def band_lu_factor(ab, n, ipiv):
    """In-place LU with partial pivoting, P A = L U (algorithm of LAPACK dgbtf2).

    Unblocked right-looking elimination: for each column j find the pivot
    among rows j .. j+KL, swap it into row j over columns j .. ju (ju = the
    rightmost column reached by any swapped row so far, which is where the
    up-to-KL extra super-diagonals of fill-in come from), scale the
    multipliers and apply the rank-1 update to the trailing band. The update
    stops at the last non-zero multiplier and skips exact-zero entries of U's
    row: it subtracts no exact zeros, which leaves every non-zero entry's bits
    as the full update would.

    Returns ``info``: 0 on success, else the 1-based column j+1 at which the
    factorisation stopped because the pivot was exactly zero or the pivot
    column / the new row of U contained a non-finite value.  Unlike LAPACK
    (which continues past a zero pivot) it stops there; ``ab`` is then partly
    factored and must not be passed to :func:`band_lu_solve`.  With info == 0
    every stored factor entry is finite (|multipliers| <= 1 by pivoting).
    """
    # Fill-in rows (0 .. KL-1) of columns KU+1 .. KV-1 are never covered by
    # the per-step zeroing below; clear them once (dgbtf2 does the same).
    for j in range(KU + 1, min(KV, n)):
        for r in range(KV - j, KL):
            ab[r, j] = 0.0
    ju = 0  # last column touched by the row interchanges so far (0-based)
    for j in range(n):
        # column j + KV enters the window: clear its fill-in rows
        if j + KV < n:
            for r in range(KL):
                ab[r, j + KV] = 0.0
        km = min(KL, n - 1 - j)  # number of sub-diagonal entries in column j
        # pivot search (idamax) over A[j .. j+km, j] = ab[KV .. KV+km, j];
        # the running sum of |a| is finite iff every entry is finite.
        jp = 0
        amax = abs(ab[KV, j])
        asum = amax
        for r in range(1, km + 1):
            v = abs(ab[KV + r, j])
            asum += v
            if v > amax:
                amax = v
                jp = r
        if amax == 0.0 or not (asum - asum == 0.0):
            return j + 1
        ipiv[j] = j + jp
        ju = max(ju, min(j + KU + jp, n - 1))
        if jp != 0:
            # swap rows j and j+jp over columns j .. ju
            for c in range(j, ju + 1):
                ra = KV + j - c
                rb = ra + jp
                t = ab[ra, c]
                ab[ra, c] = ab[rb, c]
                ab[rb, c] = t
        pinv = 1.0 / ab[KV, j]
        if not (pinv - pinv == 0.0):  # |pivot| subnormal: 1/pivot overflows
            return j + 1
        # scale multipliers, then rank-1 update of A[j+1 .. j+km, j+1 .. ju]
        usum = 0.0
        lj = ab[KV + 1 :, j]  # multipliers L[j+1 .., j]
        m = km  # 1 + the last non-zero multiplier (NaN counts as non-zero)
        while m > 0 and lj[m - 1] == 0.0:
            m -= 1
        if m == 0:
            # a column with nothing below the pivot (a fixed DOF, band_fix_dof): the
            # multipliers are zero and the update would subtract exact zeros; skip it
            for c in range(j + 1, ju + 1):
                usum += abs(ab[KV + j - c, c])
        elif m == KL:
            # interior columns: constant trip count, fully unrolled by LLVM
            for r in range(KL):
                lj[r] *= pinv
            for c in range(j + 1, ju + 1):
                ru = KV + j - c  # row of A[j, c] in ab
                u = ab[ru, c]
                usum += abs(u)
                colc = ab[ru + 1 :, c]
                for r in range(KL):
                    colc[r] -= lj[r] * u
        else:
            # the last columns (km < KL), or a sparse one (zeros below row j + m, e.g. the
            # z-only DOFs of a deposited tail in the free-DOF system, coupled to two
            # neighbours): update rows j+1 .. j+m only, and skip the columns whose U entry
            # is an exact zero; the skipped operations subtract exact zeros, so every
            # non-zero entry keeps its bits
            for r in range(m):
                lj[r] *= pinv
            for c in range(j + 1, ju + 1):
                ru = KV + j - c
                u = ab[ru, c]
                usum += abs(u)
                if u == 0.0:
                    continue
                colc = ab[ru + 1 :, c]
                for r in range(m):
                    colc[r] -= lj[r] * u
        if not (usum - usum == 0.0):
            return j + 1
    return 0


@njit(cache=True)
def band_lu_solve(ab, n, ipiv, b):
    """Solve ``A x = b`` in place (``b <- x``) with the factors of
    :func:`band_lu_factor` (algorithm of LAPACK dgbtrs, TRANS = 'N', one rhs).

    Forward pass applies the interchanges and L (unit lower, KL multipliers
    per column); backward pass solves with U (upper, bandwidth KL + KU).
    Only call it after ``band_lu_factor`` returned 0 (a zero pivot left by a
    failed factorisation raises ZeroDivisionError, numba's default error
    model).  Unlike dgbtrs it does not skip zero entries of b; the result is
    identical (and an exactly-zero x[i] stays exactly zero, see band_fix_dof).
    """
    # L y = P b  (interchanges applied as we go, like dgbtrs)
    for j in range(n - 1):
        p = ipiv[j]
        bj = b[p]
        if p != j:
            b[p] = b[j]
            b[j] = bj
        if bj == 0.0:  # nothing to eliminate (fixed DOFs have a zero right-hand side)
            continue
        if j + KL < n:  # constant trip count: unrolled, ~2x faster
            for r in range(KL):
                b[j + 1 + r] -= ab[KV + 1 + r, j] * bj
        else:
            for r in range(n - 1 - j):
                b[j + 1 + r] -= ab[KV + 1 + r, j] * bj
    # U x = y  (column-oriented back substitution, U has KV super-diagonals)
    for j in range(n - 1, -1, -1):
        xj = b[j] / ab[KV, j]
        b[j] = xj
        if xj == 0.0:
            continue
        if j >= KV:
            for r in range(KV):
                b[j - KV + r] -= ab[r, j] * xj
        else:
            for i in range(j):
                b[i] -= ab[KV + i - j, j] * xj


# --------------------------------------------------------------------------
# test helpers (plain numpy)
# --------------------------------------------------------------------------


def dense_to_band(A: np.ndarray) -> np.ndarray:
    """Dense (n, n) matrix -> Fortran-ordered band array ``(LDAB, n)``.

    Raises ValueError if A has a non-zero outside the KL/KU band.
    """
    A = np.asarray(A, dtype=np.float64)
    n = A.shape[0]
    if A.shape != (n, n):
        raise ValueError("A must be square")
    i, j = np.indices((n, n))
    if np.any(A[(i - j > KL) | (j - i > KU)] != 0.0):
        raise ValueError("A has entries outside the band")
    ab = band_alloc(n)
    inband = (i - j <= KL) & (j - i <= KU)
    ab[KV + i[inband] - j[inband], j[inband]] = A[inband]
    return ab


def band_to_dense(ab: np.ndarray, n: int) -> np.ndarray:
    """Band array -> dense (n, n) matrix (only the original KL/KU band)."""
    A = np.zeros((n, n))
    for j in range(n):
        for i in range(max(0, j - KU), min(n, j + KL + 1)):
            A[i, j] = ab[KV + i - j, j]
    return A

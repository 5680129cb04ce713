"""Benchmark: numba banded LU (cnt_env.rod.banded) vs LAPACK dgbsv.

For n_dof = 4N - 1 (N = 250, 500, 1000, 2000) and a random nonsymmetric
band matrix with kl = ku = 10 (diagonal shifted so it is "dominant-ish": partial
pivoting still swaps rows in a fraction of the columns) time, as the median
(and min) of many interleaved repeats after warm-up:

* ``numba``        band_lu_factor + band_lu_solve called from Python
* ``numba_lapack`` prototype: LAPACK dgbtrf + dgbtrs from scipy.linalg.cython_lapack
                   called *inside* an njit function (no Python in between)
* ``scipy_dgbsv``  scipy.linalg.lapack.dgbsv, overwrite_ab/overwrite_b (no copies)
* ``scipy_solve_banded`` scipy.linalg.solve_banded (copies into LAPACK layout
                   internally; that copy is part of its cost)
* ``copy``         np.copyto of the (31, n) band array, which every in-place
                   method needs per Newton step unless the Jacobian is
                   re-assembled anyway (it is excluded from the timings above)

Prints one JSON object to stdout.  Run:
    PYTHONPATH=. python benchmarks/banded_lu.py [--repeats 400]
"""

from __future__ import annotations

import argparse
import json
import platform
import time

import llvmlite.binding as llvm
import numba
import numpy as np
import scipy
from llvmlite import ir
from numba import njit, types
from numba.core import cgutils
from numba.extending import get_cython_function_address, intrinsic
from scipy.linalg import lapack, solve_banded

from cnt_env.rod.banded import (
    KL,
    KU,
    KV,
    LDAB,
    band_add_block,
    band_add_block_contig,
    band_alloc,
    band_lu_factor,
    band_lu_solve,
    band_matvec,
    band_zero,
)

# --------------------------------------------------------------------------
# Prototype: LAPACK from numba.  scipy.linalg.cython_lapack exports C function
# pointers; registering them as named symbols with LLVM (instead of calling
# through a ctypes pointer) keeps the calling njit functions cacheable, since
# the cached object code only refers to the symbol name, which is re-bound at
# import time in each process.  Scalar arguments go through stack slots.
# --------------------------------------------------------------------------

for _name in ("dgbtrf", "dgbtrs"):
    llvm.add_symbol(
        f"cnt_env_{_name}", get_cython_function_address("scipy.linalg.cython_lapack", _name)
    )

_i32 = ir.IntType(32)
_i32p = _i32.as_pointer()
_f64p = ir.DoubleType().as_pointer()


def _check_args(ab, ipiv):
    return (
        isinstance(ab, types.Array)
        and ab.ndim == 2
        and ab.dtype == types.float64
        and isinstance(ipiv, types.Array)
        and ipiv.ndim == 1
        and ipiv.dtype == types.int32
    )


@intrinsic
def _lapack_dgbtrf(typingctx, ab, n, ipiv):
    """info = dgbtrf(m=n, n, KL, KU, ab, LDAB, ipiv); ab must be F-contiguous (LDAB, >=n)."""
    if not (_check_args(ab, ipiv) and isinstance(n, types.Integer)):
        return None
    sig = types.int32(ab, n, ipiv)

    def codegen(context, builder, sig, args):
        a = context.make_array(sig.args[0])(context, builder, args[0])
        p = context.make_array(sig.args[2])(context, builder, args[2])
        n32 = context.cast(builder, args[1], sig.args[1], types.int32)
        pn = cgutils.alloca_once_value(builder, n32)
        pkl = cgutils.alloca_once_value(builder, ir.Constant(_i32, KL))
        pku = cgutils.alloca_once_value(builder, ir.Constant(_i32, KU))
        pld = cgutils.alloca_once_value(builder, ir.Constant(_i32, LDAB))
        pinfo = cgutils.alloca_once_value(builder, ir.Constant(_i32, 0))
        fnty = ir.FunctionType(ir.VoidType(), [_i32p] * 4 + [_f64p, _i32p, _i32p, _i32p])
        fn = cgutils.get_or_insert_function(builder.module, fnty, "cnt_env_dgbtrf")
        builder.call(fn, [pn, pn, pkl, pku, a.data, pld, p.data, pinfo])
        return builder.load(pinfo)

    return sig, codegen


@intrinsic
def _lapack_dgbtrs(typingctx, ab, n, ipiv, b):
    """info = dgbtrs('N', n, KL, KU, 1, ab, LDAB, ipiv, b, n); b contiguous."""
    if not (_check_args(ab, ipiv) and isinstance(n, types.Integer)):
        return None
    if not (isinstance(b, types.Array) and b.dtype == types.float64):
        return None
    sig = types.int32(ab, n, ipiv, b)

    def codegen(context, builder, sig, args):
        a = context.make_array(sig.args[0])(context, builder, args[0])
        p = context.make_array(sig.args[2])(context, builder, args[2])
        bb = context.make_array(sig.args[3])(context, builder, args[3])
        n32 = context.cast(builder, args[1], sig.args[1], types.int32)
        ptrans = cgutils.alloca_once_value(builder, ir.Constant(ir.IntType(8), ord("N")))
        pn = cgutils.alloca_once_value(builder, n32)
        pkl = cgutils.alloca_once_value(builder, ir.Constant(_i32, KL))
        pku = cgutils.alloca_once_value(builder, ir.Constant(_i32, KU))
        pnrhs = cgutils.alloca_once_value(builder, ir.Constant(_i32, 1))
        pld = cgutils.alloca_once_value(builder, ir.Constant(_i32, LDAB))
        pinfo = cgutils.alloca_once_value(builder, ir.Constant(_i32, 0))
        fnty = ir.FunctionType(
            ir.VoidType(),
            [ir.IntType(8).as_pointer()] + [_i32p] * 4 + [_f64p, _i32p, _i32p, _f64p, _i32p, _i32p],
        )
        fn = cgutils.get_or_insert_function(builder.module, fnty, "cnt_env_dgbtrs")
        builder.call(fn, [ptrans, pn, pkl, pku, pnrhs, a.data, pld, p.data, bb.data, pn, pinfo])
        return builder.load(pinfo)

    return sig, codegen


@njit(cache=True)
def lapack_factor_solve(ab, n, ipiv, b):
    """LAPACK dgbtrf + dgbtrs from numba (prototype).  ipiv is 1-based (LAPACK)."""
    if ab.shape[0] != LDAB or ab.strides[0] != 8 or ab.strides[1] != 8 * LDAB:
        raise ValueError("ab must be Fortran-contiguous with LDAB rows")
    if b.strides[0] != 8 or ipiv.strides[0] != 4:
        raise ValueError("b and ipiv must be contiguous")
    info = _lapack_dgbtrf(ab, n, ipiv)
    if info == 0:
        info = _lapack_dgbtrs(ab, n, ipiv, b)
    return info


@njit(cache=True)
def numba_factor_solve(ab, n, ipiv, b):
    info = band_lu_factor(ab, n, ipiv)
    if info == 0:
        band_lu_solve(ab, n, ipiv, b)
    return info


# --------------------------------------------------------------------------
# assembly micro-benchmark: dofs array vs first_dof
# --------------------------------------------------------------------------


@njit(cache=True)
def _assemble_dofs(ab, n, blocks, dofs):
    band_zero(ab, n)
    k = blocks.shape[1]
    for e in range(blocks.shape[0]):
        for a in range(k):
            dofs[a] = 4 * e + a
        band_add_block(ab, dofs, blocks[e])


@njit(cache=True)
def _assemble_contig(ab, n, blocks):
    band_zero(ab, n)
    for e in range(blocks.shape[0]):
        band_add_block_contig(ab, 4 * e, blocks[e])


# --------------------------------------------------------------------------


def random_band(n: int, rng: np.random.Generator, shift: float) -> np.ndarray:
    """(LDAB, n) Fortran band array, N(0,1) entries in the band, diag += shift*sign."""
    ab = band_alloc(n)
    ab[KL:, :] = rng.standard_normal((KL + KU + 1, n))
    d = ab[KV]
    d += np.where(d >= 0, shift, -shift)
    for j in range(n):  # zero the out-of-matrix corners of the band
        for r in range(KL, LDAB):
            i = r - KV + j
            if i < 0 or i >= n:
                ab[r, j] = 0.0
    return ab


def timed(fn, setup, repeats):
    ts = np.empty(repeats)
    for k in range(repeats):
        setup()
        t0 = time.perf_counter()
        fn()
        ts[k] = time.perf_counter() - t0
    return ts


def bench_one(N: int, repeats: int, shift: float, rng: np.random.Generator) -> dict:
    """All measurements for one rod size N (n_dof = 4N - 1)."""
    n = 4 * N - 1
    ab0 = random_band(n, rng, shift)
    b0 = rng.standard_normal(n)
    compact0 = np.ascontiguousarray(ab0[KL:])  # (kl+ku+1, n) for solve_banded

    ab = band_alloc(n)
    b = np.empty(n)
    b2 = np.empty((n, 1), order="F")
    ipiv = np.zeros(n, dtype=np.int32)
    ipiv_l = np.zeros(n, dtype=np.int32)

    def reset():
        np.copyto(ab, ab0)
        np.copyto(b, b0)
        np.copyto(b2[:, 0], b0)

    # --- correctness cross-check before timing
    reset()
    assert band_lu_factor(ab, n, ipiv) == 0
    band_lu_solve(ab, n, ipiv, b)
    x_numba = b.copy()
    n_swaps = int(np.count_nonzero(ipiv != np.arange(n)))
    reset()
    assert lapack_factor_solve(ab, n, ipiv_l, b) == 0
    x_nl = b.copy()
    reset()
    lub, piv, x, info = lapack.dgbsv(KL, KU, ab, b2, overwrite_ab=1, overwrite_b=1)
    assert info == 0 and np.shares_memory(lub, ab) and np.shares_memory(x, b2)
    x_dgbsv = x[:, 0].copy()
    x_sb = solve_banded((KL, KU), compact0, b0, check_finite=False)
    r = np.empty(n)
    band_matvec(ab0, n, x_numba, r)
    scale = np.abs(x_dgbsv).max()
    check = {
        "n_row_swaps": n_swaps,
        "ipiv_equal_dgbsv": bool(np.array_equal(ipiv, piv)),
        "max_rel_diff_numba_vs_dgbsv": float(np.abs(x_numba - x_dgbsv).max() / scale),
        "max_rel_diff_numba_lapack_vs_dgbsv": float(np.abs(x_nl - x_dgbsv).max() / scale),
        "max_rel_diff_solve_banded_vs_dgbsv": float(np.abs(x_sb - x_dgbsv).max() / scale),
        "rel_residual_numba": float(np.linalg.norm(r - b0) / np.linalg.norm(b0)),
    }

    def m_numba():
        band_lu_factor(ab, n, ipiv)
        band_lu_solve(ab, n, ipiv, b)

    methods = {
        "numba": (m_numba, reset),
        "numba_one_call": (lambda: numba_factor_solve(ab, n, ipiv, b), reset),
        "numba_lapack": (lambda: lapack_factor_solve(ab, n, ipiv_l, b), reset),
        "scipy_dgbsv": (
            lambda: lapack.dgbsv(KL, KU, ab, b2, overwrite_ab=1, overwrite_b=1),
            reset,
        ),
        "scipy_solve_banded": (
            lambda: solve_banded((KL, KU), compact0, b, overwrite_b=True, check_finite=False),
            reset,
        ),
        "numba_factor_only": (lambda: band_lu_factor(ab, n, ipiv), reset),
        "copy_ab": (lambda: np.copyto(ab, ab0), lambda: None),
    }
    # warm-up, then interleave chunks of repeats so machine noise hits all alike
    for fn, setup in methods.values():
        timed(fn, setup, 20)
    chunk = 10
    ts = {k: [] for k in methods}
    for _ in range(0, repeats, chunk):
        for k, (fn, setup) in methods.items():
            ts[k].append(timed(fn, setup, chunk))
    res = {}
    for k, v in ts.items():
        v = np.concatenate(v) * 1e6
        res[k] = {"median_us": round(float(np.median(v)), 2), "min_us": round(float(v.min()), 2)}
    med = {k: v["median_us"] for k, v in res.items()}
    res["ratio_numba_over_dgbsv"] = round(med["numba"] / med["scipy_dgbsv"], 3)
    res["ratio_numba_over_numba_lapack"] = round(med["numba"] / med["numba_lapack"], 3)
    res["ratio_numba_over_solve_banded"] = round(med["numba"] / med["scipy_solve_banded"], 3)
    res["numba_within_1.5x_of_lapack"] = bool(
        med["numba"] <= 1.5 * min(med["scipy_dgbsv"], med["numba_lapack"])
    )

    # assembly: one 11-DOF stencil per interior node, blocks 11x11, incl. band_zero
    n_el = (n - 11) // 4 + 1
    blocks = rng.standard_normal((n_el, 11, 11))
    dofs = np.zeros(11, dtype=np.int64)
    _assemble_dofs(ab, n, blocks, dofs)
    a1 = ab.copy()
    _assemble_contig(ab, n, blocks)
    assert np.array_equal(a1, ab)
    t_d = timed(lambda: _assemble_dofs(ab, n, blocks, dofs), lambda: None, repeats)
    t_c = timed(lambda: _assemble_contig(ab, n, blocks), lambda: None, repeats)
    res["assembly_11x11_blocks"] = {
        "n_blocks": n_el,
        "band_add_block_dofs_median_us": round(float(np.median(t_d)) * 1e6, 2),
        "band_add_block_contig_median_us": round(float(np.median(t_c)) * 1e6, 2),
    }
    return {"n_dof": n, "check": check, **res}


def run(sizes, repeats, shift):
    rng = np.random.default_rng(12345)
    config = {
        "kl": KL,
        "ku": KU,
        "diag_shift": shift,
        "repeats": repeats,
        "stat": "median and min over repeats, microseconds; methods interleaved",
        "numba": numba.__version__,
        "numpy": np.__version__,
        "scipy": scipy.__version__,
        "machine": platform.processor() or platform.machine(),
    }
    results = {str(N): bench_one(N, repeats, shift, rng) for N in sizes}
    return {"config": config, "results": results}


def main():
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--sizes", type=int, nargs="+", default=[250, 500, 1000, 2000])
    p.add_argument("--repeats", type=int, default=400)
    p.add_argument("--shift", type=float, default=5.0, help="diagonal shift (pivoting amount)")
    a = p.parse_args()
    print(json.dumps(run(a.sizes, a.repeats, a.shift), indent=2))


if __name__ == "__main__":
    main()

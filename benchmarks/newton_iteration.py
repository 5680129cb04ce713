"""Cost of one Newton iteration of the implicit DER stepper against a bare banded LU.

For N = 250, 500, 1000, 2000 nodes (n_dof = 4N - 1), on a bent, twisted rod with drag:

* ``assemble_us``: frames + strains + residual + Jacobian in band storage;
* ``solve_us``: our pivoted banded LU factor + solve (numba, ``banded.py``);
* ``iteration_us``: the sum, i.e. one Newton iteration;
* ``bare_lu_numba_us`` / ``bare_lu_lapack_us``: the floor, factor + solve of the same
  matrix alone (our kernel; LAPACK dgbsv through scipy, called on a prepared copy).

Prints JSON; medians over repeats after a warm-up. Run:

    python benchmarks/newton_iteration.py [--repeats 200]
"""

from __future__ import annotations

import argparse
import json
import platform
import time

import numpy as np
from scipy.linalg import lapack

from cnt_env.cli.common import int_list
from cnt_env.rod.banded import KL, KU, band_lu_factor, band_lu_solve
from cnt_env.sim.stepper import (
    SOFT_FRESH,
    DragParams,
    Rod,
    RodMaterial,
    assemble,
    update_frames,
)


def make_rod(n_nodes: int) -> Rod:
    s = np.linspace(0.0, n_nodes - 1.0, n_nodes)  # unit edges
    nodes = np.stack([3.0 * np.cos(s / 15), 3.0 * np.sin(s / 15), 0.2 * s], axis=1)
    rod = Rod(nodes, RodMaterial(k_s=6.6e3, k_b=1.0, k_t=1.0, rho=2200.0, r0=0.02),
              drag=DragParams(mu=1.0))  # fmt: skip
    rod.flow[:] = (0.01, 0.0, 0.0)
    rod.fix_node(0)
    rod.fix_node(1)
    rod.fix_theta(0)
    rng = np.random.default_rng(0)
    rod.u[: rod.n_dof] = 1e-3 * rng.normal(size=rod.n_dof)
    return rod


def _median_us(fn, repeats: int) -> float:
    fn()
    times = []
    for _ in range(repeats):
        t0 = time.perf_counter()
        fn()
        times.append(time.perf_counter() - t0)
    return float(np.median(times) * 1e6)


def bench(n_nodes: int, repeats: int) -> dict:
    rod = make_rod(n_nodes)
    n = rod.n_dof
    dt = 0.05
    q_old = rod.q.copy()
    q = rod.q.copy()
    q[:n] += dt * rod.u[:n]
    m, d = rod.material, rod.drag
    ws = {name: getattr(rod, name) for name in (
        "_tangents", "_lengths", "_d1", "_d2", "_ref_twist", "_m1", "_m2", "_kb", "_kappa",
        "_twist", "_force", "_ab", "_ipiv", "_rhs")}  # fmt: skip

    def do_assemble() -> None:
        update_frames(q, n_nodes, rod.tangents_old, rod.d1_old, rod.ref_twist_old,
                      ws["_tangents"], ws["_lengths"], ws["_d1"], ws["_d2"], ws["_ref_twist"],
                      ws["_m1"], ws["_m2"], ws["_kb"], ws["_kappa"], ws["_twist"])  # fmt: skip
        assemble(q, q_old, rod.u, n_nodes, dt, rod.mass, rod.fixed, rod.rest_lengths,
                 rod.voronoi_lengths, m.k_s, m.k_b, m.k_t, ws["_m1"], ws["_m2"], ws["_twist"],
                 rod.ext_force, rod.drag_on, rod.flow, d.shear, d.mu, d.sigma, d.c_sigma,
                 d.law_code, rod.vdw, rod.sub_friction, rod.sub_stiffness, rod.sub_anchor,
                 ws["_force"],
                 ws["_ab"], ws["_rhs"], rod.tangents_old, rod.options.exact_jacobian, True,
                 rod._ab_soft, SOFT_FRESH)  # fmt: skip

    do_assemble()
    ab0 = ws["_ab"][:, :n].copy(order="F")
    rhs0 = ws["_rhs"][:n].copy()
    ab = ab0.copy(order="F")
    b = rhs0.copy()
    ipiv = np.zeros(n, dtype=np.int64)

    def do_solve() -> None:
        ab[...] = ab0
        b[...] = rhs0
        band_lu_factor(ab, n, ipiv)
        band_lu_solve(ab, n, ipiv, b)

    def do_copy() -> None:
        ab[...] = ab0
        b[...] = rhs0

    def do_lapack() -> None:
        ab[...] = ab0
        b[...] = rhs0
        lapack.dgbsv(KL, KU, ab, b, overwrite_ab=True, overwrite_b=True)

    t_asm = _median_us(do_assemble, repeats)
    t_copy = _median_us(do_copy, repeats)
    t_solve = _median_us(do_solve, repeats) - t_copy
    t_lapack = _median_us(do_lapack, repeats) - t_copy
    # sanity: the solution solves the system
    do_solve()
    x = b.copy()
    dense = np.zeros((n, n))
    if n <= 4000:
        for i in range(n):
            for j in range(max(0, i - KL), min(n, i + KU + 1)):
                dense[i, j] = ab0[KL + KU + i - j, j]
        rel = float(np.linalg.norm(dense @ x - rhs0) / np.linalg.norm(rhs0))
    else:
        rel = float("nan")
    return {
        "n_nodes": n_nodes,
        "n_dof": n,
        "assemble_us": round(t_asm, 2),
        "solve_us": round(t_solve, 2),
        "iteration_us": round(t_asm + t_solve, 2),
        "bare_lu_numba_us": round(t_solve, 2),
        "bare_lu_lapack_us": round(t_lapack, 2),
        "iteration_over_lapack_lu": round((t_asm + t_solve) / t_lapack, 2),
        "iteration_over_numba_lu": round((t_asm + t_solve) / t_solve, 2),
        "assemble_us_per_node": round(t_asm / n_nodes, 4),
        "solve_residual_rel": rel,
    }


def main(argv: list[str] | None = None) -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--repeats", type=int, default=200)
    parser.add_argument("--sizes", type=int_list, default="250,500,1000,2000")
    args = parser.parse_args(argv)
    rows = [bench(n, args.repeats) for n in args.sizes]
    per_node = [r["iteration_us"] / r["n_nodes"] for r in rows]
    out = {
        "benchmark": "newton_iteration",
        "machine": platform.processor() or platform.machine(),
        "rows": rows,
        "iteration_us_per_node": [round(x, 4) for x in per_node],
        "linear_in_N": bool(max(per_node) / min(per_node) < 1.5),
    }
    print(json.dumps(out, indent=2))


if __name__ == "__main__":
    main()

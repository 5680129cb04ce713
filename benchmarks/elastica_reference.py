"""Steady-state reference for the "CNT in cross-flow" anchor problem.

A rod of length ``L`` is clamped at the origin, standing along +y, in a uniform
gas flow ``U`` along +x.  Once the rod has come to rest its velocity is zero, so
the drag per unit length it feels is the linear anisotropic law evaluated on the
full flow velocity ``v = (U, 0)``:

    f = mu [sigma t(t.v) + C_sigma (v - t(t.v))],     t = (cos th, sin th).

Because ``f`` depends on the local tangent angle ``th`` the load is a
*follower-type* (non-conservative) distributed load.  Its components are

    f_x = mu U (sigma cos^2 th + C_sigma sin^2 th),
    f_y = mu U (sigma - C_sigma) cos th sin th.

Continuum model (:func:`steady_tip`)
------------------------------------
Planar, inextensible, unshearable Kirchhoff elastica with bending stiffness
``k_b``.  With arc length ``s`` in [0, L], internal force ``n = (n_x, n_y)``
(force exerted by the part beyond ``s`` on the part before it) and bending
moment ``M = k_b th'``, the static balance laws ``n' + f = 0`` and
``M' + t x n = 0`` give the first-order system

    x' = cos th,  y' = sin th,  th' = M / k_b,
    M' = n_x sin th - n_y cos th,
    n_x' = -f_x(th),  n_y' = -f_y(th),

with boundary conditions x(0) = y(0) = 0, th(0) = pi/2 (clamp, tangent along
+y) and n_x(L) = n_y(L) = M(L) = 0 (free tip).  It is solved in scaled
variables s/L, x/L, y/L, n L^2/(k_b lam), M L/(k_b lam), in which the only
parameters are the load number ``lam = mu U L^3 / k_b`` (= 1514 for the
anchor), ``sigma`` and ``C_sigma``, using :func:`scipy.integrate.solve_bvp`
with an analytic Jacobian and continuation in ``lam`` from the straight rod.
Dividing force and moment by ``lam`` keeps the unknowns O(1); without it the
relative collocation residual has a round-off floor near 1e-9 and solve_bvp's
mesh refinement runs away for tol <= 1e-10.

Discrete model (:func:`steady_tip_discrete_check`)
--------------------------------------------------
An independent check: an inextensible chain of ``n_edges`` rigid links of equal
length ``h = L / n_edges`` joined by rotational springs (bending energy
``sum k_b phi_i^2 / (2 h)`` with turning angles ``phi_i``), the first link clamped
along +y as in a DER clamp, each link's drag ``f(th_j) h`` lumped half onto each
of its end nodes.  The equilibrium equations are solved with Newton's method and
continuation.  Its tip converges to the continuum tip at *first* order in
``h`` (the clamped first link and the lumping are O(h) effects), so at N = 200
and 400 it shows how far a discrete rod's steady tip may legitimately sit from
the continuum one; 2 tip(2N) - tip(N) lands on the continuum tip.

Results for the anchor parameters (``python -m benchmarks.elastica_reference``)
-------------------------------------------------------------------------------
* Stated law (sigma = 1, C_sigma = 2.29): tip x = 19.69964 um, y = 0.73034 um;
  tol 1e-5 ... 1e-10 changes the tip by < 1e-9 relative (1e-14 at the end).
  Discrete chain: N = 200 (19.6469, 0.7818), N = 400 (19.6739, 0.7559),
  N = 800 (19.6869, 0.7431) um.
* The earlier figure (19.799, 0.487) um is the steady tip of the *isotropic*
  law sigma = C_sigma = 2.29: on a static rod isotropic drag is the uniform dead
  load C_sigma mu U along +x, and ``steady_tip(sigma=2.29)`` or
  ``steady_tip(load="dead")`` give (19.79915, 0.48733) um.  With sigma = 1 the
  nearly flow-aligned rod feels 2.29x less axial drag, hence less tension
  straightening its tail and a higher tip.
"""

from __future__ import annotations

import json
import time

import numpy as np
from scipy.integrate import solve_bvp

# Anchor-problem defaults (SI).
LENGTH = 20e-6  # m
K_B = 2.7e-24  # N m^2
MU = 5.11e-7  # Pa s
SIGMA = 1.0
C_SIGMA = 2.29
FLOW = 1.0  # m/s


LOAD_MODELS = ("drag", "dead")


def _load(th, sigma, c_sigma, load="drag"):
    """Drag per unit length divided by mu U, and its derivative in th.

    ``load="drag"``: the linear anisotropic drag on the static rod (follower
    load, depends on the tangent angle).  ``load="dead"``: C_sigma mu U along
    +x everywhere, the drag of the undeformed vertical rod, identical to the
    isotropic law sigma = C_sigma (see the module docstring).
    """
    if load == "dead":
        z = np.zeros_like(th)
        return c_sigma + z, z, z, z
    if load != "drag":
        raise ValueError(f"load must be one of {LOAD_MODELS}, got {load!r}")
    c = np.cos(th)
    s = np.sin(th)
    gx = sigma * c * c + c_sigma * s * s
    gy = (sigma - c_sigma) * c * s
    dgx = 2.0 * (c_sigma - sigma) * s * c
    dgy = (sigma - c_sigma) * (c * c - s * s)
    return gx, gy, dgx, dgy


def _make_system(lam, sigma, c_sigma, load="drag"):
    """ODE right-hand side and Jacobian in scaled variables.

    State z = [x/L, y/L, th, M L/(k_b lam), n_x L^2/(k_b lam), n_y L^2/(k_b lam)]
    with lam = mu U L^3 / k_b.  Dividing the force and moment by lam keeps all
    unknowns O(1) for any load, which keeps solve_bvp's relative residual well
    above its round-off floor; lam then appears only in th' = lam m.
    """

    def fun(_s, z):
        th, m, nx, ny = z[2], z[3], z[4], z[5]
        c = np.cos(th)
        sn = np.sin(th)
        gx, gy, _, _ = _load(th, sigma, c_sigma, load)
        return np.vstack((c, sn, lam * m, nx * sn - ny * c, -gx, -gy))

    def jac(_s, z):
        th, nx, ny = z[2], z[4], z[5]
        c = np.cos(th)
        sn = np.sin(th)
        _, _, dgx, dgy = _load(th, sigma, c_sigma, load)
        j = np.zeros((6, 6, z.shape[1]))
        j[0, 2] = -sn
        j[1, 2] = c
        j[2, 3] = lam
        j[3, 2] = nx * c + ny * sn
        j[3, 4] = sn
        j[3, 5] = -c
        j[4, 2] = -dgx
        j[5, 2] = -dgy
        return j

    return fun, jac


def _bc(za, zb):
    return np.array([za[0], za[1], za[2] - 0.5 * np.pi, zb[3], zb[4], zb[5]])


def _bc_jac(_za, _zb):
    ja = np.zeros((6, 6))
    jb = np.zeros((6, 6))
    ja[0, 0] = ja[1, 1] = ja[2, 2] = 1.0
    jb[3, 3] = jb[4, 4] = jb[5, 5] = 1.0
    return ja, jb


def _straight_guess(s):
    z = np.zeros((6, s.size))
    z[1] = s
    z[2] = 0.5 * np.pi
    return z


def _solve_scaled(lam_target, sigma, c_sigma, load, n_mesh, tol, max_nodes, lam_start=1.0):
    """Continuation in lam from the straight rod, then a final solve at ``tol``.

    Returns (sol, path) with path = [(lam, solve_bvp status, mesh nodes), ...].
    The continuation steps use a loose tolerance (max(tol, 1e-5)); lam grows
    geometrically and the growth factor is halved on failure.
    """
    s = np.linspace(0.0, 1.0, n_mesh)
    z = _straight_guess(s)
    path = []
    lam_target = float(lam_target)
    step_tol = max(tol, 1e-5)
    lam = min(lam_start, lam_target)
    factor = 2.0
    lam_done = 0.0
    sol = None
    while lam_done < lam_target:
        fun, jac = _make_system(lam, sigma, c_sigma, load)
        trial = solve_bvp(
            fun, _bc, s, z, fun_jac=jac, bc_jac=_bc_jac, tol=step_tol, max_nodes=max_nodes
        )
        path.append((lam, int(trial.status), int(trial.x.size)))
        if trial.status == 0:
            sol, s, z, lam_done = trial, trial.x, trial.y, lam
            factor = min(factor * 1.5, 4.0)
            lam = min(lam * factor, lam_target)
        else:
            factor = 1.0 + 0.5 * (factor - 1.0)
            if factor < 1.0 + 1e-3:
                raise RuntimeError(f"continuation stalled at lam={lam_done:g}: {trial.message}")
            lam = lam_done * factor if lam_done > 0 else lam * 0.5
    if tol < step_tol:
        fun, jac = _make_system(lam_target, sigma, c_sigma, load)
        sol = solve_bvp(fun, _bc, s, z, fun_jac=jac, bc_jac=_bc_jac, tol=tol, max_nodes=max_nodes)
        path.append((lam_target, int(sol.status), int(sol.x.size)))
        if sol.status != 0:
            raise RuntimeError(f"final solve at tol={tol:g} failed: {sol.message}")
    return sol, path


def _global_balance(sol, sigma, c_sigma, load, n_quad=20001):
    """Independent check of a solution: overall force and moment balance.

    From n' = -f and M' = -(r x n)' - r x f with r(0) = 0 and n(L) = M(L) = 0
    follow n(0) = int f ds and M(0) = int (r x f) ds.  The integrals are taken
    by Simpson's rule on the dense (interpolated) BVP solution, so they check
    the shape against the base reactions.  Returns the mismatches relative to
    the base reactions.
    """
    s = np.linspace(0.0, 1.0, n_quad)
    z = sol.sol(s)
    gx, gy, _, _ = _load(z[2], sigma, c_sigma, load)
    w = np.ones(n_quad)
    w[1:-1:2] = 4.0
    w[2:-1:2] = 2.0
    w *= (s[1] - s[0]) / 3.0
    z0 = sol.y[:, 0]
    scale_f = max(abs(z0[4]), abs(z0[5]), 1e-300)
    scale_m = max(abs(z0[3]), 1e-300)
    return {
        "force_mismatch": float(max(abs(w @ gx - z0[4]), abs(w @ gy - z0[5])) / scale_f),
        "moment_mismatch": float(abs(w @ (z[0] * gy - z[1] * gx) - z0[3]) / scale_m),
    }


def steady_tip(
    length=LENGTH,
    k_b=K_B,
    mu=MU,
    sigma=SIGMA,
    c_sigma=C_SIGMA,
    flow=FLOW,
    n_mesh=201,
    tol=1e-8,
    max_nodes=100_000,
    load="drag",
):
    """Steady shape of the clamped rod in the flow (continuum elastica BVP).

    Parameters are SI (``mu`` in Pa s, ``flow`` in m/s).  ``n_mesh`` is the
    initial uniform mesh on [0, L]; ``tol`` is solve_bvp's tolerance on the
    relative collocation residual (the mesh is refined until it is met);
    ``load`` is ``"drag"`` (the physical follower drag, default) or ``"dead"``
    (uniform C_sigma mu U along +x, same as ``sigma=c_sigma``).

    Returns a dict with

    * ``tip_x``, ``tip_y`` (m);
    * the shape: ``s``, ``x``, ``y`` (m), ``theta`` (rad, from +x),
      ``moment`` (N m), ``n_x``, ``n_y`` (N, internal force), and the base
      reactions ``base_force`` (N, N) and ``base_moment`` (N m);
    * convergence info: ``success``, ``message``, ``max_rms_residual``
      (largest relative collocation residual), ``bc_residual``, ``n_nodes``
      (final mesh), ``path`` (continuation [(lam, status, nodes)]), ``lam``
      (= mu U L^3 / k_b), ``tol``, ``balance`` (global force / moment balance
      mismatch, see ``_global_balance``) and ``wall_time_s``.
    """
    t0 = time.perf_counter()
    _load(np.zeros(1), sigma, c_sigma, load)  # validates ``load``
    lam = mu * flow * length**3 / k_b
    scale_n = lam * k_b / length**2  # N per unit of scaled force
    scale_m = lam * k_b / length  # N m per unit of scaled moment
    if lam == 0.0:
        s = np.linspace(0.0, 1.0, n_mesh)
        z = _straight_guess(s)
        info = {"success": True, "message": "zero load", "rms": 0.0, "path": []}
        balance = {"force_mismatch": 0.0, "moment_mismatch": 0.0}
    else:
        sol, path = _solve_scaled(lam, sigma, c_sigma, load, n_mesh, tol, max_nodes)
        s, z = sol.x, sol.y
        info = {
            "success": bool(sol.success),
            "message": sol.message,
            "rms": float(np.max(sol.rms_residuals)),
            "path": path,
        }
        balance = _global_balance(sol, sigma, c_sigma, load)
    return {
        "tip_x": float(z[0, -1] * length),
        "tip_y": float(z[1, -1] * length),
        "s": s * length,
        "x": z[0] * length,
        "y": z[1] * length,
        "theta": z[2].copy(),
        "moment": z[3] * scale_m,
        "n_x": z[4] * scale_n,
        "n_y": z[5] * scale_n,
        "base_force": (float(z[4, 0] * scale_n), float(z[5, 0] * scale_n)),
        "base_moment": float(z[3, 0] * scale_m),
        "success": info["success"],
        "message": info["message"],
        "max_rms_residual": info["rms"],
        "bc_residual": float(np.max(np.abs(_bc(z[:, 0], z[:, -1])))),
        "n_nodes": int(s.size),
        "path": info["path"],
        "lam": lam,
        "tol": tol,
        "balance": balance,
        "wall_time_s": time.perf_counter() - t0,
    }


def tip_convergence(tols=(1e-5, 1e-6, 1e-7, 1e-8, 1e-9, 1e-10), **kwargs):
    """Tip of :func:`steady_tip` for a sequence of tightening tolerances.

    Returns a list of dicts (tol, tip_x, tip_y, n_nodes, rel_change) where
    ``rel_change`` = |tip - previous tip| / |tip| (None for the first row).
    """
    rows = []
    prev = None
    for tol in tols:
        r = steady_tip(tol=tol, **kwargs)
        tip = np.array([r["tip_x"], r["tip_y"]])
        rel = None if prev is None else float(np.linalg.norm(tip - prev) / np.linalg.norm(tip))
        rows.append(
            {
                "tol": tol,
                "tip_x": r["tip_x"],
                "tip_y": r["tip_y"],
                "n_nodes": r["n_nodes"],
                "rel_change": rel,
            }
        )
        prev = tip
    return rows


# ---------------------------------------------------------------------------
# Discrete check: inextensible chain of rigid links with rotational springs.
# ---------------------------------------------------------------------------


def _chain_residual(th_free, th0, h, lam, sigma, c_sigma, load="drag"):
    """Generalised forces on the free link angles, in units of k_b / L.

    Link j (length h, scaled by L) has angle th[j]; th[0] = th0 is clamped and
    th[1:] = th_free.  Returns the residual G (length n - 1) and its dense
    Jacobian dG/dth_free.
    """
    th = np.concatenate(([th0], th_free))
    n = th.size
    c = np.cos(th)
    sn = np.sin(th)
    gx, gy, dgx, dgy = _load(th, sigma, c_sigma, load)
    fx, fy, dfx, dfy = lam * gx, lam * gy, lam * dgx, lam * dgy
    # Node loads: link j puts f_j h / 2 on each of nodes j and j + 1 (0..n).
    # Total load on the nodes beyond the start of link k (nodes k+1..n):
    #   S_k = h * (sum_{j>k} f_j + f_k / 2).
    suffix_x = np.concatenate((np.cumsum(fx[::-1])[::-1], [0.0]))  # sum_{j>=k}
    suffix_y = np.concatenate((np.cumsum(fy[::-1])[::-1], [0.0]))
    sx = h * (suffix_x[1:] + 0.5 * fx)
    sy = h * (suffix_y[1:] + 0.5 * fy)
    # Bending energy E = sum_{i=1}^{n-1} (th_i - th_{i-1})^2 / (2 h)  (k_b = 1),
    # i.e. the DER form k_b kappa^2 / l_bar with kappa = turning angle and
    # l_bar = 2 h, which tends to (1/2) int k_b th'^2 ds.
    phi = np.diff(th)
    g = np.zeros(n)
    g[1:] += phi / h
    g[:-1] -= phi / h
    # Virtual work of the loads: d x_node / d th_k = h (-sin, cos) for every
    # node beyond link k.
    a = h * sn  # coefficient of sx in G
    b = -h * c  # coefficient of sy in G
    g += a * sx + b * sy
    idx = np.arange(n)
    jac = np.zeros((n, n))
    d = 1.0 / h
    jac[idx[1:], idx[1:]] += d
    jac[idx[:-1], idx[:-1]] += d
    jac[idx[1:], idx[:-1]] -= d
    jac[idx[:-1], idx[1:]] -= d
    # Explicit dependence of a_k, b_k on th_k.
    jac[idx, idx] += h * c * sx + h * sn * sy
    # Dependence through S_k on th_m: h df_m for m > k, h/2 df_k for m == k.
    upper = np.triu(np.ones((n, n)), 1)
    jac += upper * (a[:, None] * h * dfx[None, :] + b[:, None] * h * dfy[None, :])
    jac[idx, idx] += 0.5 * h * (a * dfx + b * dfy)
    return g[1:], jac[1:, 1:]


def _chain_newton(th_free, th0, h, lam, sigma, c_sigma, load, tol=1e-12, max_iter=50):
    for it in range(max_iter):
        g, jac = _chain_residual(th_free, th0, h, lam, sigma, c_sigma, load)
        dx = np.linalg.solve(jac, -g)
        big = np.max(np.abs(dx))
        if big > 0.5:  # damp very large angle updates
            dx *= 0.5 / big
        th_free = th_free + dx
        if np.max(np.abs(dx)) < tol:
            g, _ = _chain_residual(th_free, th0, h, lam, sigma, c_sigma, load)
            return th_free, it + 1, float(np.max(np.abs(g)))
    raise RuntimeError("Newton did not converge")


def steady_tip_discrete_check(
    n_edges=200,
    length=LENGTH,
    k_b=K_B,
    mu=MU,
    sigma=SIGMA,
    c_sigma=C_SIGMA,
    flow=FLOW,
    load="drag",
):
    """Steady tip of the discrete inextensible chain (see module docstring).

    The chain has ``n_edges`` equal links, the first one clamped along +y (DER
    clamp).  Its tip converges to :func:`steady_tip` at first order in 1/N
    (the clamped first link and the half-link load lumping are O(h) effects),
    so Richardson extrapolation 2 tip(2N) - tip(N) approaches the continuum.
    Returns dict(tip_x, tip_y, x, y, theta, n_edges, residual, newton_iters).
    """
    lam = mu * flow * length**3 / k_b
    h = 1.0 / n_edges
    th0 = 0.5 * np.pi
    th_free = np.full(n_edges - 1, th0)
    lam_k = min(1.0, lam)
    lam_done = 0.0 if lam > 0.0 else lam
    factor = 2.0
    iters = 0
    res = 0.0
    while lam_done < lam:
        try:
            new, it, res = _chain_newton(th_free.copy(), th0, h, lam_k, sigma, c_sigma, load)
        except (RuntimeError, np.linalg.LinAlgError):
            factor = 1.0 + 0.5 * (factor - 1.0)
            if factor < 1.0 + 1e-3:
                raise
            lam_k = lam_done * factor if lam_done > 0 else 0.5 * lam_k
            continue
        th_free, lam_done = new, lam_k
        iters += it
        factor = min(factor * 1.5, 4.0)
        lam_k = min(lam_k * factor, lam)
    th = np.concatenate(([th0], th_free))
    x = np.concatenate(([0.0], np.cumsum(h * np.cos(th)))) * length
    y = np.concatenate(([0.0], np.cumsum(h * np.sin(th)))) * length
    return {
        "tip_x": float(x[-1]),
        "tip_y": float(y[-1]),
        "x": x,
        "y": y,
        "theta": th,
        "n_edges": n_edges,
        "residual": res,
        "newton_iters": iters,
    }


def _main():
    r = steady_tip(tol=1e-10)
    dead = steady_tip(tol=1e-10, load="dead")
    summary = {
        "tip_x_um": r["tip_x"] * 1e6,
        "tip_y_um": r["tip_y"] * 1e6,
        "success": r["success"],
        "max_rms_residual": r["max_rms_residual"],
        "bc_residual": r["bc_residual"],
        "balance": r["balance"],
        "n_nodes": r["n_nodes"],
        "lam": r["lam"],
        "continuation_steps": len(r["path"]),
        "base_force_N": r["base_force"],
        "base_moment_Nm": r["base_moment"],
        "wall_time_s": r["wall_time_s"],
        "dead_load_tip_um": [dead["tip_x"] * 1e6, dead["tip_y"] * 1e6],
        "convergence": tip_convergence(),
        "discrete": {},
    }
    for n in (100, 200, 400, 800):
        d = steady_tip_discrete_check(n_edges=n)
        summary["discrete"][n] = {
            "tip_x_um": d["tip_x"] * 1e6,
            "tip_y_um": d["tip_y"] * 1e6,
            "residual": d["residual"],
        }
    print(json.dumps(summary, indent=2))


if __name__ == "__main__":
    _main()

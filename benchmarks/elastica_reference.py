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
variables (s/L, x/L, y/L, n L^2/k_b, M L/k_b), in which the only parameters are
the load number ``lam = mu U L^3 / k_b``, ``sigma`` and ``C_sigma``, using
:func:`scipy.integrate.solve_bvp` with an analytic Jacobian and continuation in
``lam`` starting from the straight rod.

Discrete model (:func:`steady_tip_discrete_check`)
--------------------------------------------------
An independent check: an inextensible chain of ``n_edges`` rigid links of equal
length ``h = L / n_edges`` joined by rotational springs (bending energy
``sum k_b phi_i^2 / h`` with turning angles ``phi_i``), the first link clamped
along +y as in a DER clamp, each link's drag ``f(th_j) h`` lumped half onto each
of its end nodes.  The equilibrium equations are solved with Newton's method and
continuation.  Its tip converges to the continuum tip at second order in ``h``
(it is what a DER with the same lumping tends to at steady state, up to the
tiny axial strain of the extensible rod), and at N = 200 / 400 it tells how far
a discrete rod's steady tip may legitimately sit from the continuum one.

For the anchor parameters, ``steady_tip()`` gives tip x = 19.7991 um,
y = 0.4872 um (see ``python -m benchmarks.elastica_reference``).
"""

from __future__ import annotations

import json
import time

import numpy as np
from scipy.integrate import solve_bvp, solve_ivp

# Anchor-problem defaults (SI).
LENGTH = 20e-6  # m
K_B = 2.7e-24  # N m^2
MU = 5.11e-7  # Pa s
SIGMA = 1.0
C_SIGMA = 2.29
FLOW = 1.0  # m/s


def _load(th, lam, sigma, c_sigma):
    """Scaled drag components (f L^3 / k_b) and their derivatives in th."""
    c = np.cos(th)
    s = np.sin(th)
    fx = lam * (sigma * c * c + c_sigma * s * s)
    fy = lam * (sigma - c_sigma) * c * s
    dfx = lam * 2.0 * (c_sigma - sigma) * s * c
    dfy = lam * (sigma - c_sigma) * (c * c - s * s)
    return fx, fy, dfx, dfy


def _make_system(lam, sigma, c_sigma):
    # State z = [x, y, th, M, nx, ny] in scaled units.
    def fun(_s, z):
        th, m, nx, ny = z[2], z[3], z[4], z[5]
        c = np.cos(th)
        sn = np.sin(th)
        fx, fy, _, _ = _load(th, lam, sigma, c_sigma)
        return np.vstack((c, sn, m, nx * sn - ny * c, -fx, -fy))

    def jac(_s, z):
        th, nx, ny = z[2], z[4], z[5]
        c = np.cos(th)
        sn = np.sin(th)
        _, _, dfx, dfy = _load(th, lam, sigma, c_sigma)
        j = np.zeros((6, 6, z.shape[1]))
        j[0, 2] = -sn
        j[1, 2] = c
        j[2, 3] = 1.0
        j[3, 2] = nx * c + ny * sn
        j[3, 4] = sn
        j[3, 5] = -c
        j[4, 2] = -dfx
        j[5, 2] = -dfy
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


def _solve_scaled(lam_target, sigma, c_sigma, n_mesh, tol, max_nodes, lam_start=1.0):
    """Continuation in lam from the straight rod; returns (sol, path)."""
    s = np.linspace(0.0, 1.0, n_mesh)
    z = _straight_guess(s)
    path = []
    lam_target = float(lam_target)
    # Continuation steps are done with a loose tolerance; the final solve is
    # done at the requested one.  lam grows geometrically, the step shrinks on
    # failure.
    step_tol = max(tol, 1e-5)
    lam = min(lam_start, lam_target)
    factor = 2.0
    lam_done = 0.0
    while True:
        last = lam >= lam_target
        fun, jac = _make_system(lam, sigma, c_sigma)
        sol = solve_bvp(
            fun,
            _bc,
            s,
            z,
            fun_jac=jac,
            bc_jac=_bc_jac,
            tol=tol if last else step_tol,
            max_nodes=max_nodes,
        )
        path.append((lam, int(sol.status), int(sol.x.size)))
        if sol.status == 0:
            s, z = sol.x, sol.y
            lam_done = lam
            if last:
                return sol, path
            factor = min(factor * 1.5, 4.0)
            lam = min(lam * factor, lam_target)
        else:
            factor = 1.0 + 0.5 * (factor - 1.0)
            if factor < 1.0 + 1e-3:
                raise RuntimeError(f"continuation stalled at lam={lam_done:g}: {sol.message}")
            lam = lam_done * factor if lam_done > 0 else lam * 0.5


def _check_by_shooting(sol, lam, sigma, c_sigma):
    """Integrate the IVP from the base with the BVP's base values; tip residual."""
    fun, _ = _make_system(lam, sigma, c_sigma)
    ivp = solve_ivp(
        fun, (0.0, 1.0), sol.y[:, 0], method="DOP853", rtol=1e-12, atol=1e-12, dense_output=False
    )
    zb = ivp.y[:, -1]
    return {
        "tip_x_scaled": float(zb[0]),
        "tip_y_scaled": float(zb[1]),
        "tip_bc_residual": float(np.max(np.abs(zb[3:]))),
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
    max_nodes=200_000,
    shoot_check=True,
):
    """Steady shape of the clamped rod in the flow (continuum elastica BVP).

    Parameters are SI (``mu`` in Pa s, ``flow`` in m/s).  ``n_mesh`` is the
    initial uniform mesh; ``tol`` is solve_bvp's relative tolerance on the
    collocation residual (the mesh is refined until it is met).

    Returns a dict with ``tip_x``, ``tip_y`` (m), the shape arrays ``s``, ``x``,
    ``y`` (m), ``theta`` (rad), ``moment`` (N m), ``n_x``, ``n_y`` (N), base
    reactions, and convergence info: ``success``, ``message``,
    ``max_rms_residual`` (scaled), ``bc_residual``, ``n_nodes``, the
    continuation ``path`` [(lam, status, nodes)], ``lam`` (load number
    mu U L^3 / k_b) and, if ``shoot_check``, an IVP re-integration from the base
    (``shoot``) whose tip must reproduce the BVP tip and the free-end BCs.
    """
    t0 = time.perf_counter()
    lam = mu * flow * length**3 / k_b
    if lam == 0.0:
        s = np.linspace(0.0, 1.0, n_mesh)
        z = _straight_guess(s)
        info = {"success": True, "message": "zero load", "rms": 0.0, "path": []}
        bc_res = 0.0
    else:
        sol, path = _solve_scaled(lam, sigma, c_sigma, n_mesh, tol, max_nodes)
        s, z = sol.x, sol.y
        info = {
            "success": bool(sol.success),
            "message": sol.message,
            "rms": float(np.max(sol.rms_residuals)),
            "path": path,
        }
        bc_res = float(np.max(np.abs(_bc(z[:, 0], z[:, -1]))))
    force = k_b / length**2
    out = {
        "tip_x": float(z[0, -1] * length),
        "tip_y": float(z[1, -1] * length),
        "s": s * length,
        "x": z[0] * length,
        "y": z[1] * length,
        "theta": z[2].copy(),
        "moment": z[3] * k_b / length,
        "n_x": z[4] * force,
        "n_y": z[5] * force,
        "base_force": (float(z[4, 0] * force), float(z[5, 0] * force)),
        "base_moment": float(z[3, 0] * k_b / length),
        "success": info["success"],
        "message": info["message"],
        "max_rms_residual": info["rms"],
        "bc_residual": bc_res,
        "n_nodes": int(s.size),
        "path": info["path"],
        "lam": lam,
        "tol": tol,
        "wall_time_s": 0.0,
    }
    if shoot_check and lam != 0.0:
        sh = _check_by_shooting(sol, lam, sigma, c_sigma)
        out["shoot"] = {
            "tip_x": sh["tip_x_scaled"] * length,
            "tip_y": sh["tip_y_scaled"] * length,
            "tip_bc_residual": sh["tip_bc_residual"],
        }
    out["wall_time_s"] = time.perf_counter() - t0
    return out


def tip_convergence(tols=(1e-6, 1e-8, 1e-10), **kwargs):
    """Tip of :func:`steady_tip` for a sequence of tolerances.

    Returns a list of dicts (tol, tip_x, tip_y, n_nodes, rel_change) where
    ``rel_change`` is |tip - previous tip| / |tip|.
    """
    rows = []
    prev = None
    for tol in tols:
        r = steady_tip(tol=tol, shoot_check=False, **kwargs)
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


def _chain_residual(th_free, th0, h_scaled, lam, sigma, c_sigma):
    """Generalised forces on the free link angles (scaled by k_b / L).

    Returns residual G (length n-1) and its Jacobian as a dense matrix.
    Angles th[0] = th0 (clamped), th[1:] = th_free.
    """
    th = np.concatenate(([th0], th_free))
    n = th.size
    h = h_scaled
    c = np.cos(th)
    sn = np.sin(th)
    fx, fy, dfx, dfy = _load(th, lam, sigma, c_sigma)
    # Node loads: link j contributes f_j h / 2 to nodes j and j+1 (nodes 0..n).
    # Force acting on everything beyond the start of link k (nodes k+1..n):
    #   S_k = sum_{j>=k+1} F_j = h * (sum_{j>k} f_j + f_k / 2)
    suffix_x = np.concatenate((np.cumsum(fx[::-1])[::-1], [0.0]))  # sum_{j>=k} fx_j
    suffix_y = np.concatenate((np.cumsum(fy[::-1])[::-1], [0.0]))
    sx = h * (suffix_x[1:] + 0.5 * fx)
    sy = h * (suffix_y[1:] + 0.5 * fy)
    # Elastic: E = sum_{i=1}^{n-1} (th_i - th_{i-1})^2 / h  (scaled k_b = 1)
    phi = np.diff(th)
    de = np.zeros(n)
    de[1:] += 2.0 * phi / h
    de[:-1] -= 2.0 * phi / h
    # Work: dx_node/dth_k = h (-sin, cos) for all nodes beyond link k.
    g = de - h * (-sn * sx + c * sy)
    # Jacobian wrt th (full n x n), then drop the clamped first row/column.
    jac = np.zeros((n, n))
    idx = np.arange(n)
    d = 2.0 / h
    jac[idx[1:], idx[1:]] += d
    jac[idx[:-1], idx[:-1]] += d
    jac[idx[1:], idx[:-1]] -= d
    jac[idx[:-1], idx[1:]] -= d
    # d/dth_k of -h(-sn_k sx_k + c_k sy_k), explicit dependence on th_k:
    jac[idx, idx] -= h * (-c * sx - sn * sy)
    # Dependence via sx_k, sy_k on th_m: dsx_k/dth_m = h dfx_m for m > k,
    # h/2 dfx_k for m == k.
    a = -h * (-sn)  # coefficient of sx in g
    b = -h * c  # coefficient of sy in g
    upper = np.triu(np.ones((n, n)), 1)
    jac += upper * (a[:, None] * h * dfx[None, :] + b[:, None] * h * dfy[None, :])
    jac[idx, idx] += a * 0.5 * h * dfx + b * 0.5 * h * dfy
    return g[1:], jac[1:, 1:]


def _chain_newton(th_free, th0, h, lam, sigma, c_sigma, tol=1e-12, max_iter=50):
    for it in range(max_iter):
        g, jac = _chain_residual(th_free, th0, h, lam, sigma, c_sigma)
        # The Jacobian is dense upper-Hessenberg-plus; solve directly.
        dx = np.linalg.solve(jac, -g)
        # Damp very large angle updates.
        big = np.max(np.abs(dx))
        if big > 0.5:
            dx *= 0.5 / big
        th_free = th_free + dx
        if np.max(np.abs(dx)) < tol:
            g, _ = _chain_residual(th_free, th0, h, lam, sigma, c_sigma)
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
):
    """Steady tip of a discrete inextensible chain (see module docstring).

    Returns dict(tip_x, tip_y, x, y, theta, n_edges, residual, newton_iters).
    """
    lam = mu * flow * length**3 / k_b
    h = 1.0 / n_edges
    th0 = 0.5 * np.pi
    th_free = np.full(n_edges - 1, th0)
    lam_k = min(1.0, lam)
    lam_done = 0.0
    factor = 2.0
    iters = 0
    res = 0.0
    while True:
        try:
            new, it, res = _chain_newton(th_free.copy(), th0, h, lam_k, sigma, c_sigma)
        except (RuntimeError, np.linalg.LinAlgError):
            factor = 1.0 + 0.5 * (factor - 1.0)
            if factor < 1.0 + 1e-3:
                raise
            lam_k = lam_done * factor if lam_done > 0 else 0.5 * lam_k
            continue
        th_free, lam_done = new, lam_k
        iters += it
        if lam_done >= lam:
            break
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
    summary = {
        "tip_x_um": r["tip_x"] * 1e6,
        "tip_y_um": r["tip_y"] * 1e6,
        "success": r["success"],
        "max_rms_residual": r["max_rms_residual"],
        "bc_residual": r["bc_residual"],
        "n_nodes": r["n_nodes"],
        "lam": r["lam"],
        "continuation_steps": len(r["path"]),
        "shoot_tip_um": [r["shoot"]["tip_x"] * 1e6, r["shoot"]["tip_y"] * 1e6],
        "shoot_tip_bc_residual": r["shoot"]["tip_bc_residual"],
        "base_force_N": r["base_force"],
        "base_moment_Nm": r["base_moment"],
        "wall_time_s": r["wall_time_s"],
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

"""Stretching, bending and twisting: energies, forces and Hessians (docs/model.md §3).

Formulas: Bergou et al. 2010 (forces) and Jawed, Novelia & O'Reilly, "A primer on the
kinematics of discrete elastic rods" (2018) (curvature and twist Hessians).

The bend-twist stencil of interior node i spans the 11 contiguous DOFs
``q[4(i-1) : 4(i-1)+11] = (x_{i-1}, theta_{i-1}, x_i, theta_i, x_{i+1})``. It is computed in
the reduced coordinates ``r = (e, f, theta_e, theta_f)`` with e = x_i - x_{i-1} and
f = x_{i+1} - x_i, then mapped to the 11 DOFs (``_R_INDEX`` / ``_R_SIGN``).

Energies (rest curvature and twist are zero; ``rest_lengths`` ebar_j on edges,
``voronoi_lengths`` l_i on interior nodes):

* stretch  E_s = 1/2 k_s sum_j (|e_j|/ebar_j - 1)^2 ebar_j
* bend     E_b = 1/2 k_b sum_i (kappa1_i^2 + kappa2_i^2) / l_i
* twist    E_t = 1/2 k_t sum_i twist_i^2 / l_i

``force`` receives -dE/dq (added, not overwritten) and the band ``ab`` receives
+d^2E/dq^2 (added). Frames (d1, d2) must already be those of the current iterate.
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit

from cnt_env.rod.banded import KL, KU

_DIAG = KL + KU  # row of the main diagonal in band storage

# For local DOF a (0..10): the two reduced coordinates it enters, with signs (a sign of
# 0 marks an unused second slot, so the map is branch-free).
# Reduced layout: e = r[0:3], f = r[3:6], theta_e = r[6], theta_f = r[7].
_R_INDEX = np.array(
    [
        [0, 0], [1, 1], [2, 2],  # x_{i-1}: -e
        [6, 6],  # theta_e
        [0, 3], [1, 4], [2, 5],  # x_i: +e, -f
        [7, 7],  # theta_f
        [3, 3], [4, 4], [5, 5],  # x_{i+1}: +f
    ],
    dtype=np.int64,
)  # fmt: skip
_R_SIGN = np.array(
    [
        [-1.0, 0.0], [-1.0, 0.0], [-1.0, 0.0],
        [1.0, 0.0],
        [1.0, -1.0], [1.0, -1.0], [1.0, -1.0],
        [1.0, 0.0],
        [1.0, 0.0], [1.0, 0.0], [1.0, 0.0],
    ]
)  # fmt: skip


@njit(cache=True)
def stretch_energy(q: np.ndarray, n_nodes: int, rest_lengths: np.ndarray, k_s: float) -> float:
    energy = 0.0
    for j in range(n_nodes - 1):
        e0 = q[4 * j + 4] - q[4 * j]
        e1 = q[4 * j + 5] - q[4 * j + 1]
        e2 = q[4 * j + 6] - q[4 * j + 2]
        strain = math.sqrt(e0 * e0 + e1 * e1 + e2 * e2) / rest_lengths[j] - 1.0
        energy += 0.5 * k_s * strain * strain * rest_lengths[j]
    return energy


@njit(cache=True)
def bend_twist_energy(
    kappa: np.ndarray,
    twist: np.ndarray,
    voronoi_lengths: np.ndarray,
    n_nodes: int,
    k_b: float,
    k_t: float,
) -> float:
    energy = 0.0
    for i in range(1, n_nodes - 1):
        energy += 0.5 * k_b * (kappa[i, 0] ** 2 + kappa[i, 1] ** 2) / voronoi_lengths[i]
        energy += 0.5 * k_t * twist[i] ** 2 / voronoi_lengths[i]
    return energy


@njit(cache=True)
def add_stretch(
    q: np.ndarray,
    n_nodes: int,
    rest_lengths: np.ndarray,
    k_s: float,
    force: np.ndarray,
    ab: np.ndarray,
    with_hessian: bool,
) -> None:
    """Stretching force -dE_s/dq and Hessian; per edge, on the DOFs of its two nodes."""
    for j in range(n_nodes - 1):
        a = 4 * j  # first DOF of x_j; x_{j+1} starts at a + 4
        e0 = q[a + 4] - q[a]
        e1 = q[a + 5] - q[a + 1]
        e2 = q[a + 6] - q[a + 2]
        ln = math.sqrt(e0 * e0 + e1 * e1 + e2 * e2)
        t = (e0 / ln, e1 / ln, e2 / ln)
        ebar = rest_lengths[j]
        tension = k_s * (ln / ebar - 1.0)  # dE/d|e|
        for k in range(3):
            force[a + k] += tension * t[k]
            force[a + 4 + k] -= tension * t[k]
        if not with_hessian:
            continue
        # d2E/de2 = k_s/ebar t t^T + tension/|e| (I - t t^T)
        c_par = k_s / ebar
        c_perp = tension / ln
        for k in range(3):
            for m in range(3):
                h = (c_par - c_perp) * t[k] * t[m]
                if k == m:
                    h += c_perp
                ab[_DIAG + k - m, a + m] += h
                ab[_DIAG + k - m, a + 4 + m] += h
                ab[_DIAG + k - m - 4, a + 4 + m] -= h  # row a+k, col a+4+m
                ab[_DIAG + k - m + 4, a + m] -= h  # row a+4+k, col a+m


@njit(cache=True, inline="always")
def _cross(a: tuple, b: tuple) -> tuple:
    return (a[1] * b[2] - a[2] * b[1], a[2] * b[0] - a[0] * b[2], a[0] * b[1] - a[1] * b[0])


@njit(cache=True, inline="always")
def _dot(a: tuple, b: tuple) -> float:
    return a[0] * b[0] + a[1] * b[1] + a[2] * b[2]


@njit(cache=True, inline="always")
def _vec(a: np.ndarray) -> tuple:
    return (a[0], a[1], a[2])


@njit(cache=True, inline="always")
def _d2_same(w: float, inv2: float, kap: float, smid: float, sgn: float, ichi: float,
             tt: tuple, tmp: tuple, t: tuple, kb: tuple, mf: tuple, k: int,
             m: int) -> float:  # fmt: skip
    """cb kappa_c d2kappa_c/dd_k dd_m for d = e or f, without its diagonal term (primer;
    c = 1, 2): with t, inv2, tmp, mf those of e (smid = -sgn) or of f (smid = +sgn)."""
    return (
        w
        * inv2
        * (
            2.0 * kap * (tt[k] * tt[m])
            + smid * (tmp[k] * tt[m] + tt[k] * tmp[m])
            + kap * ichi * t[k] * t[m]
            + 0.25 * sgn * (kb[k] * mf[m] + mf[k] * kb[m])
        )
    )


@njit(cache=True, inline="always")
def _d2_ef(w: float, inef: float, kap: float, sgn: float, ichi: float, tt: tuple, tmp: tuple,
           tmp2: tuple, te: tuple, tf: tuple, k: int, m: int) -> float:  # fmt: skip
    """cb kappa_c d2kappa_c/de_k df_m without its diagonal and cross-product terms."""
    return (
        w
        * inef
        * (
            -kap * ichi * te[k] * tf[m]
            + 2.0 * kap * tt[k] * tt[m]
            - sgn * tmp[k] * tt[m]
            + sgn * tt[k] * tmp2[m]
        )
    )


@njit(cache=True)
def _bend_twist_zz(te: tuple, tf: tuple, tt: tuple, kb: tuple, ichi: float, ine: float,
                   inf_: float, a1: tuple, b1: tuple, a2: tuple, b2: tuple, m1e: tuple,
                   m2e: tuple, m1f: tuple, m2f: tuple, kappa1: float, kappa2: float,
                   twist: float, cb: float, ct: float, h: np.ndarray, gk1: np.ndarray,
                   gk2: np.ndarray, gtw: np.ndarray) -> None:  # fmt: skip
    """h[2, 2], h[2, 5], h[5, 5] of :func:`_bend_twist_reduced`'s Hessian alone: the
    terms of the full Hessian that land on them, in its order (so the same bits). A
    stencil whose only free DOFs are the three nodes' z (a deposited, snapped stretch of
    the stepped substrate's tail) needs no other entry: the rows and columns of fixed DOFs
    are replaced by the identity (banded.band_fix_dof)."""
    for a, b in ((2, 2), (2, 5), (5, 5)):
        h[a, b] = cb * (gk1[a] * gk1[b] + gk2[a] * gk2[b]) + ct * gtw[a] * gtw[b]
    ine2 = ine * ine
    inf2 = inf_ * inf_
    inef = ine * inf_
    for pass_ in range(2):
        if pass_ == 0:
            kap, sgn, mfe, mff, tmp, tmp2 = kappa1, 1.0, m2e, m2f, a1, b1
        else:
            kap, sgn, mfe, mff, tmp, tmp2 = kappa2, -1.0, m1e, m1f, a2, b2
        w = cb * kap
        h[2, 2] += _d2_same(w, ine2, kap, -sgn, sgn, ichi, tt, tmp, te, kb, mfe, 2, 2)
        h[5, 5] += _d2_same(w, inf2, kap, sgn, sgn, ichi, tt, tmp2, tf, kb, mff, 2, 2)
        h[2, 2] -= w * kap * ichi * ine2
        h[5, 5] -= w * kap * ichi * inf2
        h[2, 5] += _d2_ef(w, inef, kap, sgn, ichi, tt, tmp, tmp2, te, tf, 2, 2)
        h[2, 5] -= w * kap * ichi * inef
    w = ct * twist
    u1 = (te[0] + tt[0], te[1] + tt[1], te[2] + tt[2])
    u2 = (tf[0] + tt[0], tf[1] + tt[1], tf[2] + tt[2])
    cc = 0.5 * w * inef
    h[2, 2] -= 0.25 * w * ine2 * (kb[2] * u1[2] + u1[2] * kb[2])
    h[5, 5] -= 0.25 * w * inf2 * (kb[2] * u2[2] + u2[2] * kb[2])
    h[2, 5] -= cc * kb[2] * tt[2]


@njit(cache=True)
def _bend_twist_reduced(
    e: tuple,
    f: tuple,
    m1e: tuple,
    m2e: tuple,
    m1f: tuple,
    m2f: tuple,
    twist: float,
    l_i: float,
    k_b: float,
    k_t: float,
    g: np.ndarray,
    h: np.ndarray,
    gk1: np.ndarray,
    gk2: np.ndarray,
    gtw: np.ndarray,
    with_hessian: bool,
    zz_only: bool = False,
) -> None:
    """Gradient g (8) and Hessian h (8x8) of the bend+twist energy of one interior node
    in the reduced coordinates (e, f, theta_e, theta_f). gk1/gk2/gtw (8) are scratch.
    Only the upper triangle of h is filled (the Hessian is symmetric; the caller mirrors
    it). 3-vectors are tuples so that they live in registers: scratch arrays would alias
    for LLVM and force reloads. ``zz_only``: only h[2, 2], h[2, 5] and h[5, 5] (the z
    components of e and f), by the same operations in the same order as the full
    Hessian, so with the same bits (the others are left as they were).
    """
    ne = math.sqrt(_dot(e, e))
    nf = math.sqrt(_dot(f, f))
    # reciprocals hoisted: without fastmath LLVM keeps every division
    ine = 1.0 / ne
    inf_ = 1.0 / nf
    te = (e[0] * ine, e[1] * ine, e[2] * ine)
    tf = (f[0] * inf_, f[1] * inf_, f[2] * inf_)
    chi = 1.0 + _dot(te, tf)
    ichi = 1.0 / chi
    c = _cross(te, tf)
    kb = (2.0 * ichi * c[0], 2.0 * ichi * c[1], 2.0 * ichi * c[2])
    tt = ((te[0] + tf[0]) * ichi, (te[1] + tf[1]) * ichi, (te[2] + tf[2]) * ichi)
    d1t = ((m1e[0] + m1f[0]) * ichi, (m1e[1] + m1f[1]) * ichi, (m1e[2] + m1f[2]) * ichi)
    d2t = ((m2e[0] + m2f[0]) * ichi, (m2e[1] + m2f[1]) * ichi, (m2e[2] + m2f[2]) * ichi)
    kappa1 = 0.5 * (_dot(kb, m2e) + _dot(kb, m2f))
    kappa2 = -0.5 * (_dot(kb, m1e) + _dot(kb, m1f))

    # --- first derivatives (Bergou 2010 §4.2; primer eqs. for d kappa / d e) ---
    a1 = _cross(tf, d2t)
    b1 = _cross(te, d2t)
    a2 = _cross(tf, d1t)
    b2 = _cross(te, d1t)
    for k in range(3):
        gk1[k] = (-kappa1 * tt[k] + a1[k]) * ine
        gk1[3 + k] = (-kappa1 * tt[k] - b1[k]) * inf_
        gk2[k] = (-kappa2 * tt[k] - a2[k]) * ine
        gk2[3 + k] = (-kappa2 * tt[k] + b2[k]) * inf_
        # d(reference twist)/de = kb / (2|e|), d/df = kb / (2|f|)  (Bergou 2010 eq. 9)
        gtw[k] = 0.5 * kb[k] * ine
        gtw[3 + k] = 0.5 * kb[k] * inf_
    gk1[6] = -0.5 * _dot(kb, m1e)
    gk1[7] = -0.5 * _dot(kb, m1f)
    gk2[6] = -0.5 * _dot(kb, m2e)
    gk2[7] = -0.5 * _dot(kb, m2f)
    gtw[6] = -1.0
    gtw[7] = 1.0

    cb = k_b / l_i
    ct = k_t / l_i
    for a in range(8):
        g[a] = cb * (kappa1 * gk1[a] + kappa2 * gk2[a]) + ct * twist * gtw[a]
    if not with_hessian:
        return
    if zz_only:
        _bend_twist_zz(te, tf, tt, kb, ichi, ine, inf_, a1, b1, a2, b2, m1e, m2e, m1f, m2f,
                       kappa1, kappa2, twist, cb, ct, h, gk1, gk2, gtw)  # fmt: skip
        return
    for a in range(8):
        for b in range(a, 8):
            h[a, b] = cb * (gk1[a] * gk1[b] + gk2[a] * gk2[b]) + ct * gtw[a] * gtw[b]

    # --- cb * kappa * (second derivatives of kappa1 and kappa2) (primer). kappa2's
    # formulas are kappa1's with d2 -> d1 and the sign sgn flipped on the terms odd in
    # the director; the edge-theta terms have one form with om = m1 (kappa1), m2 (kappa2).
    ine2 = ine * ine
    inf2 = inf_ * inf_
    inef = ine * inf_
    h[6, 6] += cb * kappa1 * (-0.5 * _dot(kb, m2e)) + cb * kappa2 * (0.5 * _dot(kb, m1e))
    h[7, 7] += cb * kappa1 * (-0.5 * _dot(kb, m2f)) + cb * kappa2 * (0.5 * _dot(kb, m1f))
    for pass_ in range(2):
        if pass_ == 0:
            kap, sgn, dtl, mfe, mff, ome, omf = kappa1, 1.0, d2t, m2e, m2f, m1e, m1f
            tmp, tmp2 = a1, b1  # tf x tilde_d, te x tilde_d
        else:
            kap, sgn, dtl, mfe, mff, ome, omf = kappa2, -1.0, d1t, m1e, m1f, m2e, m2f
            tmp, tmp2 = a2, b2
        w = cb * kap
        for k in range(3):
            for m in range(k, 3):
                h[k, m] += _d2_same(w, ine2, kap, -sgn, sgn, ichi, tt, tmp, te, kb, mfe, k, m)
                h[3 + k, 3 + m] += _d2_same(w, inf2, kap, sgn, sgn, ichi, tt, tmp2, tf, kb, mff,
                                            k, m)  # fmt: skip
            h[k, k] -= w * kap * ichi * ine2
            h[3 + k, 3 + k] -= w * kap * ichi * inf2
            # D2/DeDf (full off-diagonal block)
            for m in range(3):
                h[k, 3 + m] += _d2_ef(w, inef, kap, sgn, ichi, tt, tmp, tmp2, te, tf, k, m)
            h[k, 3 + k] -= w * kap * ichi * inef
        # - sgn [tilde_d]_x / (|e||f|)
        cc = -w * sgn * inef
        h[0, 4] += -cc * dtl[2]
        h[0, 5] += cc * dtl[1]
        h[1, 3] += cc * dtl[2]
        h[1, 5] += -cc * dtl[0]
        h[2, 3] += -cc * dtl[1]
        h[2, 4] += cc * dtl[0]
        # edge-theta
        for col in range(6, 8):
            om = ome if col == 6 else omf
            p1 = _cross(tf, om)
            p2 = _cross(te, om)
            s_om = 0.5 * _dot(kb, om)
            for k in range(3):
                h[k, col] += w * (s_om * tt[k] - p1[k] * ichi) * ine
                h[3 + k, col] += w * (s_om * tt[k] + p2[k] * ichi) * inf_

    # --- ct * twist * (Hessian of the reference twist) (primer) ---
    w = ct * twist
    u1 = (te[0] + tt[0], te[1] + tt[1], te[2] + tt[2])
    u2 = (tf[0] + tt[0], tf[1] + tt[1], tf[2] + tt[2])
    cc = 0.5 * w * inef
    for k in range(3):
        for m in range(k, 3):
            h[k, m] -= 0.25 * w * ine2 * (kb[k] * u1[m] + u1[k] * kb[m])
            h[3 + k, 3 + m] -= 0.25 * w * inf2 * (kb[k] * u2[m] + u2[k] * kb[m])
        for m in range(3):
            h[k, 3 + m] -= cc * kb[k] * tt[m]
    # + cc (2/chi) [te]_x
    c2 = 2.0 * cc * ichi
    h[0, 4] += -c2 * te[2]
    h[0, 5] += c2 * te[1]
    h[1, 3] += c2 * te[2]
    h[1, 5] += -c2 * te[0]
    h[2, 3] += -c2 * te[1]
    h[2, 4] += c2 * te[0]


@njit(cache=True, inline="always")
def _rotation_gradient(d: tuple, a: tuple) -> tuple:
    """d psi / d edge for the edge vector d whose reference director is transported from
    the unit tangent a: psi is the rotation of that director about t = d/|d| beyond
    instantaneous parallel transport, d psi/d d = -(a x t) / ((1 + a.t) |d|) (zero at
    t = a; FD-checked in tests/test_elastic_fd.py). Zero for antiparallel a and t, where
    the transport is undefined."""
    nd = math.sqrt(_dot(d, d))
    t = (d[0] / nd, d[1] / nd, d[2] / nd)
    den = (1.0 + _dot(a, t)) * nd
    if den <= 1e-12 * nd:
        return (0.0, 0.0, 0.0)
    c = _cross(a, t)
    return (-c[0] / den, -c[1] / den, -c[2] / den)


@njit(cache=True)
def _transport_terms(
    e: tuple, f: tuple, ae: tuple, af: tuple, g: np.ndarray, h: np.ndarray, kx: np.ndarray
) -> None:
    """The Jacobian terms the DER Hessian h leaves out, in reduced coordinates: K (8 x 6,
    columns e and f; the theta columns get none), so that the Jacobian of the computed
    gradient g is h + K (docs/model.md §3, "Exact Jacobian").

    Each edge's reference director is transported from its start-of-step tangent (ae,
    af), so a change of the edge turns the director about its tangent by d psi =
    grad_psi . d(edge) beyond instantaneous transport, which acts as a change of that
    edge's theta: K[:, e] += h[:, theta_e] grad_psi_e^T (likewise f). At the start of
    the step (t = a) that vanishes, but the gradient formula's own derivative under
    instantaneous transport still adds (dE/dtheta_e) [t_e]_x / (2 |e|^2) on the (e, e)
    block (likewise f): the curl of grad_psi, which is why the DER Hessian is only the
    symmetric part of the force Jacobian.
    """
    ge = _rotation_gradient(e, ae)
    gf = _rotation_gradient(f, af)
    for r in range(8):
        for c in range(3):
            kx[r, c] = h[r, 6] * ge[c]
            kx[r, 3 + c] = h[r, 7] * gf[c]
    for blk in range(2):
        d = e if blk == 0 else f
        nd2 = _dot(d, d)
        nd = math.sqrt(nd2)
        s = g[6 + blk] / (2.0 * nd2 * nd)  # [t]_x = [d]_x / |d|
        o = 3 * blk
        kx[o + 0, o + 1] -= s * d[2]
        kx[o + 0, o + 2] += s * d[1]
        kx[o + 1, o + 0] += s * d[2]
        kx[o + 1, o + 2] -= s * d[0]
        kx[o + 2, o + 0] -= s * d[1]
        kx[o + 2, o + 1] += s * d[0]


@njit(cache=True, inline="always")
def _only_z_free(fixed: np.ndarray, a0: int) -> bool:
    """Are all 11 DOFs of the stencil at a0 fixed except the three nodes' z (2, 6, 10)?"""
    if fixed.size == 0:
        return False
    for a in range(11):
        if a % 4 != 2 and not fixed[a0 + a]:
            return False
    return True


@njit(cache=True)
def add_bend_twist(
    q: np.ndarray,
    n_nodes: int,
    m1: np.ndarray,
    m2: np.ndarray,
    twist: np.ndarray,
    voronoi_lengths: np.ndarray,
    k_b: float,
    k_t: float,
    force: np.ndarray,
    ab: np.ndarray,
    with_hessian: bool,
    tangents_old: np.ndarray,
    transport: bool,
    fixed: np.ndarray,
) -> None:
    """Bending and twisting force -dE/dq and Jacobian over all interior nodes.

    With ``transport`` the Jacobian is that of the force as computed, frames
    time-parallel-transported from ``tangents_old`` (:func:`_transport_terms`); without
    it, the symmetric DER Hessian (Bergou 2010; the primer). The force is the same
    either way. ``fixed`` (n_dof, nonzero = fixed) lets a stencil whose only free DOFs
    are its nodes' z skip the Hessian entries that the fixed rows and columns discard
    (:func:`_bend_twist_zz`; the entries that remain have the same bits). Pass zeros to
    assemble every entry (the caller's band_fix_dof must then not be relied on)."""
    g = np.empty(8)
    h = np.zeros((8, 8))
    gk1 = np.empty(8)
    gk2 = np.empty(8)
    gtw = np.empty(8)
    kx = np.zeros((8, 6))
    for i in range(1, n_nodes - 1):
        a0 = 4 * (i - 1)
        e = (q[a0 + 4] - q[a0], q[a0 + 5] - q[a0 + 1], q[a0 + 6] - q[a0 + 2])
        f = (q[a0 + 8] - q[a0 + 4], q[a0 + 9] - q[a0 + 5], q[a0 + 10] - q[a0 + 6])
        zz = with_hessian and not transport and _only_z_free(fixed, a0)
        _bend_twist_reduced(
            e, f, _vec(m1[i - 1]), _vec(m2[i - 1]), _vec(m1[i]), _vec(m2[i]), twist[i],
            voronoi_lengths[i], k_b, k_t, g, h, gk1, gk2, gtw, with_hessian, zz,
        )  # fmt: skip
        for a in range(11):
            force[a0 + a] -= _R_SIGN[a, 0] * g[_R_INDEX[a, 0]] + _R_SIGN[a, 1] * g[_R_INDEX[a, 1]]
        if not with_hessian:
            continue
        if zz:  # the z-z entries of nodes i-1, i, i+1 (local DOFs 2, 6, 10) alone
            h[5, 2] = h[2, 5]
            first, step = 2, 4
        else:
            for a in range(8):  # mirror the upper triangle
                for b in range(a):
                    h[a, b] = h[b, a]
            if transport:
                _transport_terms(e, f, _vec(tangents_old[i - 1]), _vec(tangents_old[i]), g, h,
                                 kx)  # fmt: skip
            first, step = 0, 1
        # H_q = T^T H_r T, each local DOF a = s0 r[i0] + s1 r[i1] (s1 = 0 when single)
        for a in range(first, 11, step):
            ia0 = _R_INDEX[a, 0]
            ia1 = _R_INDEX[a, 1]
            sa0 = _R_SIGN[a, 0]
            sa1 = _R_SIGN[a, 1]
            for b in range(a, 11, step):
                ib0 = _R_INDEX[b, 0]
                ib1 = _R_INDEX[b, 1]
                sb0 = _R_SIGN[b, 0]
                sb1 = _R_SIGN[b, 1]
                hab = (sa0 * (sb0 * h[ia0, ib0] + sb1 * h[ia0, ib1])
                       + sa1 * (sb0 * h[ia1, ib0] + sb1 * h[ia1, ib1]))  # fmt: skip
                if not transport:
                    ab[_DIAG + a - b, a0 + b] += hab
                    if b != a:
                        ab[_DIAG + b - a, a0 + a] += hab
                    continue
                # the transport terms are not symmetric: map K (8 x 6) both ways
                kab = 0.0
                if ib0 < 6:  # column b is a position DOF
                    kab = (sa0 * (sb0 * kx[ia0, ib0] + sb1 * kx[ia0, ib1])
                           + sa1 * (sb0 * kx[ia1, ib0] + sb1 * kx[ia1, ib1]))  # fmt: skip
                ab[_DIAG + a - b, a0 + b] += hab + kab
                if b != a:
                    kba = 0.0
                    if ia0 < 6:
                        kba = (sb0 * (sa0 * kx[ib0, ia0] + sa1 * kx[ib0, ia1])
                               + sb1 * (sa0 * kx[ib1, ia0] + sa1 * kx[ib1, ia1]))  # fmt: skip
                    ab[_DIAG + b - a, a0 + a] += hab + kba

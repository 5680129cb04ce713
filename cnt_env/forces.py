"""External forces with their Jacobians: vdW contact force (paper eq. 1) and rarefied drag
(paper eq. 2).

Both kernels *add* the force to ``force`` and *add* -dF/dq (the contribution to the
residual Jacobian) to the band ``ab``.

Drag (physics.md §4), per unit length on edge j with unit tangent t:

    F_a = mu [sigma t t^T + C_sigma (I - t t^T)] v_r = mu A(t) v_r,
    v_r = v_flow - (u_j + u_{j+1}) / 2,  u = (q - q_n) / dt  (implicit Euler velocity),

with A = C_sigma I + (sigma - C_sigma) t t^T. The edge force ebar_j F_a (ebar = rest length)
is split half to each node. The Jacobian has the velocity part -ebar mu A / (4 dt) per node
pair (physics.md §4) and, because A depends on the tangent, a geometric part
ebar mu (sigma - C_sigma) [(t.v_r) I + t v_r^T] (I - t t^T) / |e| / 2 per node, with
the sign of d t / d x (- for x_j, + for x_{j+1}). Both are included, so Newton stays
quadratic even when the drag dominates (the crossflow benchmark).
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit

from .rod.banded import KL, KU

_DIAG = KL + KU

DRAG_LINEAR = 0  # the small-speed-ratio free-molecular law (default)


@njit(cache=True)
def add_linear_drag(
    q: np.ndarray,
    q_old: np.ndarray,
    dt: float,
    n_nodes: int,
    rest_lengths: np.ndarray,
    drag_on: np.ndarray,
    flow: np.ndarray,
    mu: float,
    sigma: float,
    c_sigma: float,
    force: np.ndarray,
    ab: np.ndarray,
    with_jacobian: bool,
) -> None:
    """Linear anisotropic drag on every edge j with ``drag_on[j]`` (paper eq. 2, linear)."""
    t = np.empty(3)
    vr = np.empty(3)
    fe = np.empty(3)
    geo = np.empty((3, 3))
    for j in range(n_nodes - 1):
        if not drag_on[j]:
            continue
        a = 4 * j
        b = a + 4
        ln = 0.0
        for k in range(3):
            t[k] = q[b + k] - q[a + k]
            ln += t[k] * t[k]
        ln = math.sqrt(ln)
        for k in range(3):
            t[k] /= ln
            vr[k] = flow[k] - 0.5 * (q[a + k] - q_old[a + k] + q[b + k] - q_old[b + k]) / dt
        tv = t[0] * vr[0] + t[1] * vr[1] + t[2] * vr[2]
        coef = rest_lengths[j] * mu
        for k in range(3):
            fe[k] = coef * (c_sigma * vr[k] + (sigma - c_sigma) * tv * t[k])
            force[a + k] += 0.5 * fe[k]
            force[b + k] += 0.5 * fe[k]
        if not with_jacobian:
            continue
        # geometric part: dF_node/dx_{j+1} = G, dF_node/dx_j = -G, where
        # G = coef (sigma - C_sigma) [(t.v_r) I + t v_r^T] (I - t t^T) / (2 |e|)
        g = 0.5 * coef * (sigma - c_sigma) / ln
        for k in range(3):
            for m in range(3):
                s = 0.0
                for p in range(3):
                    left = tv * (1.0 if k == p else 0.0) + t[k] * vr[p]
                    proj = (1.0 if p == m else 0.0) - t[p] * t[m]
                    s += left * proj
                geo[k, m] = g * s
        cv = 0.25 * coef / dt  # velocity part: dF_node/dx_any = -cv A
        for k in range(3):
            for m in range(3):
                amat = (sigma - c_sigma) * t[k] * t[m]
                if k == m:
                    amat += c_sigma
                # residual Jacobian gets -dF/dq; rows a+k and b+k, columns a+m and b+m
                dfa = -cv * amat - geo[k, m]  # dF_node / dx_j
                dfb = -cv * amat + geo[k, m]  # dF_node / dx_{j+1}
                ab[_DIAG + k - m, a + m] -= dfa
                ab[_DIAG + k - m - 4, b + m] -= dfb
                ab[_DIAG + k - m + 4, a + m] -= dfa
                ab[_DIAG + k - m, b + m] -= dfb


@njit(cache=True)
def add_vdw(
    q: np.ndarray,
    node: int,
    coef: float,
    delta: float,
    sqrt_clamp: float,
    force: np.ndarray,
    ab: np.ndarray,
    with_jacobian: bool,
) -> None:
    """vdW pull on the contact node c (paper eq. 1, physics.md §4).

    E_v = coef (beta - beta0) with coef = e_v delta / beta0 and sin(beta) = y_c / delta, so
    F_y = -coef / sqrt(delta^2 - y_c^2). The root is clamped from below at
    ``sqrt_clamp * delta`` (beyond the clamp the force is constant and its derivative 0).
    Integrated from beta0 to 0 it releases exactly e_v delta.
    """
    if node < 0:
        return
    k = 4 * node + 1  # y DOF of node c
    y = q[k]
    root_sq = delta * delta - y * y
    floor = sqrt_clamp * delta
    if root_sq <= floor * floor:
        force[k] -= coef / floor
        return
    root = math.sqrt(root_sq)
    force[k] -= coef / root
    if with_jacobian:
        # residual Jacobian gets -dF_y/dy = coef * y / root^3
        ab[_DIAG, k] += coef * y / (root * root_sq)

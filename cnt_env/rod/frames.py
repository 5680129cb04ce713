"""Frames and strains of the discrete elastic rod (docs/model.md §3; Bergou et al. 2010).

Arrays (see ``cnt_env/rod/__init__.py`` for the shared layout):

=================  ==================  ==========================================
name               shape               lives on
=================  ==================  ==========================================
``q``              (4 n_nodes - 1,)    interleaved DOFs
``tangents``       (n_edges, 3)        edges, unit vectors
``edge_lengths``   (n_edges,)          edges, current |e_j|
``d1``, ``d2``     (n_edges, 3)        edges, reference directors (d2 = t x d1)
``m1``, ``m2``     (n_edges, 3)        edges, material directors
``ref_twist``      (n_nodes,)          interior nodes (0 and n_nodes-1 unused)
``kb``             (n_nodes, 3)        interior nodes, curvature binormal
``kappa``          (n_nodes, 2)        interior nodes, material curvatures
``twist``          (n_nodes,)          interior nodes
=================  ==================  ==========================================
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit

# Below this |t_a x t_b| the transport is the identity (tangents parallel).
PARALLEL_EPS = 1e-15


@njit(cache=True, inline="always")
def dot3(a: np.ndarray, b: np.ndarray) -> float:
    return a[0] * b[0] + a[1] * b[1] + a[2] * b[2]


@njit(cache=True, inline="always")
def cross3(a: np.ndarray, b: np.ndarray, out: np.ndarray) -> None:
    c0 = a[1] * b[2] - a[2] * b[1]
    c1 = a[2] * b[0] - a[0] * b[2]
    c2 = a[0] * b[1] - a[1] * b[0]
    out[0] = c0
    out[1] = c1
    out[2] = c2


@njit(cache=True, inline="always")
def _transport3(
    u0: float, u1: float, u2: float,
    a0: float, a1: float, a2: float,
    t0: float, t1: float, t2: float,
) -> tuple:  # fmt: skip
    """Parallel transport of (u0, u1, u2) from unit tangent a to unit tangent t, on
    scalars: rotation about a x t by the angle between them, in the orthonormal bases
    (a, a x b, b) and (t, t x b, b) with b = (a x t)/|a x t|; the identity when they are
    parallel. The one home of the formula (:func:`parallel_transport`, :func:`update_all`)."""
    b0 = a1 * t2 - a2 * t1
    b1 = a2 * t0 - a0 * t2
    b2 = a0 * t1 - a1 * t0
    nb = math.sqrt(b0 * b0 + b1 * b1 + b2 * b2)
    if nb < PARALLEL_EPS:
        return u0, u1, u2
    b0 /= nb
    b1 /= nb
    b2 /= nb
    na0 = a1 * b2 - a2 * b1
    na1 = a2 * b0 - a0 * b2
    na2 = a0 * b1 - a1 * b0
    nb0 = t1 * b2 - t2 * b1
    nb1 = t2 * b0 - t0 * b2
    nb2 = t0 * b1 - t1 * b0
    ut = u0 * a0 + u1 * a1 + u2 * a2
    un = u0 * na0 + u1 * na1 + u2 * na2
    ub = u0 * b0 + u1 * b1 + u2 * b2
    return (
        ut * t0 + un * nb0 + ub * b0,
        ut * t1 + un * nb1 + ub * b1,
        ut * t2 + un * nb2 + ub * b2,
    )


@njit(cache=True)
def parallel_transport(u: np.ndarray, t_a: np.ndarray, t_b: np.ndarray, out: np.ndarray) -> None:
    """Rotate ``u`` about t_a x t_b by the angle that takes unit t_a to unit t_b.

    Identity when t_a and t_b are parallel. ``out`` may alias ``u``.
    """
    out[0], out[1], out[2] = _transport3(u[0], u[1], u[2], t_a[0], t_a[1], t_a[2],
                                         t_b[0], t_b[1], t_b[2])  # fmt: skip


@njit(cache=True, inline="always")
def _edge_tangent(q: np.ndarray, j: int) -> tuple:
    """Length and unit tangent (ln, t0, t1, t2) of edge j."""
    e0 = q[4 * j + 4] - q[4 * j]
    e1 = q[4 * j + 5] - q[4 * j + 1]
    e2 = q[4 * j + 6] - q[4 * j + 2]
    ln = math.sqrt(e0 * e0 + e1 * e1 + e2 * e2)
    return ln, e0 / ln, e1 / ln, e2 / ln


@njit(cache=True)
def compute_tangents(
    q: np.ndarray, n_nodes: int, tangents: np.ndarray, edge_lengths: np.ndarray
) -> None:
    """Unit tangents and lengths of every edge."""
    for j in range(n_nodes - 1):
        ln, t0, t1, t2 = _edge_tangent(q, j)
        edge_lengths[j] = ln
        tangents[j, 0] = t0
        tangents[j, 1] = t1
        tangents[j, 2] = t2


@njit(cache=True)
def time_parallel_frames(
    tangents_old: np.ndarray,
    d1_old: np.ndarray,
    tangents: np.ndarray,
    n_edges: int,
    d1: np.ndarray,
    d2: np.ndarray,
) -> None:
    """Reference directors by time-parallel transport from the frame frozen at step start.

    Always transports from the *start-of-step* frame (docs/model.md §3), never from the
    previous Newton iterate, then re-orthonormalises.
    """
    for j in range(n_edges):
        parallel_transport(d1_old[j], tangents_old[j], tangents[j], d1[j])
        t = tangents[j]
        c = dot3(d1[j], t)
        d1[j, 0] -= c * t[0]
        d1[j, 1] -= c * t[1]
        d1[j, 2] -= c * t[2]
        n = math.sqrt(dot3(d1[j], d1[j]))
        d1[j, 0] /= n
        d1[j, 1] /= n
        d1[j, 2] /= n
        cross3(t, d1[j], d2[j])


@njit(cache=True)
def reference_twist(
    tangents: np.ndarray,
    d1: np.ndarray,
    ref_twist_old: np.ndarray,
    n_nodes: int,
    ref_twist: np.ndarray,
) -> None:
    """Reference twist at interior nodes, updated incrementally (docs/model.md §3).

    Transport d1_{i-1} onto t_i, rotate it about t_i by the old reference twist, and
    add the signed angle from there to d1_i. Incremental, so no 2 pi jumps.
    """
    u = np.empty(3)
    w = np.empty(3)
    for i in range(1, n_nodes - 1):
        t = tangents[i]
        parallel_transport(d1[i - 1], tangents[i - 1], t, u)
        a = ref_twist_old[i]
        ca = math.cos(a)
        sa = math.sin(a)
        cross3(t, u, w)
        tu = dot3(t, u)
        for k in range(3):
            u[k] = ca * u[k] + sa * w[k] + (1.0 - ca) * tu * t[k]
        cross3(u, d1[i], w)
        ref_twist[i] = a + math.atan2(dot3(w, t), dot3(u, d1[i]))


@njit(cache=True)
def material_frames(
    q: np.ndarray, d1: np.ndarray, d2: np.ndarray, n_edges: int, m1: np.ndarray, m2: np.ndarray
) -> None:
    """m1 = cos(theta) d1 + sin(theta) d2, m2 = -sin(theta) d1 + cos(theta) d2."""
    for j in range(n_edges):
        c = math.cos(q[4 * j + 3])
        s = math.sin(q[4 * j + 3])
        for k in range(3):
            m1[j, k] = c * d1[j, k] + s * d2[j, k]
            m2[j, k] = -s * d1[j, k] + c * d2[j, k]


@njit(cache=True)
def curvature_binormal(tangents: np.ndarray, n_nodes: int, kb: np.ndarray) -> None:
    """kb_i = 2 t_{i-1} x t_i / (1 + t_{i-1} . t_i) (Bergou 2010 eq. 1)."""
    w = np.empty(3)
    for i in range(1, n_nodes - 1):
        cross3(tangents[i - 1], tangents[i], w)
        f = 2.0 / (1.0 + dot3(tangents[i - 1], tangents[i]))
        kb[i, 0] = f * w[0]
        kb[i, 1] = f * w[1]
        kb[i, 2] = f * w[2]


@njit(cache=True)
def strains(
    q: np.ndarray,
    kb: np.ndarray,
    m1: np.ndarray,
    m2: np.ndarray,
    ref_twist: np.ndarray,
    n_nodes: int,
    kappa: np.ndarray,
    twist: np.ndarray,
) -> None:
    """kappa1 = kb.(m2_e + m2_f)/2, kappa2 = -kb.(m1_e + m1_f)/2, twist = dtheta + ref twist."""
    for i in range(1, n_nodes - 1):
        k1 = 0.0
        k2 = 0.0
        for k in range(3):
            k1 += kb[i, k] * (m2[i - 1, k] + m2[i, k])
            k2 -= kb[i, k] * (m1[i - 1, k] + m1[i, k])
        kappa[i, 0] = 0.5 * k1
        kappa[i, 1] = 0.5 * k2
        twist[i] = q[4 * i + 3] - q[4 * i - 1] + ref_twist[i]


@njit(cache=True)
def initial_reference_frame(tangents: np.ndarray, n_edges: int, d1: np.ndarray) -> None:
    """A space-parallel reference frame for a new rod: d1_0 any unit normal, then
    parallel-transported edge to edge (zero reference twist by construction)."""
    t0 = tangents[0]
    # the coordinate axis least aligned with t0, projected
    ax = 0
    if abs(t0[1]) < abs(t0[ax]):
        ax = 1
    if abs(t0[2]) < abs(t0[ax]):
        ax = 2
    for k in range(3):
        d1[0, k] = -t0[ax] * t0[k]
    d1[0, ax] += 1.0
    n = math.sqrt(dot3(d1[0], d1[0]))
    for k in range(3):
        d1[0, k] /= n
    for j in range(1, n_edges):
        parallel_transport(d1[j - 1], tangents[j - 1], tangents[j], d1[j])
        c = dot3(d1[j], tangents[j])
        for k in range(3):
            d1[j, k] -= c * tangents[j, k]
        n = math.sqrt(dot3(d1[j], d1[j]))
        for k in range(3):
            d1[j, k] /= n


@njit(cache=True)
def update_all(
    q: np.ndarray,
    n_nodes: int,
    tangents_old: np.ndarray,
    d1_old: np.ndarray,
    ref_twist_old: np.ndarray,
    tangents: np.ndarray,
    lengths: np.ndarray,
    d1: np.ndarray,
    d2: np.ndarray,
    ref_twist: np.ndarray,
    m1: np.ndarray,
    m2: np.ndarray,
    kb: np.ndarray,
    kappa: np.ndarray,
    twist: np.ndarray,
) -> None:
    """Every frame and strain of iterate q in one pass over the edges: the results of
    :func:`compute_tangents`, :func:`time_parallel_frames`, :func:`reference_twist`,
    :func:`material_frames`, :func:`curvature_binormal` and :func:`strains` called in
    turn, by the same operations in the same order (so the same bits:
    tests/test_frames.py), with edge j-1's vectors kept in registers."""
    # edge j-1's tangent, reference director d1 and material directors
    pt0 = pt1 = pt2 = 0.0
    pd0 = pd1 = pd2 = 0.0
    pm10 = pm11 = pm12 = 0.0
    pm20 = pm21 = pm22 = 0.0
    for j in range(n_nodes - 1):
        # tangent and length (compute_tangents)
        ln, t0, t1, t2 = _edge_tangent(q, j)
        lengths[j] = ln
        tangents[j, 0] = t0
        tangents[j, 1] = t1
        tangents[j, 2] = t2
        # reference director transported in time, re-orthonormalised (time_parallel_frames)
        d0, d1_, d2_ = _transport3(d1_old[j, 0], d1_old[j, 1], d1_old[j, 2],
                                   tangents_old[j, 0], tangents_old[j, 1],
                                   tangents_old[j, 2], t0, t1, t2)  # fmt: skip
        c = d0 * t0 + d1_ * t1 + d2_ * t2
        d0 -= c * t0
        d1_ -= c * t1
        d2_ -= c * t2
        nn = math.sqrt(d0 * d0 + d1_ * d1_ + d2_ * d2_)
        d0 /= nn
        d1_ /= nn
        d2_ /= nn
        d1[j, 0] = d0
        d1[j, 1] = d1_
        d1[j, 2] = d2_
        s0 = t1 * d2_ - t2 * d1_
        s1 = t2 * d0 - t0 * d2_
        s2 = t0 * d1_ - t1 * d0
        d2[j, 0] = s0
        d2[j, 1] = s1
        d2[j, 2] = s2
        # material frame (material_frames)
        ct = math.cos(q[4 * j + 3])
        st = math.sin(q[4 * j + 3])
        m10 = ct * d0 + st * s0
        m11 = ct * d1_ + st * s1
        m12 = ct * d2_ + st * s2
        m20 = -st * d0 + ct * s0
        m21 = -st * d1_ + ct * s1
        m22 = -st * d2_ + ct * s2
        m1[j, 0] = m10
        m1[j, 1] = m11
        m1[j, 2] = m12
        m2[j, 0] = m20
        m2[j, 1] = m21
        m2[j, 2] = m22
        if j >= 1:
            i = j  # the interior node between edges j-1 and j
            # reference twist (reference_twist)
            u0, u1, u2 = _transport3(pd0, pd1, pd2, pt0, pt1, pt2, t0, t1, t2)
            a = ref_twist_old[i]
            ca = math.cos(a)
            sa = math.sin(a)
            w0 = t1 * u2 - t2 * u1
            w1 = t2 * u0 - t0 * u2
            w2 = t0 * u1 - t1 * u0
            tu = t0 * u0 + t1 * u1 + t2 * u2
            u0 = ca * u0 + sa * w0 + (1.0 - ca) * tu * t0
            u1 = ca * u1 + sa * w1 + (1.0 - ca) * tu * t1
            u2 = ca * u2 + sa * w2 + (1.0 - ca) * tu * t2
            w0 = u1 * d2_ - u2 * d1_
            w1 = u2 * d0 - u0 * d2_
            w2 = u0 * d1_ - u1 * d0
            rt = a + math.atan2(w0 * t0 + w1 * t1 + w2 * t2, u0 * d0 + u1 * d1_ + u2 * d2_)
            ref_twist[i] = rt
            # curvature binormal (curvature_binormal)
            c0 = pt1 * t2 - pt2 * t1
            c1 = pt2 * t0 - pt0 * t2
            c2 = pt0 * t1 - pt1 * t0
            f = 2.0 / (1.0 + (pt0 * t0 + pt1 * t1 + pt2 * t2))
            k0 = f * c0
            k1_ = f * c1
            k2_ = f * c2
            kb[i, 0] = k0
            kb[i, 1] = k1_
            kb[i, 2] = k2_
            # strains (strains)
            a1 = 0.0
            a2 = 0.0
            a1 += k0 * (pm20 + m20)
            a2 -= k0 * (pm10 + m10)
            a1 += k1_ * (pm21 + m21)
            a2 -= k1_ * (pm11 + m11)
            a1 += k2_ * (pm22 + m22)
            a2 -= k2_ * (pm12 + m12)
            kappa[i, 0] = 0.5 * a1
            kappa[i, 1] = 0.5 * a2
            twist[i] = q[4 * i + 3] - q[4 * i - 1] + rt
        pt0, pt1, pt2 = t0, t1, t2
        pd0, pd1, pd2 = d0, d1_, d2_
        pm10, pm11, pm12 = m10, m11, m12
        pm20, pm21, pm22 = m20, m21, m22

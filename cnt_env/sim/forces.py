"""External forces with their Jacobians: vdW contact force (paper eq. 1, or the cohesive
adhesion of finite range) and rarefied drag (paper eq. 2).

Both kernels *add* the force to ``force`` and *add* -dF/dq (the contribution to the
residual Jacobian) to the band ``ab``.

Drag (docs/model.md §4), per unit length on edge j with unit tangent t:

    F_a = mu [sigma t t^T + C_sigma (I - t t^T)] v_r = mu A(t) v_r,
    v_r = v_flow - (u_j + u_{j+1}) / 2,  u = (q - q_n) / dt  (implicit Euler velocity),

with A = C_sigma I + (sigma - C_sigma) t t^T; v_flow is uniform, or scaled by the height
of the edge's midpoint in a linear boundary layer (``shear``, DragParams.shear, with its
column in the Jacobian). The edge force ebar_j F_a (ebar = rest length) is split half to
each node. The Jacobian has the velocity part -ebar mu A / (4 dt) per node
pair (docs/model.md §4) and, because A depends on the tangent, a geometric part
ebar mu (sigma - C_sigma) [(t.v_r) I + t v_r^T] (I - t t^T) / |e| / 2 per node, with
the sign of d t / d x (- for x_j, + for x_{j+1}). Both are included, so Newton stays
quadratic even when the drag dominates (the crossflow benchmark).
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit

from cnt_env.rod.banded import KL, KU

_DIAG = KL + KU

DRAG_LINEAR = 0  # the small-speed-ratio free-molecular law (default)
DRAG_PRINTED = 1  # the paper's printed eq. 2, with the extra cos/sin(alpha) factors
DRAG_LAWS = {"linear": DRAG_LINEAR, "printed": DRAG_PRINTED}
# |v_r| is regularised as sqrt(|v_r|^2 + eps^2) in the printed law (smooth at v_r = 0)
PRINTED_EPS = 1e-12


@njit(cache=True, inline="always")
def _edge_velocity_state(
    q: np.ndarray,
    q_old: np.ndarray,
    dt: float,
    flow: np.ndarray,
    shear: float,
    j: int,
    t: np.ndarray,
    vr: np.ndarray,
) -> float:
    """Unit tangent t of edge j and the relative velocity v_r = v_flow s(y) - (u_j +
    u_{j+1})/2 at its midpoint (implicit-Euler velocities); returns |e_j|. The flow's
    profile s(y) is 1 (uniform, ``shear`` 0) or ``shear`` max(y, 0) (a linear boundary
    layer, :func:`_shear_slope`), y the edge midpoint's height."""
    a = 4 * j
    b = a + 4
    ln = 0.0
    for k in range(3):
        t[k] = q[b + k] - q[a + k]
        ln += t[k] * t[k]
    ln = math.sqrt(ln)
    scale = 1.0
    if shear > 0.0:
        scale = shear * max(0.5 * (q[a + 1] + q[b + 1]), 0.0)
    for k in range(3):
        t[k] /= ln
        vr[k] = flow[k] * scale - 0.5 * (q[a + k] - q_old[a + k] + q[b + k] - q_old[b + k]) / dt
    return ln


@njit(cache=True, inline="always")
def _shear_slope(q: np.ndarray, a: int, b: int, shear: float) -> float:
    """d s / d y_node of the flow's profile at the edge of nodes a.., b.. (DOF offsets):
    each node's height moves the midpoint by half; 0 for a uniform flow or a midpoint
    below the substrate (where s is clamped at 0)."""
    if shear > 0.0 and q[a + 1] + q[b + 1] > 0.0:
        return 0.5 * shear
    return 0.0


@njit(cache=True, inline="always")
def _add_shear_columns(ab: np.ndarray, a: int, b: int, dfdy: np.ndarray) -> None:
    """J -= dF_node/dy for the drag's dependence on the edge's height through the flow's
    profile: ``dfdy[k]`` = dF_node_k / dy_a = dF_node_k / dy_b, the same on both nodes'
    rows (a + k, b + k) and both height columns (a + 1, b + 1)."""
    for k in range(3):
        ab[_DIAG + k - 1, a + 1] -= dfdy[k]
        ab[_DIAG + k + 3, a + 1] -= dfdy[k]
        ab[_DIAG + k - 5, b + 1] -= dfdy[k]
        ab[_DIAG + k - 1, b + 1] -= dfdy[k]


@njit(cache=True, inline="always")
def _z_only_edge(fixed: np.ndarray, a: int, b: int) -> bool:
    """Are both nodes of the edge (DOFs a.., b..) fixed in x and y (only z free)? Then
    the edge's Jacobian block matters on its z rows and columns alone: band_fix_dof
    zeroes the others."""
    return fixed.size > 0 and bool(fixed[a] and fixed[a + 1] and fixed[b] and fixed[b + 1])


@njit(cache=True)
def add_linear_drag(
    q: np.ndarray,
    q_old: np.ndarray,
    dt: float,
    n_nodes: int,
    rest_lengths: np.ndarray,
    drag_on: np.ndarray,
    flow: np.ndarray,
    shear: float,
    mu: float,
    sigma: float,
    c_sigma: float,
    force: np.ndarray,
    ab: np.ndarray,
    with_jacobian: bool,
    fixed: np.ndarray,
) -> None:
    """Linear anisotropic drag on every edge j with ``drag_on[j]`` (paper eq. 2, linear).

    ``fixed`` (n_dof; empty: none): an edge whose nodes are fixed in x and y gets only its
    z-z Jacobian entries (the others are discarded with the fixed rows and columns;
    the same bits, :func:`_z_only_edge`). ``shear``: the flow's profile
    (:func:`_edge_velocity_state`)."""
    t = np.empty(3)
    vr = np.empty(3)
    fe = np.empty(3)
    geo = np.empty((3, 3))
    dfdy = np.empty(3)
    for j in range(n_nodes - 1):
        if not drag_on[j]:
            continue
        a = 4 * j
        b = a + 4
        ln = _edge_velocity_state(q, q_old, dt, flow, shear, j, t, vr)
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
        lo = 2 if _z_only_edge(fixed, a, b) else 0  # z-z alone, or the whole block
        for k in range(lo, 3):
            for m in range(lo, 3):
                s = 0.0
                for p in range(3):
                    left = tv * (1.0 if k == p else 0.0) + t[k] * vr[p]
                    proj = (1.0 if p == m else 0.0) - t[p] * t[m]
                    s += left * proj
                geo[k, m] = g * s
        cv = 0.25 * coef / dt  # velocity part: dF_node/dx_any = -cv A
        for k in range(lo, 3):
            for m in range(lo, 3):
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
        slope = _shear_slope(q, a, b, shear)
        if slope > 0.0 and lo == 0:  # dF_node/dy = coef A v_flow ds/dy / 2
            tf = t[0] * flow[0] + t[1] * flow[1] + t[2] * flow[2]
            for k in range(3):
                dfdy[k] = 0.5 * coef * slope * (c_sigma * flow[k] + (sigma - c_sigma) * tf * t[k])
            _add_shear_columns(ab, a, b, dfdy)


@njit(cache=True)
def add_substrate(
    q: np.ndarray,
    q_old: np.ndarray,
    dt: float,
    n_dof: int,
    friction: np.ndarray,
    stiffness: np.ndarray,
    anchor: np.ndarray,
    force: np.ndarray,
    ab: np.ndarray,
    jacobian: bool,
) -> None:
    """Per-DOF substrate terms on deposited nodes (docs/model.md §5, [choice]; substrate.py):

    * friction: F_k = -friction_k (q_k - q_old_k) / dt, a viscous resistance to sliding
      (friction_k = eta * Voronoi length, eta per unit length in units of mu);
    * penalty: F_k = -stiffness_k (q_k - anchor_k), a stiff spring that enforces a snap
      inside the implicit solve instead of a position jump.

    Both are diagonal: the residual Jacobian gets friction_k / dt + stiffness_k on DOF k.
    Zero coefficients add exactly nothing; ``jacobian`` False leaves ``ab`` untouched.
    """
    for k in range(n_dof):
        c = friction[k]
        s = stiffness[k]
        if c == 0.0 and s == 0.0:
            continue
        force[k] -= c * (q[k] - q_old[k]) / dt + s * (q[k] - anchor[k])
        if jacobian:
            ab[_DIAG, k] += c / dt + s


# layout of the vdW parameter vector the stepper carries (Rod.vdw)
VDW_NODE, VDW_BETA0, VDW_DELTA, VDW_CLAMP, VDW_ENERGY, VDW_MODEL, VDW_RANGE = range(7)
# adhesion models (VDW_MODEL; deposition.ContactOptions.adhesion, docs/model.md §4)
ADHESION_EQ1 = 0  # paper eq. 1: a pull on the contact node alone (default)
ADHESION_COHESIVE = 1  # a finite-range pull on every free node near the substrate
ADHESION_MODELS = {"eq1": ADHESION_EQ1, "cohesive": ADHESION_COHESIVE}


@njit(cache=True)
def vdw_pull(y: float, beta0: float, delta: float, clamp: float, e_v: float) -> tuple[float, float]:
    """Vertical vdW force F_y on the contact node at height y, and dF_y/dy (paper eq. 1).

    beta is the contact edge's angle, sin(beta) = y / delta, and
    E_v = (e_v delta / beta0)(beta - beta0): the edge releases e_v delta as beta goes from
    beta0 (its angle when node c-1 touched down) to 0, with the constant torque
    e_v delta / beta0, so F_y = -(e_v delta / beta0) / sqrt(delta^2 - y^2).
    sqrt(delta^2 - y^2) is clamped from below at ``clamp * delta`` (there dF/dy = 0).

    (Two other profiles were tried and dropped, see benchmarks/RESULTS.md: a quadratic
    E_v ~ beta^2 stalls, since its pull vanishes as beta -> 0 while the rod above still
    resists; a constant continuum moment sqrt(2 k_b e_v) releases 1.1-1.5 e_v per length.)
    """
    c = e_v * delta / beta0
    root_sq = delta * delta - y * y
    floor = clamp * delta
    if root_sq <= floor * floor:
        return -c / floor, 0.0
    root = math.sqrt(root_sq)
    return -c / root, -c * y / (root * root_sq)


@njit(cache=True)
def add_vdw(q: np.ndarray, vdw: np.ndarray, force: np.ndarray, ab: np.ndarray) -> None:
    """Add the vdW pull on the contact node c (``vdw`` laid out as VDW_*) and its
    contribution -dF_y/dy to the residual Jacobian."""
    node = int(vdw[VDW_NODE])
    if node < 0:
        return
    k = 4 * node + 1  # y DOF of node c
    f, dfdy = vdw_pull(q[k], vdw[VDW_BETA0], vdw[VDW_DELTA], vdw[VDW_CLAMP], vdw[VDW_ENERGY])
    force[k] += f
    ab[_DIAG, k] -= dfdy


@njit(cache=True)
def cohesive_pull(y: float, weight: float, h: float, e_v: float) -> tuple[float, float]:
    """Vertical adhesive force F_y on a free node at height y that stands for ``weight``
    of rod length, and dF_y/dy (the cohesive adhesion model, docs/model.md §4).

    E = -e_v weight phi(y / h) with phi(u) = (1 - u)^2 on [0, 1] and 0 above: the node
    releases exactly e_v weight on its way from y = h down to y = 0, and the pull
    F_y = -(2 e_v weight / h)(1 - y / h) rises from 0 at the edge of the range, so a
    node enters the pull continuously. Below y = 0 (an overshoot before the node is
    deposited) the pull keeps its contact value, phi = 1 - 2u."""
    if y >= h:
        return 0.0, 0.0
    c = 2.0 * e_v * weight / h
    if y <= 0.0:
        return -c, 0.0
    return -c * (1.0 - y / h), c / h


@njit(cache=True)
def cohesive_energy(y: float, weight: float, h: float, e_v: float) -> float:
    """The energy E of :func:`cohesive_pull` (F_y = -dE/dy)."""
    if y >= h:
        return 0.0
    u = y / h
    if u <= 0.0:
        return -e_v * weight * (1.0 - 2.0 * u)
    return -e_v * weight * (1.0 - u) * (1.0 - u)


@njit(cache=True)
def add_cohesive(q: np.ndarray, n_nodes: int, voronoi_lengths: np.ndarray, vdw: np.ndarray,
                 force: np.ndarray, ab: np.ndarray, with_jacobian: bool) -> None:  # fmt: skip
    """Add the cohesive pull (:func:`cohesive_pull`, range ``vdw[VDW_RANGE]``) on every
    free node from the contact node c = ``vdw[VDW_NODE]`` to the top, each weighted by
    its Voronoi length (Rod.voronoi_lengths: half of each rest edge beside it), and
    -dF_y/dy to the residual Jacobian. Nodes above the range feel nothing, so the pull hands over
    from one node to the next continuously as the rod rolls onto the substrate."""
    first = int(vdw[VDW_NODE])
    if first < 0:
        return
    h = vdw[VDW_RANGE]
    e_v = vdw[VDW_ENERGY]
    for i in range(first, n_nodes):
        k = 4 * i + 1
        if q[k] >= h:
            continue
        f, dfdy = cohesive_pull(q[k], voronoi_lengths[i], h, e_v)
        force[k] += f
        if with_jacobian:
            ab[_DIAG, k] -= dfdy


@njit(cache=True)
def adhesion_energy(q: np.ndarray, n_nodes: int, voronoi_lengths: np.ndarray,
                    vdw: np.ndarray) -> float:  # fmt: skip
    """The cohesive model's energy summed over the nodes :func:`add_cohesive` pulls."""
    first = int(vdw[VDW_NODE])
    if first < 0:
        return 0.0
    total = 0.0
    for i in range(first, n_nodes):
        y = q[4 * i + 1]
        if y < vdw[VDW_RANGE]:
            total += cohesive_energy(y, voronoi_lengths[i], vdw[VDW_RANGE], vdw[VDW_ENERGY])
    return total


@njit(cache=True)
def add_adhesion(q: np.ndarray, n_nodes: int, voronoi_lengths: np.ndarray, vdw: np.ndarray,
                 force: np.ndarray, ab: np.ndarray, with_jacobian: bool) -> None:  # fmt: skip
    """The vdW adhesion of the model ``vdw[VDW_MODEL]``: paper eq. 1 (:func:`add_vdw`)
    or the cohesive pull (:func:`add_cohesive`)."""
    if int(vdw[VDW_MODEL]) == ADHESION_COHESIVE:
        add_cohesive(q, n_nodes, voronoi_lengths, vdw, force, ab, with_jacobian)
        return
    node = int(vdw[VDW_NODE])
    if node < 0:
        return
    if with_jacobian:
        add_vdw(q, vdw, force, ab)
        return
    k = 4 * node + 1  # add_vdw without its Jacobian entry
    f, _ = vdw_pull(q[k], vdw[VDW_BETA0], vdw[VDW_DELTA], vdw[VDW_CLAMP], vdw[VDW_ENERGY])
    force[k] += f


@njit(cache=True)
def add_printed_drag(
    q: np.ndarray,
    q_old: np.ndarray,
    dt: float,
    n_nodes: int,
    rest_lengths: np.ndarray,
    drag_on: np.ndarray,
    flow: np.ndarray,
    shear: float,
    mu: float,
    sigma: float,
    c_sigma: float,
    force: np.ndarray,
    ab: np.ndarray,
    with_jacobian: bool,
    fixed: np.ndarray,
) -> None:
    """Drag with the paper's printed angle factors (docs/model.md §4, [choice]):

        F_a = mu [sigma cos(alpha) (v_r.t) t + C_sigma sin(alpha) (v_r - (v_r.t) t)],

    alpha the angle between v_r and the edge (cos alpha = |v_r.t|/|v_r|). It equals the
    linear law for purely axial or purely normal motion and is weaker in between. The
    Jacobian is exact: the velocity part and the geometric part (the tangent's dependence
    on q, which dominates the velocity part when |v_r| dt >> |e|, as in a strong flow).
    ``fixed`` and ``shear``: as for :func:`add_linear_drag`.
    """
    t = np.empty(3)
    vr = np.empty(3)
    b = np.empty(3)
    jac = np.empty((3, 3))
    dft = np.empty((3, 3))
    dfdy = np.empty(3)
    for j in range(n_nodes - 1):
        if not drag_on[j]:
            continue
        a = 4 * j
        c = a + 4
        ln = _edge_velocity_state(q, q_old, dt, flow, shear, j, t, vr)
        ax = t[0] * vr[0] + t[1] * vr[1] + t[2] * vr[2]
        nb2 = 0.0
        for k in range(3):
            b[k] = vr[k] - ax * t[k]
            nb2 += b[k] * b[k]
        nv = math.sqrt(ax * ax + nb2 + PRINTED_EPS * PRINTED_EPS)
        nb = math.sqrt(nb2 + PRINTED_EPS * PRINTED_EPS)
        coef = rest_lengths[j] * mu
        for k in range(3):
            fk = coef * (sigma * abs(ax) * ax * t[k] + c_sigma * nb * b[k]) / nv
            force[a + k] += 0.5 * fk
            force[c + k] += 0.5 * fk
        if not with_jacobian:
            continue
        # dF/dv_r: axial g = sigma a|a|/|v| t, normal h = C |b| b / |v|
        lo = 2 if _z_only_edge(fixed, a, c) else 0  # z-z alone, or the whole block
        for k in range(lo, 3):
            for m in range(lo, 3):
                pkm = (1.0 if k == m else 0.0) - t[k] * t[m]
                dg = sigma * t[k] * (2.0 * abs(ax) * t[m] / nv - ax * abs(ax) * vr[m] / nv**3)
                dh = c_sigma * ((b[k] * b[m] / nb + nb * pkm) / nv - nb * b[k] * vr[m] / nv**3)
                jac[k, m] = coef * (dg + dh)
        # geometric part, v_r fixed: dF/dt = coef/|v| [sigma (2|a| t v_r^T + a|a| I)
        #   - C (a b b^T/|b| + |b| (t v_r^T + a I))]  (db/dt = -(t v_r^T + a I),
        # d|b|/dt = -a b^T/|b| as b.t = 0), and dt/de = (I - t t^T)/|e|; half the edge
        # force per node, so dF_node/dx_{j+1} = G = dF/dt (I - t t^T)/(2|e|) = -dF_node/dx_j
        an = abs(ax)
        for k in range(3):
            for p in range(3):
                eye = 1.0 if k == p else 0.0
                tv = t[k] * vr[p] + ax * eye
                dft[k, p] = coef * (sigma * (2.0 * an * t[k] * vr[p] + an * ax * eye)
                                    - c_sigma * (ax * b[k] * b[p] / nb + nb * tv)) / nv  # fmt: skip
        cv = 0.25 / dt  # dv_r/dx = -1/(2 dt) per node, half the edge force per node
        g = 0.5 / ln
        for k in range(lo, 3):
            for m in range(lo, 3):
                geo = 0.0
                for p in range(3):
                    geo += dft[k, p] * ((1.0 if p == m else 0.0) - t[p] * t[m])
                geo *= g
                d = cv * jac[k, m]  # velocity part of -dF_node/dx, the same for both nodes
                # the residual Jacobian gets -dF_node/dx: +geo on node j's columns, -geo on j+1's
                ab[_DIAG + k - m, a + m] += d + geo
                ab[_DIAG + k - m - 4, c + m] += d - geo
                ab[_DIAG + k - m + 4, a + m] += d + geo
                ab[_DIAG + k - m, c + m] += d - geo
        slope = _shear_slope(q, a, c, shear)
        if slope > 0.0 and lo == 0:  # dF_node/dy = (dF/dv_r) v_flow ds/dy / 2
            for k in range(3):
                dfdy[k] = 0.5 * slope * (jac[k, 0] * flow[0] + jac[k, 1] * flow[1]
                                         + jac[k, 2] * flow[2])  # fmt: skip
            _add_shear_columns(ab, a, c, dfdy)

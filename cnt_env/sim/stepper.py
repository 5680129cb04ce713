"""Implicit-Euler Newton stepper for the discrete elastic rod (docs/model.md §3).

Residual (per DOF), with u = (q - q_n)/dt:

    f(q) = M ((q - q_n)/dt - u_n)/dt - F_elastic(q) - F_ext(q, u)
    J    = M/dt^2 + Hess E - dF_ext/dq          (dF/dq = (dF/du)/dt for drag)

J is assembled straight into LAPACK band storage and solved with the pivoted banded LU
of ``banded.py``. Fixed DOFs get a zero update: the solve runs on the free DOFs' band
alone (:func:`gather_free`; the same bits as identity rows in the full band). A step converges when
the free-DOF residual is below ``residual_tol * force_scale`` (force units; e_v in the
dimensionless model) or the update is below ``update_tol * length_scale``. A failed step
is rewound and retried as two half steps, recursively, down to ``max_halvings``; past
that :class:`SimulationError` is raised with the state. Nothing returns NaN silently.

:class:`Rod` owns every buffer (capacity ``max_nodes``; ``n_nodes`` of them in use):

======================  ==================  ==========================================
buffer                  shape               lives on
======================  ==================  ==========================================
``q``, ``u``            (4 max_nodes,)      DOFs: positions and theta; their velocities
``mass``                (4 max_nodes,)      DOFs: lumped node mass, theta inertia
``fixed``               (4 max_nodes,)      DOFs: 1 = prescribed (not solved for)
``ext_force``           (4 max_nodes,)      DOFs: constant external load
``sub_friction``        (4 max_nodes,)      DOFs: substrate friction coefficient
``sub_stiffness``,      (4 max_nodes,)      DOFs: substrate penalty spring to
``sub_anchor``                              ``sub_anchor`` (forces.add_substrate)
``rest_lengths``        (max_nodes - 1,)    edges
``drag_on``             (max_nodes - 1,)    edges: 1 = drag acts
``tangents_old``, ...   (max_nodes - 1, 3)  edges: frame frozen at step start
``ref_twist_old``       (max_nodes,)        interior nodes
``voronoi_lengths``     (max_nodes,)        interior nodes (ends hold half an edge)
======================  ==================  ==========================================
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from numba import njit

from cnt_env import numerics
from cnt_env.rod import elastic, frames
from cnt_env.rod.banded import (
    KL,
    KU,
    LDAB,
    band_alloc,
    band_fix_dof,
    band_lu_factor,
    band_lu_solve,
    band_zero,
)
from cnt_env.sim.forces import (
    DRAG_LAWS,
    DRAG_LINEAR,
    add_adhesion,
    add_linear_drag,
    add_printed_drag,
    add_substrate,
)

_DIAG = KL + KU
# assemble's handling of the soft (bend-twist and drag) Jacobian blocks
SOFT_FRESH, SOFT_KEEP, SOFT_REUSE = 0, 1, 2

# status codes of newton_solve
CONVERGED = 0
MAX_ITERATIONS = 1
SINGULAR = 2
NON_FINITE = 3
ROTATED = 4
STATUS_TEXT = {
    CONVERGED: "converged",
    MAX_ITERATIONS: "Newton did not converge within max_iter",
    SINGULAR: "singular Jacobian (zero pivot in banded LU)",
    NON_FINITE: "non-finite residual or update",
    ROTATED: "an edge rotated more than NewtonOptions.max_edge_rotation in one step",
}


class SimulationError(RuntimeError):
    """A step failed even after halving dt ``max_halvings`` times.

    Carries ``step`` (steps taken), ``time`` (simulated time reached), ``dt`` (the last
    attempted step), ``reason`` and ``state`` (a copy of q and u at the last good step).
    """

    def __init__(self, reason: str, step: int, time: float, dt: float, state: dict):
        super().__init__(
            f"simulation failed at step {step}, t = {time:.6g}, dt = {dt:.3g}: {reason}. "
            "The state at the last converged step is in .state; try a smaller dt, a finer "
            "discretisation, or check the parameters for unphysical values."
        )
        self.reason = reason
        self.step = step
        self.time = time
        self.dt = dt
        self.state = state


@dataclass(frozen=True)
class RodMaterial:
    """Stiffnesses and inertia, in the caller's unit system (dimensionless in cnt_env)."""

    k_s: float  # stretching stiffness [force]
    k_b: float  # bending stiffness [force length^2]
    k_t: float  # twisting stiffness [force length^2]
    rho: float  # mass per length
    r0: float  # tube radius: theta inertia rho * length * r0^2 / 2 (keeps J regular)

    def __post_init__(self) -> None:
        for name in ("k_s", "k_b", "k_t", "rho", "r0"):
            v = getattr(self, name)
            if not (math.isfinite(v) and v > 0):
                raise ValueError(f"RodMaterial.{name} must be finite and > 0, got {v!r}")


@dataclass(frozen=True)
class DragParams:
    """Rarefied drag (paper eq. 2): axial sigma*mu, normal c_sigma*mu; ``law`` is
    ``"linear"`` (default) or ``"printed"`` (forces.add_printed_drag). ``shear`` is the
    flow's profile over the height y: 0 (default) a uniform flow, the paper's; > 0 a
    linear boundary layer, the flow ``Rod.flow`` times ``shear`` y (so ``Rod.flow`` at
    y = 1/shear), in 1/length of the rod's units."""

    mu: float = 1.0
    sigma: float = 1.0
    c_sigma: float = 2.29
    law: str = "linear"
    shear: float = 0.0

    @property
    def law_code(self) -> int:
        return DRAG_LAWS[self.law]

    def __post_init__(self) -> None:
        if self.law not in DRAG_LAWS:
            raise ValueError(f"drag law must be one of {list(DRAG_LAWS)}, got {self.law!r}")
        for name in ("mu", "sigma", "c_sigma", "shear"):
            v = getattr(self, name)
            if not (math.isfinite(v) and v >= 0):
                raise ValueError(f"DragParams.{name} must be finite and >= 0, got {v!r}")


@dataclass(frozen=True)
class NewtonOptions:
    """Tolerances of the Newton solve; each has one home, here."""

    # in units of force_scale (e_v in the dimensionless model). The deposition model can
    # afford 1e-5 e_v (benchmarks/RESULTS.md, "Issue 11: speed";
    # tests/test_stepper_speed_equivalence.py); this default serves any force scale.
    residual_tol: float = 1e-8
    force_scale: float = 1.0
    update_tol: float = 1e-12  # in units of the shortest rest length
    max_iter: int = 25
    max_halvings: int = 12
    # Evaluate a residual that is expected to converge alone, before assembling J (the
    # results are bit-identical either way; False is the pre-issue-11 cost, for A/B).
    residual_check: bool = True
    # Newton's Jacobian with the frame-transport terms the DER Hessian omits
    # (elastic._transport_terms; -dF/dq exactly). Off by default: on the deposition runs
    # it saves 1-2% of the iterations (the residual sequence is set by the large first
    # update, not by the Jacobian's error) and costs ~9% more per assembly
    # (benchmarks/RESULTS.md, "Issue 11", exact Jacobian). False: the symmetric DER
    # Hessian (Bergou 2010), bit-identical to tests/data/stepper_regression.npz.
    exact_jacobian: bool = False
    # Length projection of the Newton iterates (project_lengths): each edge the update
    # rotated is brought back to the length the linearised update asks for, shortened by
    # at most this fraction per iteration (0: off, the plain Newton iterates). Same
    # converged solution to the tolerance, fewer iterations where edges rotate (the
    # model's contact edge): benchmarks/RESULTS.md, "Issue 11", length projection.
    length_projection: float = 0.0
    # A step whose Newton solve fails from the predictor q_n + dt u_n is solved once more
    # from q_n before it is halved (same equations: only the start differs). Off by
    # default: it changes the trajectory wherever a step used to be halved. On the
    # serpentine at half the model's step the predictor's start diverges in the step
    # after a deposit (residuals 1e4-1e9) while q_n converges in 4-5 iterations
    # (benchmarks/RESULTS.md, issue 12, "Δt on the shipped solver").
    predictor_retry: bool = False
    # A converged step that turns any edge by more than this angle (rad) is rejected like a
    # failed solve (retried from q_n with predictor_retry, else halved); 0 turns the check
    # off. Implicit Euler on the vdW contact can converge to a distant root of the step
    # equations: on the serpentine at half the model's step one step turned an edge by
    # 116 deg (a hairpin beside the contact, the contact node lifted from y 0.68 to 1.05),
    # the seed of the defects that made periodic serpentines irregular. At the model's
    # step no edge turns more than 17.2 deg in a step (v-bar 0.037 and 0.12, 1000 L_vb):
    # benchmarks/RESULTS.md, issue 12, "The edge-rotation check".
    max_edge_rotation: float = 0.0
    # Within a step, Newton's later iterations reuse the bend-twist and drag blocks of the
    # Jacobian from the step's first assembly (stepper.assemble, SOFT_REUSE); the stiff
    # blocks (stretch, vdW), the substrate and inertia are assembled at every iterate and
    # every residual is exact, so the equations, the tolerance and the solution are the
    # same, and the LU is still refactored each iteration (a reused stretch block is what
    # made chord Newton diverge). Off by default: the iterates differ, so the traces part
    # as for a change of tolerance. On the env: ~0.5 more iterations per step at ~2/3 of
    # the cost each, 1.3x the L_vb per CPU-s (benchmarks/RESULTS.md, issue 11, "lagged
    # soft Jacobian").
    lagged_jacobian: bool = False

    def __post_init__(self) -> None:
        p = self.length_projection
        if not (math.isfinite(p) and 0.0 <= p < 1.0):
            raise ValueError(f"NewtonOptions.length_projection must be in [0, 1), got {p!r}")
        r = self.max_edge_rotation
        if not (math.isfinite(r) and 0.0 <= r <= math.pi):
            raise ValueError(f"NewtonOptions.max_edge_rotation must be in [0, pi], got {r!r}")


#: Frames and strains of iterate q, transported from the step-start frame (one fused
#: pass; the stepper's name for :func:`frames.update_all`).
update_frames = frames.update_all


@njit(cache=True)
def assemble(
    q: np.ndarray,
    q_old: np.ndarray,
    u_old: np.ndarray,
    n_nodes: int,
    dt: float,
    mass: np.ndarray,
    fixed: np.ndarray,
    rest_lengths: np.ndarray,
    voronoi_lengths: np.ndarray,
    k_s: float,
    k_b: float,
    k_t: float,
    m1: np.ndarray,
    m2: np.ndarray,
    twist: np.ndarray,
    ext_force: np.ndarray,
    drag_on: np.ndarray,
    flow: np.ndarray,
    flow_shear: float,
    mu: float,
    sigma: float,
    c_sigma: float,
    drag_law: int,
    vdw: np.ndarray,
    sub_friction: np.ndarray,
    sub_stiffness: np.ndarray,
    sub_anchor: np.ndarray,
    force: np.ndarray,
    ab: np.ndarray,
    rhs: np.ndarray,
    tangents_old: np.ndarray,
    transport: bool,
    fix_rows: bool,
    ab_soft: np.ndarray,
    soft: int,
) -> float:
    """Residual f (stored as rhs = -f, zero on fixed DOFs) and Jacobian J in band storage
    (identity rows on fixed DOFs). Returns max |f| over free DOFs (inf/NaN propagate).
    ``transport``: J includes the frame-transport terms (exact; elastic.add_bend_twist).
    ``fix_rows`` False leaves the fixed DOFs' rows and columns as assembled, for a caller
    that drops them (:func:`gather_free`).

    ``soft`` (NewtonOptions.lagged_jacobian): SOFT_FRESH assembles every block at q;
    SOFT_KEEP also keeps the bend-twist and drag blocks of J in ``ab_soft``; SOFT_REUSE
    takes those two blocks from ``ab_soft`` (an earlier iterate's) and assembles the rest
    (stretch, vdW, substrate, inertia) at q. The residual is always that of q, and in
    SOFT_FRESH the operations are those of the plain assembly (the same bits)."""
    n_dof = 4 * n_nodes - 1
    inv_dt2 = 1.0 / (dt * dt)
    for k in range(n_dof):
        force[k] = ext_force[k]
    soft_ab = ab  # where the bend-twist and drag blocks go
    if soft == SOFT_REUSE:
        for c in range(n_dof):
            for r in range(LDAB):
                ab[r, c] = ab_soft[r, c]
    else:
        band_zero(ab, n_dof)
        if soft == SOFT_KEEP:
            band_zero(ab_soft, n_dof)
            soft_ab = ab_soft
    with_soft = soft != SOFT_REUSE
    elastic.add_stretch(q, n_nodes, rest_lengths, k_s, force, ab, True)
    elastic.add_bend_twist(q, n_nodes, m1, m2, twist, voronoi_lengths, k_b, k_t, force, soft_ab,
                           with_soft, tangents_old, transport, fixed)  # fmt: skip
    if drag_law == DRAG_LINEAR:
        add_linear_drag(q, q_old, dt, n_nodes, rest_lengths, drag_on, flow, flow_shear, mu,
                        sigma, c_sigma, force, soft_ab, with_soft, fixed)  # fmt: skip
    else:
        add_printed_drag(q, q_old, dt, n_nodes, rest_lengths, drag_on, flow, flow_shear, mu,
                         sigma, c_sigma, force, soft_ab, with_soft, fixed)  # fmt: skip
    if soft == SOFT_KEEP:
        for c in range(n_dof):
            for r in range(LDAB):
                ab[r, c] += ab_soft[r, c]
    add_adhesion(q, n_nodes, voronoi_lengths, vdw, force, ab, True)
    add_substrate(q, q_old, dt, n_dof, sub_friction, sub_stiffness, sub_anchor, force, ab, True)
    res = 0.0
    for k in range(n_dof):
        if fixed[k]:
            rhs[k] = 0.0
            if fix_rows:
                band_fix_dof(ab, n_dof, k)
            continue
        r = mass[k] * ((q[k] - q_old[k]) / dt - u_old[k]) / dt - force[k]  # docs/model.md §3
        ab[_DIAG, k] += mass[k] * inv_dt2
        rhs[k] = -r
        if not abs(r) <= res:  # also catches NaN
            res = abs(r)
    return res


@njit(cache=True)
def residual(
    q: np.ndarray,
    q_old: np.ndarray,
    u_old: np.ndarray,
    n_nodes: int,
    dt: float,
    mass: np.ndarray,
    fixed: np.ndarray,
    rest_lengths: np.ndarray,
    voronoi_lengths: np.ndarray,
    k_s: float,
    k_b: float,
    k_t: float,
    m1: np.ndarray,
    m2: np.ndarray,
    twist: np.ndarray,
    ext_force: np.ndarray,
    drag_on: np.ndarray,
    flow: np.ndarray,
    flow_shear: float,
    mu: float,
    sigma: float,
    c_sigma: float,
    drag_law: int,
    vdw: np.ndarray,
    sub_friction: np.ndarray,
    sub_stiffness: np.ndarray,
    sub_anchor: np.ndarray,
    force: np.ndarray,
    ab: np.ndarray,
    rhs: np.ndarray,
) -> float:
    """The residual part of :func:`assemble` alone: rhs = -f (zero on fixed DOFs), the
    same floating-point operations in the same order, so the same bits; ``ab`` is not
    touched. Returns max |f| over free DOFs."""
    n_dof = 4 * n_nodes - 1
    for k in range(n_dof):
        force[k] = ext_force[k]
    elastic.add_stretch(q, n_nodes, rest_lengths, k_s, force, ab, False)
    # (the tangents_old argument, here m1, is not read without the Jacobian)
    elastic.add_bend_twist(q, n_nodes, m1, m2, twist, voronoi_lengths, k_b, k_t, force, ab, False,
                           m1, False, fixed)  # fmt: skip
    if drag_law == DRAG_LINEAR:
        add_linear_drag(q, q_old, dt, n_nodes, rest_lengths, drag_on, flow, flow_shear, mu,
                        sigma, c_sigma, force, ab, False, fixed)  # fmt: skip
    else:
        add_printed_drag(q, q_old, dt, n_nodes, rest_lengths, drag_on, flow, flow_shear, mu,
                         sigma, c_sigma, force, ab, False, fixed)  # fmt: skip
    add_adhesion(q, n_nodes, voronoi_lengths, vdw, force, ab, False)
    add_substrate(q, q_old, dt, n_dof, sub_friction, sub_stiffness, sub_anchor, force, ab, False)
    res = 0.0
    for k in range(n_dof):
        if fixed[k]:
            rhs[k] = 0.0
            continue
        r = mass[k] * ((q[k] - q_old[k]) / dt - u_old[k]) / dt - force[k]  # docs/model.md §3
        rhs[k] = -r
        if not abs(r) <= res:  # also catches NaN
            res = abs(r)
    return res


@njit(cache=True)
def gather_free(ab: np.ndarray, free: np.ndarray, n_free: int, ab_r: np.ndarray) -> None:
    """The band of J restricted to the free DOFs ``free[:n_free]`` (ascending), in
    ``ab_r``: A_r[a, b] = A[free[a], free[b]]. Dropping the fixed DOFs' identity rows and
    zeroed columns leaves the solution of the free DOFs unchanged, and the banded LU does
    the same operations on the same non-zero entries in the same order (the mapping is
    monotone, so every coupling stays within the band), so the same bits."""
    for b in range(n_free):
        cb = free[b]
        for a in range(max(0, b - KU), min(n_free, b + KL + 1)):
            d = free[a] - cb
            ab_r[_DIAG + a - b, b] = ab[_DIAG + d, cb] if -KU <= d <= KL else 0.0


@njit(cache=True)
def project_lengths(
    q: np.ndarray,
    dq: np.ndarray,
    n_nodes: int,
    fixed: np.ndarray,
    tangents: np.ndarray,
    lengths: np.ndarray,
    cap: float,
) -> None:
    """Length projection of a Newton iterate (``NewtonOptions.length_projection``).

    A Newton update dq rotates an edge e to e + de, of length sqrt(l_lin^2 + |de_perp|^2)
    with l_lin = |e| + t.de the length the linearised update asks for: the rotation
    stretches it by ~|e| theta^2 / 2, which k_s turns into a residual of k_s |e| theta^2 / 2
    that the next iteration undoes (the residual then bounces, e.g. 5 -> 61 -> 0.7 -> 4.6
    on the env's contact edge). Each edge whose upper node is wholly free is rescaled to
    l_lin along e + de, by at most ``cap`` (relative), and the nodes above move with
    it, rigidly, so no other edge changes; a node with a fixed DOF restarts the chain.
    The correction is second order in dq, so Newton's convergence and its solution are
    unchanged: only the iterates on the way differ.
    """
    sx = 0.0
    sy = 0.0
    sz = 0.0
    for j in range(n_nodes - 1):
        a = 4 * j
        b = a + 4
        if fixed[b] or fixed[b + 1] or fixed[b + 2]:
            sx = 0.0
            sy = 0.0
            sz = 0.0
            continue
        # the edge as Newton left it: node j has moved by the shift s already
        ex = q[b] - q[a] + sx
        ey = q[b + 1] - q[a + 1] + sy
        ez = q[b + 2] - q[a + 2] + sz
        ln = math.sqrt(ex * ex + ey * ey + ez * ez)
        lin = lengths[j]
        for k in range(3):
            lin += tangents[j, k] * (dq[b + k] - dq[a + k])
        f = 1.0
        if 0.0 < lin < ln:  # ln >= |l_lin| always: the correction only shortens
            f = max(lin / ln, 1.0 - cap)
        nx = q[a] + f * ex
        ny = q[a + 1] + f * ey
        nz = q[a + 2] + f * ez
        sx = nx - q[b]
        sy = ny - q[b + 1]
        sz = nz - q[b + 2]
        q[b] = nx
        q[b + 1] = ny
        q[b + 2] = nz


@njit(cache=True)
def newton_solve(
    q: np.ndarray,
    q_old: np.ndarray,
    u_old: np.ndarray,
    n_nodes: int,
    dt: float,
    mass: np.ndarray,
    fixed: np.ndarray,
    rest_lengths: np.ndarray,
    voronoi_lengths: np.ndarray,
    k_s: float,
    k_b: float,
    k_t: float,
    tangents_old: np.ndarray,
    d1_old: np.ndarray,
    ref_twist_old: np.ndarray,
    ext_force: np.ndarray,
    drag_on: np.ndarray,
    flow: np.ndarray,
    flow_shear: float,
    mu: float,
    sigma: float,
    c_sigma: float,
    drag_law: int,
    vdw: np.ndarray,
    sub_friction: np.ndarray,
    sub_stiffness: np.ndarray,
    sub_anchor: np.ndarray,
    tol_abs: float,
    update_abs: float,
    max_iter: int,
    tangents: np.ndarray,
    lengths: np.ndarray,
    d1: np.ndarray,
    d2: np.ndarray,
    m1: np.ndarray,
    m2: np.ndarray,
    kb: np.ndarray,
    kappa: np.ndarray,
    twist: np.ndarray,
    ref_twist: np.ndarray,
    force: np.ndarray,
    ab: np.ndarray,
    ipiv: np.ndarray,
    rhs: np.ndarray,
    out_stats: np.ndarray,
    ab_r: np.ndarray,
    free: np.ndarray,
    rhs_r: np.ndarray,
    check: bool,
    transport: bool,
    projection: float,
    ab_soft: np.ndarray,
    lagged: bool,
) -> int:
    """One implicit-Euler step from (q_old, u_old); q holds the initial guess (fixed DOFs
    at their prescribed values) and receives the solution. On return the frame buffers
    (tangents, d1, d2, ref_twist, ...) belong to the returned q. out_stats = [iterations,
    final free residual, LU factorisations, residual-only evaluations]. Returns a status
    code (CONVERGED, ...).

    A residual that the last two are expected to bring below ``tol_abs`` (geometric
    extrapolation; ``check``) is first evaluated alone (:func:`residual`, no Jacobian):
    when it converges the Jacobian is not assembled, and when it does not, the full
    assembly follows. Either way every iterate, residual and Jacobian is the same, bit
    for bit, as with an assembly every iteration.

    When DOFs are fixed, the linear solve runs on the free DOFs alone (``ab_r``, ``free``,
    ``rhs_r``: :func:`gather_free`), which gives the same bits as the full system with
    identity rows and is cheaper by the fixed share of the band.
    """
    n_dof = 4 * n_nodes - 1
    n_free = 0
    for k in range(n_dof):
        if fixed[k] == 0:
            free[n_free] = k
            n_free += 1
    reduced = n_free < n_dof
    status = MAX_ITERATIONS
    it = 0
    res = math.inf
    res_prev = math.inf
    res_prev2 = math.inf
    n_factor = 0
    n_resid = 0
    while True:
        update_frames(q, n_nodes, tangents_old, d1_old, ref_twist_old, tangents, lengths,
                      d1, d2, ref_twist, m1, m2, kb, kappa, twist)  # fmt: skip
        if status == CONVERGED or it >= max_iter:
            break
        # expected residual by geometric extrapolation of the last two: if it converges,
        # evaluate it without the Jacobian first
        if check and it >= 2 and res_prev * (res_prev / res_prev2) <= tol_abs:
            res = residual(q, q_old, u_old, n_nodes, dt, mass, fixed, rest_lengths,
                           voronoi_lengths, k_s, k_b, k_t, m1, m2, twist, ext_force, drag_on,
                           flow, flow_shear, mu, sigma, c_sigma, drag_law, vdw, sub_friction,
                           sub_stiffness, sub_anchor, force, ab, rhs)  # fmt: skip
            n_resid += 1
            if not math.isfinite(res):
                status = NON_FINITE
                break
            if res <= tol_abs:
                status = CONVERGED
                break
        soft = SOFT_FRESH
        if lagged:  # the first assembly of the solve keeps the soft blocks, later ones reuse
            soft = SOFT_REUSE if n_factor > 0 else SOFT_KEEP
        res = assemble(q, q_old, u_old, n_nodes, dt, mass, fixed, rest_lengths,
                       voronoi_lengths, k_s, k_b, k_t, m1, m2, twist, ext_force, drag_on,
                       flow, flow_shear, mu, sigma, c_sigma, drag_law, vdw, sub_friction,
                       sub_stiffness, sub_anchor, force, ab, rhs, tangents_old, transport,
                       not reduced, ab_soft, soft)  # fmt: skip
        if not math.isfinite(res):
            status = NON_FINITE
            break
        if res <= tol_abs:
            status = CONVERGED
            break
        if reduced:
            gather_free(ab, free, n_free, ab_r)
            for a in range(n_free):
                rhs_r[a] = rhs[free[a]]
            if band_lu_factor(ab_r, n_free, ipiv) != 0:
                status = SINGULAR
                break
            band_lu_solve(ab_r, n_free, ipiv, rhs_r)
            for a in range(n_free):  # the fixed DOFs keep rhs = 0: a zero update
                rhs[free[a]] = rhs_r[a]
        else:
            if band_lu_factor(ab, n_dof, ipiv) != 0:
                status = SINGULAR
                break
            band_lu_solve(ab, n_dof, ipiv, rhs)
        n_factor += 1
        du = 0.0
        for k in range(n_dof):
            q[k] += rhs[k]
            if not abs(rhs[k]) <= du:
                du = abs(rhs[k])
        if projection > 0.0:
            project_lengths(q, rhs, n_nodes, fixed, tangents, lengths, projection)
        it += 1
        res_prev2 = res_prev
        res_prev = res
        if not math.isfinite(du):
            status = NON_FINITE
            break
        if du <= update_abs:
            status = CONVERGED  # frames are refreshed for this q at the loop top
    out_stats[0] = it
    out_stats[1] = res
    out_stats[2] = n_factor
    out_stats[3] = n_resid
    return status


@njit(cache=True)
def _rotation_status(q: np.ndarray, n_nodes: int, tangents_old: np.ndarray,
                     cos_max_rotation: float) -> int:  # fmt: skip
    """ROTATED if some edge's direction at q makes an angle with its start-of-step
    tangent whose cosine is below ``cos_max_rotation``, else CONVERGED."""
    for j in range(n_nodes - 1):
        a, b = 4 * j, 4 * (j + 1)
        ex, ey, ez = q[b] - q[a], q[b + 1] - q[a + 1], q[b + 2] - q[a + 2]
        dot = ex * tangents_old[j, 0] + ey * tangents_old[j, 1] + ez * tangents_old[j, 2]
        if dot < cos_max_rotation * math.sqrt(ex * ex + ey * ey + ez * ez):
            return ROTATED
    return CONVERGED


@njit(cache=True)
def implicit_step(
    q: np.ndarray,
    u: np.ndarray,
    q_old: np.ndarray,
    u_old: np.ndarray,
    n_nodes: int,
    dt: float,
    mass: np.ndarray,
    fixed: np.ndarray,
    rest_lengths: np.ndarray,
    voronoi_lengths: np.ndarray,
    k_s: float,
    k_b: float,
    k_t: float,
    tangents_old: np.ndarray,
    d1_old: np.ndarray,
    ref_twist_old: np.ndarray,
    ext_force: np.ndarray,
    drag_on: np.ndarray,
    flow: np.ndarray,
    flow_shear: float,
    mu: float,
    sigma: float,
    c_sigma: float,
    drag_law: int,
    vdw: np.ndarray,
    sub_friction: np.ndarray,
    sub_stiffness: np.ndarray,
    sub_anchor: np.ndarray,
    tol_abs: float,
    update_tol: float,
    max_iter: int,
    tangents: np.ndarray,
    lengths: np.ndarray,
    d1: np.ndarray,
    d2: np.ndarray,
    m1: np.ndarray,
    m2: np.ndarray,
    kb: np.ndarray,
    kappa: np.ndarray,
    twist: np.ndarray,
    ref_twist: np.ndarray,
    force: np.ndarray,
    ab: np.ndarray,
    ipiv: np.ndarray,
    rhs: np.ndarray,
    out_stats: np.ndarray,
    ab_r: np.ndarray,
    free: np.ndarray,
    rhs_r: np.ndarray,
    check: bool,
    transport: bool,
    projection: float,
    retry: bool,
    cos_max_rotation: float,
    ab_soft: np.ndarray,
    lagged: bool,
) -> int:
    """One attempted step of Rod (:meth:`Rod._try_step`) in one compiled call: save the
    step start, predict q_n + dt u_n on free DOFs, solve (with ``retry``, once more from
    q_n when that fails; out_stats then sum both solves' counts); a converged solution
    that turns an edge's tangent against ``tangents_old`` below ``cos_max_rotation``
    counts as failed (ROTATED; -2: no check); commit (u, start-of-step frames) on success
    or restore q and u on failure."""
    n_dof = 4 * n_nodes - 1
    for k in range(n_dof):
        q_old[k] = q[k]
        u_old[k] = u[k]
    for k in range(n_dof):
        if fixed[k] == 0:
            q[k] += dt * u[k]
    min_rest = rest_lengths[0]
    for j in range(1, n_nodes - 1):
        if rest_lengths[j] < min_rest:
            min_rest = rest_lengths[j]
    status = MAX_ITERATIONS
    its = 0.0
    lus = 0.0
    residual_only = 0.0
    for attempt in range(2 if retry else 1):
        if attempt == 1:
            if status == CONVERGED:
                break
            for k in range(n_dof):  # the retry: the same equations from q_n
                q[k] = q_old[k]
        status = newton_solve(
            q, q_old, u_old, n_nodes, dt, mass, fixed, rest_lengths, voronoi_lengths, k_s,
            k_b, k_t, tangents_old, d1_old, ref_twist_old, ext_force, drag_on, flow, flow_shear, mu,
            sigma, c_sigma, drag_law, vdw, sub_friction, sub_stiffness, sub_anchor, tol_abs,
            update_tol * min_rest, max_iter, tangents, lengths,
            d1, d2, m1, m2, kb, kappa, twist, ref_twist, force, ab, ipiv, rhs, out_stats, ab_r,
            free, rhs_r, check, transport, projection, ab_soft, lagged,
        )  # fmt: skip
        its += out_stats[0]
        lus += out_stats[2]
        residual_only += out_stats[3]
        if status == CONVERGED and cos_max_rotation > -1.0:
            status = _rotation_status(q, n_nodes, tangents_old, cos_max_rotation)
    out_stats[0] = its
    out_stats[2] = lus
    out_stats[3] = residual_only
    if status != CONVERGED:
        for k in range(n_dof):
            q[k] = q_old[k]
            u[k] = u_old[k]
        return status
    for k in range(n_dof):
        u[k] = (q[k] - q_old[k]) / dt
    for j in range(n_nodes - 1):
        for c in range(3):
            tangents_old[j, c] = tangents[j, c]
            d1_old[j, c] = d1[j, c]
    for i in range(n_nodes):
        ref_twist_old[i] = ref_twist[i]
    return CONVERGED


class Rod:
    """A discrete elastic rod with its buffers and an implicit-Euler Newton stepper.

    Positions are set from ``nodes`` (n_nodes, 3); rest lengths are the initial edge
    lengths unless given. The reference frame starts space-parallel, so the rod starts
    untwisted with theta = 0 unless ``thetas`` are given.
    """

    q: np.ndarray
    u: np.ndarray
    mass: np.ndarray
    fixed: np.ndarray
    ext_force: np.ndarray
    rest_lengths: np.ndarray
    voronoi_lengths: np.ndarray
    drag_on: np.ndarray
    flow: np.ndarray
    tangents_old: np.ndarray
    d1_old: np.ndarray
    ref_twist_old: np.ndarray

    def __init__(
        self,
        nodes: np.ndarray,
        material: RodMaterial,
        drag: DragParams | None = None,
        options: NewtonOptions | None = None,
        rest_lengths: np.ndarray | None = None,
        thetas: np.ndarray | None = None,
        max_nodes: int | None = None,
    ) -> None:
        nodes = np.asarray(nodes, dtype=np.float64)
        if nodes.ndim != 2 or nodes.shape[1] != 3 or nodes.shape[0] < 2:
            raise ValueError("nodes must have shape (n_nodes >= 2, 3)")
        if not np.all(np.isfinite(nodes)):
            raise ValueError("nodes contain NaN or inf")
        n = nodes.shape[0]
        cap = max(n, max_nodes or n)
        self.material = material
        self.drag = drag or DragParams(mu=0.0)
        self.options = options or NewtonOptions()
        self.n_nodes = n
        self.max_nodes = cap
        self._allocate(cap)
        self.flow = np.zeros(3)
        # vdW contact, laid out as forces.VDW_*: node -1 means no contact force
        self.vdw = np.array([-1.0, 1.0, 1.0, 0.05, 1.0, 0.0, 0.05])
        self.time = 0.0
        self.steps = 0
        self.newton_iterations = 0
        self.halvings = 0
        self.lu_factorisations = 0

        for i in range(n):
            self.q[4 * i : 4 * i + 3] = nodes[i]
        if thetas is not None:
            self.q[3 : 4 * n - 1 : 4] = thetas
        frames.compute_tangents(self.q, n, self.tangents_old, self._lengths)
        if rest_lengths is None:
            self.rest_lengths[: n - 1] = self._lengths[: n - 1]
        else:
            self.rest_lengths[: n - 1] = rest_lengths
        if np.any(self.rest_lengths[: n - 1] <= 0):
            raise ValueError("rest lengths must be > 0 (coincident nodes?)")
        frames.initial_reference_frame(self.tangents_old, n - 1, self.d1_old)
        self.update_mass()

    # per-DOF, per-edge and per-node buffers, and the Newton workspace (name: (shape, dtype))
    _DOF_BUFFERS = ("q", "u", "mass", "fixed", "ext_force", "_q_old", "_u_old", "_force",
                    "_rhs", "_ipiv", "sub_friction", "sub_stiffness", "sub_anchor")  # fmt: skip
    _EDGE_BUFFERS = ("rest_lengths", "drag_on", "tangents_old", "d1_old", "_tangents",
                     "_lengths", "_d1", "_d2", "_m1", "_m2")  # fmt: skip
    _NODE_BUFFERS = ("voronoi_lengths", "ref_twist_old", "_kb", "_kappa", "_twist",
                     "_ref_twist")  # fmt: skip

    def _allocate(self, cap: int) -> None:
        """(Re)allocate every buffer for ``cap`` nodes, keeping the active contents."""
        old = {name: getattr(self, name, None) for name in
               self._DOF_BUFFERS + self._EDGE_BUFFERS + self._NODE_BUFFERS}  # fmt: skip
        n_dof_cap = 4 * cap  # one padding slot so q reshapes to (n_nodes, 4)
        new = {
            "q": np.zeros(n_dof_cap), "u": np.zeros(n_dof_cap), "mass": np.zeros(n_dof_cap),
            "fixed": np.zeros(n_dof_cap, dtype=np.uint8), "ext_force": np.zeros(n_dof_cap),
            "_q_old": np.zeros(n_dof_cap), "_u_old": np.zeros(n_dof_cap),
            "_force": np.zeros(n_dof_cap), "_rhs": np.zeros(n_dof_cap),
            "_ipiv": np.zeros(n_dof_cap, dtype=np.int64),
            "sub_friction": np.zeros(n_dof_cap), "sub_stiffness": np.zeros(n_dof_cap),
            "sub_anchor": np.zeros(n_dof_cap),
            "rest_lengths": np.zeros(cap - 1), "drag_on": np.ones(cap - 1, dtype=np.uint8),
            "tangents_old": np.zeros((cap - 1, 3)), "d1_old": np.zeros((cap - 1, 3)),
            "_tangents": np.zeros((cap - 1, 3)), "_lengths": np.zeros(cap - 1),
            "_d1": np.zeros((cap - 1, 3)), "_d2": np.zeros((cap - 1, 3)),
            "_m1": np.zeros((cap - 1, 3)), "_m2": np.zeros((cap - 1, 3)),
            "voronoi_lengths": np.zeros(cap), "ref_twist_old": np.zeros(cap),
            "_kb": np.zeros((cap, 3)), "_kappa": np.zeros((cap, 2)), "_twist": np.zeros(cap),
            "_ref_twist": np.zeros(cap),
        }  # fmt: skip
        for name, arr in new.items():
            prev = old[name]
            if prev is not None:
                m = min(len(prev), len(arr))
                arr[:m] = prev[:m]
            setattr(self, name, arr)
        self._ab = band_alloc(n_dof_cap)
        self._ab_r = band_alloc(n_dof_cap)  # the free DOFs' system (gather_free)
        self._ab_soft = band_alloc(n_dof_cap)  # NewtonOptions.lagged_jacobian
        self._free = np.zeros(n_dof_cap, dtype=np.int64)
        self._rhs_r = np.zeros(n_dof_cap)
        self._stats = np.zeros(4)
        self.max_nodes = cap

    def append_node(self, position: np.ndarray, velocity: np.ndarray, rest_length: float) -> None:
        """Add a node after the last one (injection at the free top, docs/model.md §4).

        The new edge gets theta and the reference director of the last edge transported
        onto its tangent, so it starts untwisted; the new interior node has zero
        reference twist.
        """
        n = self.n_nodes
        if n + 1 > self.max_nodes:
            self._allocate(max(2 * self.max_nodes, n + 1))
        j = n - 1  # index of the new edge
        i = 4 * n
        self.q[i : i + 3] = position
        self.u[i : i + 3] = velocity
        self.q[i - 1] = self.q[i - 5]  # theta of the new edge = theta of the last edge
        self.u[i - 1] = self.u[i - 5]
        self.fixed[i - 1 : i + 3] = 0
        self.ext_force[i - 1 : i + 3] = 0.0
        self.sub_friction[i - 1 : i + 3] = 0.0
        self.sub_stiffness[i - 1 : i + 3] = 0.0
        e = np.asarray(position, dtype=np.float64) - self.q[i - 4 : i - 1]
        t_new = e / numerics.norm(e)
        frames.parallel_transport(self.d1_old[j - 1], self.tangents_old[j - 1], t_new,
                                  self.d1_old[j])  # fmt: skip
        self.d1_old[j] -= numerics.dot(self.d1_old[j], t_new) * t_new
        self.d1_old[j] /= numerics.norm(self.d1_old[j])
        self.tangents_old[j] = t_new
        self.rest_lengths[j] = rest_length
        self.drag_on[j] = 1
        self.ref_twist_old[n - 1] = 0.0
        self.n_nodes = n + 1
        self.update_mass()

    def split_edge(self, j: int, n_sub: int) -> None:
        """Split edge j into ``n_sub`` equal collinear edges (graded discretisation).

        The new nodes lie on the straight edge with linearly interpolated velocities; the
        sub-edges inherit theta and the reference director of edge j, so the split adds no
        stretch, twist or bending at the new nodes. Mass is redistributed by
        :meth:`update_mass` (total mass is conserved).
        """
        if n_sub < 2:
            return
        n = self.n_nodes
        if not 0 <= j < n - 1:
            raise ValueError(f"edge {j} out of range")
        k = n_sub - 1
        if n + k > self.max_nodes:
            self._allocate(max(2 * self.max_nodes, n + k))
        a = 4 * (j + 1)  # first DOF of node j+1
        for name in self._DOF_BUFFERS:
            buf = getattr(self, name)
            buf[a + 4 * k : 4 * (n + k)] = buf[a : 4 * n].copy()
        for name in self._EDGE_BUFFERS:
            buf = getattr(self, name)
            buf[j + 1 + k : n - 1 + k] = buf[j + 1 : n - 1].copy()
            buf[j + 1 : j + 1 + k] = buf[j]
        for name in self._NODE_BUFFERS:
            buf = getattr(self, name)
            buf[j + 1 + k : n + k] = buf[j + 1 : n].copy()
        x0 = self.q[4 * j : 4 * j + 3].copy()
        x1 = self.q[a + 4 * k : a + 4 * k + 3].copy()
        u0 = self.u[4 * j : 4 * j + 3].copy()
        u1 = self.u[a + 4 * k : a + 4 * k + 3].copy()
        theta = self.q[4 * j + 3]
        omega = self.u[4 * j + 3]
        for m in range(k):
            w = (m + 1) / n_sub
            b = a + 4 * m
            self.q[b : b + 3] = (1 - w) * x0 + w * x1
            self.u[b : b + 3] = (1 - w) * u0 + w * u1
            self.q[b + 3] = theta
            self.u[b + 3] = omega
            self.fixed[b : b + 4] = 0
            self.ext_force[b : b + 4] = 0.0
            self.sub_friction[b : b + 4] = 0.0
            self.sub_stiffness[b : b + 4] = 0.0
            self.ref_twist_old[j + 1 + m] = 0.0
        self.rest_lengths[j : j + n_sub] = self.rest_lengths[j] / n_sub
        self.n_nodes = n + k
        self.update_mass()

    def drop_front(self, k: int) -> None:
        """Remove the first k nodes (deletion of the far deposited tail, docs/model.md §4)."""
        if k <= 0:
            return
        n = self.n_nodes
        if n - k < 2:
            raise ValueError("cannot drop below two nodes")
        for name in self._DOF_BUFFERS:
            a = getattr(self, name)
            a[: 4 * (n - k)] = a[4 * k : 4 * n].copy()
        for name in self._EDGE_BUFFERS:
            a = getattr(self, name)
            a[: n - 1 - k] = a[k : n - 1].copy()
        for name in self._NODE_BUFFERS:
            a = getattr(self, name)
            a[: n - k] = a[k:n].copy()
        self.n_nodes = n - k
        self.update_mass()

    # ---- views on the active part -------------------------------------------------
    @property
    def n_dof(self) -> int:
        return 4 * self.n_nodes - 1

    @property
    def nodes(self) -> np.ndarray:
        """(n_nodes, 3) view of the node positions."""
        return self.q[: 4 * self.n_nodes].reshape(self.n_nodes, 4)[:, :3]

    @property
    def node_velocities(self) -> np.ndarray:
        return self.u[: 4 * self.n_nodes].reshape(self.n_nodes, 4)[:, :3]

    @property
    def thetas(self) -> np.ndarray:
        return self.q[3 : self.n_dof : 4]

    def fix_node(self, i: int, fixed: bool = True) -> None:
        self.fixed[4 * i : 4 * i + 3] = fixed

    def fix_theta(self, j: int, fixed: bool = True) -> None:
        self.fixed[4 * j + 3] = fixed

    def update_mass(self) -> None:
        """Lumped masses from rest lengths: node rho * Voronoi length (docs/model.md §3)."""
        n = self.n_nodes
        rl = self.rest_lengths[: n - 1]
        vor = self.voronoi_lengths
        vor[:n] = 0.0
        vor[: n - 1] += 0.5 * rl
        vor[1:n] += 0.5 * rl
        rho, r0 = self.material.rho, self.material.r0
        for k in range(3):
            self.mass[k : 4 * n : 4] = rho * vor[:n]
        self.mass[3 : 4 * n - 1 : 4] = rho * rl * r0 * r0 / 2.0

    # ---- energies -------------------------------------------------------------
    def elastic_energy(self) -> float:
        """Stretch + bend + twist energy of the current state (frames as last stepped)."""
        n = self.n_nodes
        update_frames(self.q, n, self.tangents_old, self.d1_old, self.ref_twist_old,
                      self._tangents, self._lengths, self._d1, self._d2, self._ref_twist,
                      self._m1, self._m2, self._kb, self._kappa, self._twist)  # fmt: skip
        m = self.material
        return elastic.stretch_energy(self.q, n, self.rest_lengths, m.k_s) + (
            elastic.bend_twist_energy(
                self._kappa, self._twist, self.voronoi_lengths, n, m.k_b, m.k_t
            )
        )

    def elastic_force(self) -> np.ndarray:
        """-dE/dq of the current state (n_dof,), frames as for :meth:`elastic_energy`."""
        self.elastic_energy()  # refreshes frames and strains in the workspace
        n = self.n_nodes
        m = self.material
        f = np.zeros(self.n_dof)
        ab = self._ab
        elastic.add_stretch(self.q, n, self.rest_lengths, m.k_s, f, ab, False)
        elastic.add_bend_twist(self.q, n, self._m1, self._m2, self._twist,
                               self.voronoi_lengths, m.k_b, m.k_t, f, ab, False,
                               self.tangents_old, False, self.fixed)  # fmt: skip
        return f

    def kinetic_energy(self) -> float:
        nd = self.n_dof
        return 0.5 * numerics.dot(self.mass[:nd], self.u[:nd] ** 2)

    # ---- stepping -------------------------------------------------------------
    def _try_step(self, dt: float) -> int:
        """Attempt one step of size dt. On success commit it; on failure restore.

        The whole attempt (save, predict, Newton, commit or restore) is one compiled
        call, :func:`implicit_step`."""
        n = self.n_nodes
        try:
            status = self._newton(n, dt)
        except ZeroDivisionError:  # numba's error model: a degenerate edge (zero length)
            nd = self.n_dof
            self.q[:nd] = self._q_old[:nd]
            self.u[:nd] = self._u_old[:nd]
            return NON_FINITE
        self.newton_iterations += int(self._stats[0])
        self.lu_factorisations += int(self._stats[2])
        if status != CONVERGED:
            return status
        self.time += dt
        self.steps += 1
        return CONVERGED

    def _newton(self, n: int, dt: float) -> int:
        m, d, o = self.material, self.drag, self.options
        self._stats[:] = 0.0
        return implicit_step(
            self.q, self.u, self._q_old, self._u_old, n, dt,
            self.mass, self.fixed, self.rest_lengths, self.voronoi_lengths, m.k_s, m.k_b,
            m.k_t, self.tangents_old, self.d1_old, self.ref_twist_old, self.ext_force,
            self.drag_on, self.flow, d.shear, d.mu, d.sigma, d.c_sigma, d.law_code, self.vdw,
            self.sub_friction, self.sub_stiffness, self.sub_anchor,
            o.residual_tol * o.force_scale, o.update_tol, o.max_iter,
            self._tangents, self._lengths, self._d1, self._d2, self._m1, self._m2,
            self._kb, self._kappa, self._twist, self._ref_twist,
            self._force, self._ab, self._ipiv, self._rhs, self._stats,
            self._ab_r, self._free, self._rhs_r, o.residual_check, o.exact_jacobian,
            o.length_projection, o.predictor_retry,
            math.cos(o.max_edge_rotation) if o.max_edge_rotation > 0.0 else -2.0,
            self._ab_soft, o.lagged_jacobian,
        )  # fmt: skip

    def step(self, dt: float) -> None:
        """Advance by exactly ``dt``; a failed step is retried as two halves, recursively.

        Raises SimulationError when a step fails at dt / 2**max_halvings.
        """
        if not (math.isfinite(dt) and dt > 0):
            raise ValueError(f"dt must be finite and > 0, got {dt!r}")
        self._advance(dt, 0)

    def _advance(self, dt: float, depth: int) -> None:
        status = self._try_step(dt)
        if status == CONVERGED:
            return
        if depth >= self.options.max_halvings:
            nd = self.n_dof
            raise SimulationError(
                STATUS_TEXT[status], self.steps, self.time, dt,
                {"q": self.q[:nd].copy(), "u": self.u[:nd].copy(), "n_nodes": self.n_nodes},
            )  # fmt: skip
        self.halvings += 1
        self._advance(0.5 * dt, depth + 1)
        self._advance(0.5 * dt, depth + 1)

    def snapshot(self) -> dict:
        """Exact copy of the dynamic state (restore with :meth:`restore`)."""
        return {
            "n_nodes": self.n_nodes, "q": self.q.copy(), "u": self.u.copy(),
            "fixed": self.fixed.copy(), "ext_force": self.ext_force.copy(),
            "sub_friction": self.sub_friction.copy(),
            "sub_stiffness": self.sub_stiffness.copy(), "sub_anchor": self.sub_anchor.copy(),
            "rest_lengths": self.rest_lengths.copy(), "drag_on": self.drag_on.copy(),
            "flow": self.flow.copy(), "tangents_old": self.tangents_old.copy(),
            "d1_old": self.d1_old.copy(), "ref_twist_old": self.ref_twist_old.copy(),
            "vdw": self.vdw.copy(), "voronoi_lengths": self.voronoi_lengths.copy(),
            "mass": self.mass.copy(), "time": self.time, "steps": self.steps,
            "newton_iterations": self.newton_iterations, "halvings": self.halvings,
            "lu_factorisations": self.lu_factorisations,
        }  # fmt: skip

    def restore(self, snap: dict) -> None:
        """Restore a :meth:`snapshot` exactly (buffers are resized to fit)."""
        cap = (len(snap["q"])) // 4
        if cap != self.max_nodes:
            self._allocate(cap)
        for key in ("sub_friction", "sub_stiffness", "sub_anchor"):
            getattr(self, key)[...] = 0.0  # snapshots from before these existed: none
        for key, value in snap.items():
            if isinstance(value, np.ndarray):
                getattr(self, key)[...] = value
            else:
                setattr(self, key, value)


__all__ = [
    "LDAB",
    "DragParams",
    "NewtonOptions",
    "Rod",
    "RodMaterial",
    "SimulationError",
    "implicit_step",
    "newton_solve",
    "residual",
]

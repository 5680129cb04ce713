"""The deposition simulator: a CNT fed from the top falls onto a substrate and sticks.

:class:`DepositionSim` owns every buffer (through its :class:`~cnt_env.sim.stepper.Rod`)
and does, after each converged implicit step (docs/model.md §4):

1. contact: a free contact node that reaches y <= 0 is deposited (its DOFs fixed by the
   substrate); a new contact edge flatter than ``beta0_min`` is deposited at once;
2. vdW: the contact node c feels F_y = -(e_v delta / beta0) / sqrt(delta^2 - y_c^2)
   (paper eq. 1), inside the Newton solve with its Jacobian (or, with
   ``ContactOptions.adhesion="cohesive"``, every free node within range is pulled);
3. injection: while the top node is below H - delta, a node is appended one delta beyond
   it along the top tangent;
4. deletion: deposited nodes the solve no longer needs leave it; every deposited node is
   first appended to the persistent trace.

Rod layout: ``[deposited nodes (n_deposited, fixed) | contact node c | free ... | top]``.
All quantities are dimensionless (units.py): lengths in L_vb, time in mu L_vb^2 / e_v.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field, replace

import numpy as np
from numba import njit

from cnt_env import numerics
from cnt_env.presets import FLOW_PROFILES, MODEL, NEWTON, STEP_HBAR_CAP
from cnt_env.sim.forces import (
    ADHESION_MODELS,
    VDW_BETA0,
    VDW_CLAMP,
    VDW_DELTA,
    VDW_ENERGY,
    VDW_MODEL,
    VDW_NODE,
    VDW_RANGE,
    adhesion_energy,
    vdw_pull,
)
from cnt_env.sim.stepper import DragParams, NewtonOptions, Rod, RodMaterial, SimulationError
from cnt_env.sim.substrate import FlatSticky, Stepped, Substrate, check_sliding_options
from cnt_env.units import DimensionlessParams

CONTACT_MODES = ("project", "event")


@dataclass(frozen=True)
class ContactOptions:
    """Contact and vdW guards (docs/model.md §4). Each option has one home, here.

    * ``mode``: ``"event"`` (default) locates touchdown: a step that takes the contact
      node below ``-event_tol * delta * sin(beta0)`` is rewound and retaken with the step length
      interpolated to land on y = 0. ``"project"`` projects the node onto y = 0 after the
      step, as in the paper's description.
    * ``beta0_min``: a new contact edge flatter than this (rad) deposits at once.
    * ``sqrt_clamp``: sqrt(delta^2 - y_c^2) is clamped below at this times delta.
    * A contact node is deposited once y_c <= ``event_tol * delta * sin(beta0)`` (the
      vdW energy it still holds is then below 1% of e_v delta).
    * ``adhesion`` [choice]: ``"eq1"`` (default), the paper's eq. 1, a pull on the
      contact node alone that jumps to the next node when it lands; ``"cohesive"``, a
      pull of finite range ``cohesive_range`` (L_vb) on every free node below that
      height (forces.cohesive_pull), which hands over from node to node continuously.
      Both release e_v per unit length laid. With ``"cohesive"`` a contact node is
      deposited once y_c <= ``event_tol * cohesive_range``; ``beta0_min`` and
      ``sqrt_clamp`` apply to eq. 1 alone.
    """

    mode: str = "event"
    beta0_min: float = 0.005
    sqrt_clamp: float = 0.05
    event_tol: float = 0.01
    max_event_iterations: int = 30
    adhesion: str = "eq1"
    cohesive_range: float = 0.05

    def __post_init__(self) -> None:
        if self.mode not in CONTACT_MODES:
            raise ValueError(f"contact mode must be one of {CONTACT_MODES}, got {self.mode!r}")
        if self.adhesion not in ADHESION_MODELS:
            raise ValueError(f"adhesion must be one of {tuple(ADHESION_MODELS)}, "
                             f"got {self.adhesion!r}")  # fmt: skip
        h = self.cohesive_range
        if not (isinstance(h, (int, float)) and math.isfinite(h) and h > 0):
            raise ValueError(f"ContactOptions.cohesive_range must be finite and > 0 (L_vb), "
                             f"got {h!r}")  # fmt: skip
        for name in ("beta0_min", "sqrt_clamp", "event_tol"):
            v = getattr(self, name)
            if not (math.isfinite(v) and 0 < v < 1):
                raise ValueError(f"ContactOptions.{name} must be in (0, 1), got {v!r}")


@dataclass(frozen=True)
class DepositionConfig:
    """Everything that defines a deposition run, in dimensionless units.

    The model defaults come from ``presets.MODEL`` (issue 12's choice). ``drag_law`` is
    ``"linear"`` or ``"printed"`` (forces.py). The substrate is flat and sticky when
    ``params.kappa_c_bar`` is None, stepped otherwise; ``sliding`` ("B", "C" or "none"),
    ``tail_length`` (L_vb of deposited arc kept in the solve; 195 = 25 um at the
    serpentine preset), ``friction``, ``snap``, ``snap_stiffness``, ``snap_length`` and
    ``tail_clamp`` apply to the stepped one (substrate.Stepped documents each).

    ``flow_profile`` [choice, docs/model.md §4]: ``"uniform"``, the paper's flow, the same
    at every height; ``"linear"``, a boundary layer over the substrate (no slip at y = 0),
    the flow ``vbar`` (y / Hbar), so that ``vbar`` is the flow at the rod's top.

    Graded discretisation [choice, docs/model.md §6]: with ``coarse_delta`` set, edges are
    injected at the top with that length and split into edges of ``delta_bar`` once they
    come within ``fine_length`` (arc length) of the contact node, where the curvature
    lives. ``None`` keeps the rod uniform at ``delta_bar``; ``default_config``, ``cnt-sim``
    and the env take the graded rod of ``presets.MESH``. ``newton`` defaults to
    ``presets.NEWTON`` (residual 1e-5 e_v).
    ``dt`` defaults to ``dt_factor * min(Hbar, dt_hbar_cap)``: the time to deposit
    ``dt_factor`` L_vb at the speed scale 1/Hbar, whatever delta (the dynamics near the
    contact are set by L_vb, not by delta; touchdowns are located inside a step by the
    event search), held at its value at Hbar = ``dt_hbar_cap`` above it. The cap defaults
    to the substrate's ``presets.STEP_HBAR_CAP`` (155 stepped, none flat: on the stepped
    substrate the step's error grows with the step in absolute time); None is no cap, the
    rule of earlier rounds. ``initial_radius`` is R_i of the start-up contact arc;
    ``perturbation`` the seeded out-of-plane noise in units of delta. ``max_nodes`` caps
    the solved rod: a configuration whose estimated node count exceeds it is refused here,
    and a rod that grows past it while running (a lost contact) raises SimulationError
    instead of exhausting memory.
    """

    params: DimensionlessParams
    dt: float | None = None
    dt_factor: float = 0.05
    dt_hbar_cap: float | str | None = "substrate"
    initial_radius: float = 6.4
    perturbation: float = 1e-3
    coarse_delta: float | None = None
    fine_length: float = 20.0
    drag_law: str = MODEL["drag_law"]
    sliding: str = MODEL["sliding"]
    tail_length: float = MODEL["tail_length"]
    friction: float = MODEL["friction"]
    snap: str = MODEL["snap"]
    snap_stiffness: float = 1.0e4
    max_nodes: int = 200_000
    tail_clamp: str = MODEL["tail_clamp"]
    snap_length: float | None = None
    flow_profile: str = MODEL["flow_profile"]
    contact: ContactOptions = field(default_factory=ContactOptions)
    newton: NewtonOptions = field(default_factory=lambda: NewtonOptions(**NEWTON))

    def __post_init__(self) -> None:
        if self.dt is not None and not (math.isfinite(self.dt) and self.dt > 0):
            raise ValueError(f"dt must be finite and > 0, got {self.dt!r}")
        if not (math.isfinite(self.dt_factor) and self.dt_factor > 0):
            raise ValueError(f"dt_factor must be finite and > 0, got {self.dt_factor!r}")
        cap = self.dt_hbar_cap
        if not (
            cap is None
            or cap == "substrate"
            or (
                isinstance(cap, (int, float))
                and not isinstance(cap, bool)
                and math.isfinite(cap)
                and cap > 0
            )
        ):
            raise ValueError(
                "dt_hbar_cap must be finite and > 0, None (no cap) or 'substrate' (the "
                f"substrate's presets.STEP_HBAR_CAP), got {cap!r}"
            )
        p = self.params
        if not (math.isfinite(self.initial_radius) and self.initial_radius > 2 * p.delta_bar):
            raise ValueError(
                f"initial_radius must exceed 2 delta_bar = {2 * p.delta_bar}, got "
                f"{self.initial_radius!r}; refine delta_bar or enlarge the arc"
            )
        if self.initial_radius >= p.Hbar:
            raise ValueError("initial_radius must be below Hbar")
        # (with a relative slack of 1e-9, so that h = delta^2 passes whatever the rounding)
        if (self.contact.adhesion == "cohesive"
                and self.contact.cohesive_range < p.delta_bar**2 * (1 - 1e-9)):  # fmt: skip
            # a rod leaving the substrate with a curvature ~1 / L_vb rises ~delta^2 / 2 over
            # its first edge: a shorter range leaves the contact node out of reach and the
            # deposition stalls (coil, h = 0.02 at delta 0.2: the node hovers at y ~ 0.025)
            raise ValueError(
                f"the cohesive range {self.contact.cohesive_range:g} L_vb is not resolved "
                f"by delta_bar = {p.delta_bar:g}: it must be at least delta_bar^2 = "
                f"{p.delta_bar**2:g}; refine delta_bar or widen cohesive_range"
            )
        # the solved rod: the suspended part (~Hbar + the start-up arc, at the injection
        # spacing) and the deposited tail; refuse before allocating what cannot run
        if not (isinstance(self.max_nodes, int) and self.max_nodes >= 16):
            raise ValueError(f"max_nodes must be an int >= 16, got {self.max_nodes!r}")
        inject = self.coarse_delta or p.delta_bar
        fine = min(self.fine_length, p.Hbar) / p.delta_bar
        estimate = fine + (p.Hbar + self.initial_radius) / inject + self.tail_length / p.delta_bar
        if estimate > self.max_nodes:
            raise ValueError(
                f"this configuration needs ~{estimate:.3g} rod nodes (Hbar = {p.Hbar:g}, "
                f"delta_bar = {p.delta_bar:g}), more than max_nodes = {self.max_nodes}: "
                "coarsen delta_bar (or coarse_delta), lower Hbar, or raise max_nodes if "
                "you have the memory and time"
            )
        if self.flow_profile not in FLOW_PROFILES:
            raise ValueError(
                f"flow_profile must be one of {list(FLOW_PROFILES)}, got {self.flow_profile!r}"
            )
        check_sliding_options(
            self.sliding, self.friction, self.snap, self.snap_stiffness, self.tail_clamp,
            self.snap_length,
        )  # fmt: skip
        if not (self.tail_length > 4 * p.delta_bar):
            raise ValueError(f"tail_length must exceed 4 delta_bar, got {self.tail_length!r}")
        ratio = math.nan if self.coarse_delta is None else self.coarse_delta / p.delta_bar
        if self.coarse_delta is not None and not (
            math.isfinite(ratio)  # a huge coarse_delta over a small delta overflows to inf
            and self.coarse_delta >= p.delta_bar
            and abs(ratio - round(ratio)) < 1e-9
        ):
            raise ValueError(
                f"coarse_delta must be a whole multiple of delta_bar = {p.delta_bar}, got "
                f"{self.coarse_delta!r}"
            )
        if self.coarse_delta is not None and self.coarse_delta > p.Hbar:
            raise ValueError(
                f"coarse_delta = {self.coarse_delta!r} is longer than the rod (Hbar = "
                f"{p.Hbar:g}): an injected edge must fit under the top; use a few L_vb"
            )
        if not (math.isfinite(self.fine_length) and self.fine_length > 0):
            raise ValueError(f"fine_length must be finite and > 0, got {self.fine_length!r}")
        if not (math.isfinite(self.perturbation) and self.perturbation >= 0):
            raise ValueError(f"perturbation must be finite and >= 0, got {self.perturbation!r}")

    @property
    def time_step(self) -> float:
        if self.dt is not None:
            return self.dt
        cap = self.step_hbar_cap
        return self.dt_factor * (self.params.Hbar if cap is None else min(self.params.Hbar, cap))

    @property
    def step_hbar_cap(self) -> float | None:
        """``dt_hbar_cap`` resolved: the substrate's ``presets.STEP_HBAR_CAP`` by default."""
        if self.dt_hbar_cap == "substrate":
            return STEP_HBAR_CAP["stepped" if self.params.is_stepped else "flat"]
        return self.dt_hbar_cap

    def with_params(self, **changes: float) -> DepositionConfig:
        return replace(self, params=replace(self.params, **changes))


@njit(cache=True)
def _next_coarse(rest_lengths: np.ndarray, j: int, end: int, arc: float, fine_length: float,
                 delta: float) -> tuple[int, float]:  # fmt: skip
    """Walk edges j, j+1, ... < end adding their rest lengths to ``arc`` while it is below
    ``fine_length``; return the first coarse edge met (round(l / delta) > 1) and the arc
    before it, or -1. The operations of DepositionSim._refine's walk, in its order."""
    while j < end and arc < fine_length:
        if round(rest_lengths[j] / delta) > 1:
            return j, arc
        arc += rest_lengths[j]
        j += 1
    return -1, arc


@njit(cache=True)
def _n_beyond(rest_lengths: np.ndarray, n_deposited: int, tail_length: float) -> int:
    """How many of the first ``n_deposited`` nodes lie more than ``tail_length`` of arc
    behind the contact node (node ``n_deposited``): node i is sum(rest_lengths[i:
    n_deposited]) behind, summed from the newest edge (as np.cumsum of the reversed
    lengths, so the same bits)."""
    behind = 0.0
    count = 0
    for i in range(n_deposited - 1, -1, -1):
        behind += rest_lengths[i]
        if behind > tail_length:
            count += 1
    return count


class DepositionSim:
    """Stateful deposition simulator (see module docstring)."""

    rod: Rod
    n_deposited: int  # deposited nodes still in the rod (at its front)
    beta0: float  # angle of the contact edge when its lower node touched down
    time: float
    vdw_work: float  # work done by the vdW force on contact nodes (e_v L_vb)

    def __init__(self, config: DepositionConfig, seed: int | None = 0) -> None:
        self.config = config
        self.params = p = config.params
        self.substrate: Substrate = (
            FlatSticky()
            if p.kappa_c_bar is None
            else Stepped(
                kappa_c=p.kappa_c_bar,
                sliding=config.sliding,
                tail_length=config.tail_length,
                friction=config.friction,
                snap=config.snap,
                snap_stiffness=config.snap_stiffness,
                tail_clamp=config.tail_clamp,
                snap_length=config.snap_length,
            )
        )
        self.delta = p.delta_bar
        self.dt = config.time_step
        material = RodMaterial(
            k_s=p.stretch_stiffness, k_b=p.bend_stiffness, k_t=p.twist_stiffness,
            rho=p.mass_per_length, r0=p.r0_bar,
        )  # fmt: skip
        shear = 1.0 / p.Hbar if config.flow_profile == "linear" else 0.0  # DragParams.shear
        drag = DragParams(mu=p.drag_mu, sigma=p.sigma, c_sigma=p.c_sigma, law=config.drag_law,
                          shear=shear)  # fmt: skip
        rng = np.random.default_rng(seed)
        self.inject_delta = config.coarse_delta or self.delta
        nodes, rest = initial_shape(p.Hbar, config.initial_radius, self.delta,
                                    self.inject_delta, config.fine_length)  # fmt: skip
        n_dep = 2  # nodes 0 and 1 lie on the substrate: the clamp of the deposited trace
        nodes[n_dep:, 2] += (
            config.perturbation * self.delta * rng.standard_normal(len(nodes) - n_dep)
        )
        self.rod = Rod(nodes, material, drag=drag, options=config.newton, rest_lengths=rest,
                       max_nodes=len(nodes) + 64)  # fmt: skip
        self.rod.flow[:] = p.flow_velocity
        self.rod.vdw[VDW_DELTA] = self.delta
        self.rod.vdw[VDW_CLAMP] = config.contact.sqrt_clamp
        self.rod.vdw[VDW_ENERGY] = p.vdw_energy
        self.cohesive = config.contact.adhesion == "cohesive"
        self.rod.vdw[VDW_MODEL] = ADHESION_MODELS[config.contact.adhesion]
        self.rod.vdw[VDW_RANGE] = config.contact.cohesive_range
        self.n_deposited = 0
        self.snapped = np.zeros(self.rod.max_nodes, dtype=bool)  # per rod edge (stepped)
        self.snaps = 0
        self._deposited_length = -self.delta  # node 0 -> 1 is the initial clamp, not laid
        self._trace = np.zeros((1024, 3))
        self._n_archived = 0
        self.time = 0.0
        self.vdw_work = 0.0
        self.sticking_loss = 0.0  # kinetic energy discarded by sticking nodes (e_v L_vb)
        self.events = 0
        self.event_failures = 0  # touchdown searches that did not land within tol
        self.immediate_deposits = 0
        for i in range(n_dep):
            self._deposit(i)
        self._clamp_oldest()  # the oldest node on the substrate is the clamp (any substrate)
        self.beta0 = 0.0  # not armed yet
        self._settle_contact()

    # ---- geometry of the contact ---------------------------------------------------
    @property
    def contact_node(self) -> int:
        return self.n_deposited

    def _contact_angle(self) -> float:
        """Signed angle beta of edge c-1 -> c to the substrate: atan2(y_c, h) with h the
        edge's projection on the last deposited edge's direction (so beta > pi/2 when the
        edge folds back over the trace; sin(beta) = y/delta cannot tell)."""
        q = self.rod.q
        c = self.contact_node
        a, b = 4 * (c - 1), 4 * c
        e = q[b : b + 3] - q[a : a + 3]
        prev = q[a : a + 3] - q[a - 4 : a - 1]
        prev[1] = 0.0
        h = numerics.dot(e, prev) / numerics.norm(prev)
        return math.atan2(e[1], h)

    # ---- deposition, injection, deletion ------------------------------------------
    def _deposit(self, node: int) -> None:
        assert node == self.n_deposited
        i = 4 * node
        self.sticking_loss += 0.5 * numerics.dot(
            self.rod.mass[i : i + 3], self.rod.u[i : i + 3] ** 2
        )
        self.substrate.deposit(self.rod, node)
        if node >= 1:
            self.rod.fix_theta(node - 1)  # both nodes of edge node-1 are down
            self._deposited_length += self.rod.rest_lengths[node - 1]
        self.n_deposited += 1

    def _settle_contact(self) -> None:
        """Deposit contact nodes that are down (or whose edge is already flat), then arm
        the vdW force on the new contact node with its beta0 (docs/model.md §4)."""
        cfg = self.config.contact
        rod = self.rod
        if self.cohesive:  # every free node in range is pulled: deposit those that landed
            while (self.contact_node < rod.n_nodes - 2
                   and rod.q[4 * self.contact_node + 1] <= self._landing_tol()):  # fmt: skip
                self._deposit(self.contact_node)
            rod.vdw[VDW_NODE] = self.contact_node
            return
        armed = self.contact_node
        while self.contact_node < rod.n_nodes - 2:
            c = self.contact_node
            if c == armed and rod.q[4 * c + 1] <= self._landing_tol():
                self._deposit(c)
                continue
            if rod.q[4 * c + 1] <= 0.0:
                self._deposit(c)
                continue
            if c == armed and self.beta0 > 0.0:
                break  # still descending: beta0 stays what it was at the touchdown of c-1
            beta = self._contact_angle()
            if beta < cfg.beta0_min:
                self.immediate_deposits += 1
                self._deposit(c)
                continue
            self.beta0 = beta
            break
        rod.vdw[VDW_NODE] = self.contact_node
        rod.vdw[VDW_BETA0] = self.beta0

    def _inject(self) -> None:
        """Append nodes at the free top while it is below H - delta (docs/model.md §4)."""
        rod = self.rod
        while True:
            n = rod.n_nodes
            top = rod.q[4 * (n - 1) : 4 * (n - 1) + 3]
            if top[1] >= self.params.Hbar - self.inject_delta:
                return
            prev = rod.q[4 * (n - 2) : 4 * (n - 2) + 3]
            t = (top - prev) / numerics.norm(top - prev)
            d = self.inject_delta
            if n >= self.config.max_nodes:
                raise SimulationError(
                    f"the rod reached max_nodes = {self.config.max_nodes} nodes (the suspended "
                    "part keeps growing: is the contact lost?)",
                    rod.steps, self.time, self.dt, rod.snapshot(),
                )  # fmt: skip
            rod.append_node(top + d * t, rod.u[4 * (n - 1) : 4 * (n - 1) + 3].copy(), d)

    def _refine(self) -> None:
        """Split coarse edges that came within ``fine_length`` of the contact node."""
        if self.inject_delta == self.delta:
            return
        rod = self.rod
        arc = 0.0
        j = self.contact_node - 1
        while True:  # the walk over the fine edges is compiled (_next_coarse)
            j, arc = _next_coarse(rod.rest_lengths, j, rod.n_nodes - 1, arc,
                                  self.config.fine_length, self.delta)  # fmt: skip
            if j < 0:
                return
            rod.split_edge(j, round(rod.rest_lengths[j] / self.delta))
            arc += rod.rest_lengths[j]
            j += 1

    def _delete(self) -> None:
        """Archive and drop deposited nodes the solve no longer needs: on the sticky
        substrate all but the last ``keep_deposited``; on the stepped one those more than
        ``tail_length`` of arc behind the contact node. The oldest kept node is clamped."""
        rod = self.rod
        if self.substrate.tail_length == math.inf:
            extra = self.n_deposited - self.substrate.keep_deposited
        else:
            extra = _n_beyond(rod.rest_lengths, self.n_deposited, self.substrate.tail_length)
            extra = min(extra, self.n_deposited - 2)
        if extra <= 0:
            return
        self._archive(rod.nodes[:extra])
        rod.drop_front(extra)
        self.n_deposited -= extra
        keep = len(self.snapped) - extra
        self.snapped[:keep] = self.snapped[extra:].copy()
        self.snapped[keep:] = False
        self._clamp_oldest()
        rod.vdw[VDW_NODE] = self.contact_node

    def _clamp_oldest(self) -> None:
        """Clamp the oldest retained node: x, y and z, or x and y only when the stepped
        substrate's ``tail_clamp`` is "xy" (the steps do not vary along z, so a clamp in z
        would pin the sliding trace to the lab frame)."""
        rod = self.rod
        k = 2 if getattr(self.substrate, "tail_clamp", "xyz") == "xy" else 3
        rod.fixed[0:k] = 1
        rod.u[0:k] = 0.0

    def _archive(self, points: np.ndarray) -> None:
        n = self._n_archived
        k = len(points)
        if n + k > len(self._trace):
            grown = np.zeros((max(2 * len(self._trace), n + k), 3))
            grown[:n] = self._trace[:n]
            self._trace = grown
        self._trace[n : n + k] = points
        self._n_archived = n + k

    # ---- stepping -----------------------------------------------------------------
    def _light_state(self) -> tuple:
        r = self.rod
        nd = r.n_dof
        ne = r.n_nodes - 1
        return (
            r.q[:nd].copy(), r.u[:nd].copy(), r.tangents_old[:ne].copy(), r.d1_old[:ne].copy(),
            r.ref_twist_old[: r.n_nodes].copy(), r.time, r.steps,
        )  # fmt: skip

    def _restore_light(self, s: tuple) -> None:
        r = self.rod
        nd = r.n_dof
        ne = r.n_nodes - 1
        r.q[:nd], r.u[:nd], r.tangents_old[:ne], r.d1_old[:ne] = s[0], s[1], s[2], s[3]
        r.ref_twist_old[: r.n_nodes] = s[4]
        r.time, r.steps = s[5], s[6]

    def step(self, dt: float | None = None) -> float:
        """One implicit step (touchdown-located in event mode), then contact, injection and
        deletion. Returns the time advanced. Raises SimulationError on solver failure."""
        dt = self.dt if dt is None else dt
        rod = self.rod
        cfg = self.config.contact
        k_y = 4 * self.contact_node + 1
        y_before = rod.q[k_y]
        f_before = 0.0 if self.cohesive else self._vdw_force(y_before)
        e_before = self._adhesion_energy()
        state = self._light_state() if cfg.mode == "event" else None
        rod.step(dt)
        taken = dt
        tol = self._landing_tol()
        if cfg.mode == "event" and rod.q[k_y] < -tol:
            # touchdown inside the step: Illinois (modified regula falsi) on the step
            # length, each trial taken from the step start, until the contact node lands
            # within tol of y = 0. If the search does not converge, the step is retaken to
            # the last time the node was still above the substrate (never accept a deep
            # penetration: its kinetic energy would be discarded by sticking).
            self.events += 1
            lo, y_lo, hi, y_hi = 0.0, y_before, dt, rod.q[k_y]
            side = 0
            landed = False
            for _ in range(cfg.max_event_iterations):
                trial = lo + (hi - lo) * y_lo / (y_lo - y_hi)
                trial = min(max(trial, lo + 0.01 * (hi - lo)), hi - 0.01 * (hi - lo))
                self._restore_light(state)
                rod.step(trial)
                taken = trial
                y = rod.q[k_y]
                if abs(y) <= tol:
                    landed = True
                    break
                if y > 0:
                    lo, y_lo = trial, y
                    if side == 1:
                        y_hi *= 0.5
                    side = 1
                else:
                    hi, y_hi = trial, y
                    if side == -1:
                        y_lo *= 0.5
                    side = -1
            if not landed:
                self.event_failures += 1
                self._restore_light(state)
                if lo > 0.0:
                    rod.step(lo)
                    taken = lo
                else:  # even the shortest step overshoots: take it and project
                    rod.step(hi)
                    taken = hi
        y_after = rod.q[k_y]
        if self.cohesive:  # the adhesion's energy is exact: its work is its fall
            self.vdw_work += e_before - self._adhesion_energy()
        else:  # vdW work over the step (trapezoid in y): the energy the adhesion released
            self.vdw_work += 0.5 * (f_before + self._vdw_force(y_after)) * (y_after - y_before)
        self.time = rod.time
        if len(self.snapped) < rod.max_nodes:
            self.snapped = np.concatenate(
                [self.snapped, np.zeros(rod.max_nodes - len(self.snapped), dtype=bool)]
            )
        self.snaps += self.substrate.after_step(rod, self.n_deposited, self.snapped)
        self._settle_contact()
        self._inject()
        self._refine()
        self._delete()
        return taken

    def _landing_tol(self) -> float:
        """|y_c| within which a touchdown counts as landed: relative to the contact node's
        start height delta sin(beta0), since an overshoot below 0 adds
        (e_v delta / beta0) |beta| of spurious vdW work. Cohesive: relative to the range."""
        if self.cohesive:
            return self.config.contact.event_tol * self.config.contact.cohesive_range
        return self.config.contact.event_tol * self.delta * math.sin(max(self.beta0, 1e-12))

    def _adhesion_energy(self) -> float:
        """The cohesive model's adhesion energy now (0 for eq. 1, whose work is summed)."""
        if not self.cohesive:
            return 0.0
        r = self.rod
        return adhesion_energy(r.q, r.n_nodes, r.voronoi_lengths, r.vdw)

    def _vdw_force(self, y: float) -> float:
        """F_y on the contact node at height y (forces.vdw_pull, as in the solve)."""
        v = self.rod.vdw
        return vdw_pull(y, v[VDW_BETA0], v[VDW_DELTA], v[VDW_CLAMP], v[VDW_ENERGY])[0]

    def advance(self, duration: float) -> None:
        """Advance by ``duration`` with the configured dt (the last step is shortened)."""
        end = self.time + duration
        while self.time < end - 1e-12 * max(1.0, abs(end)):
            self.step(min(self.dt, end - self.time))

    def run(self, deposit_length: float, progress=None, max_time: float | None = None) -> None:
        """Step until ``deposit_length`` (L_vb) of trace is laid; ``progress(done, total)``
        is called after each step."""
        while self.deposited_length < deposit_length:
            if max_time is not None and self.time >= max_time:
                raise SimulationError(
                    f"deposited only {self.deposited_length:.1f} L_vb by t = {self.time:.4g}",
                    self.rod.steps, self.time, self.dt, self.rod.snapshot(),
                )  # fmt: skip
            self.step()
            if progress is not None:
                progress(min(self.deposited_length, deposit_length), deposit_length)

    def set_flow(self, vbar: float, phi: float) -> None:
        """Change the flow between steps: speed vbar (units of e_v/(mu H); with
        ``flow_profile`` "linear", the flow at the rod's top), direction phi."""
        if not (math.isfinite(vbar) and vbar >= 0 and math.isfinite(phi)):
            raise ValueError(f"flow must be finite with vbar >= 0, got vbar={vbar}, phi={phi}")
        s = vbar / self.params.Hbar
        self.rod.flow[:] = (s * math.cos(phi), 0.0, s * math.sin(phi))

    # ---- outputs --------------------------------------------------------------------
    def trace(self) -> np.ndarray:
        """Every deposited node so far, in order of deposition, (n, 3)."""
        return np.concatenate([self._trace[: self._n_archived],
                               self.rod.nodes[: self.n_deposited]])  # fmt: skip

    @property
    def n_trace(self) -> int:
        return self._n_archived + self.n_deposited

    @property
    def deposited_length(self) -> float:
        """Rest arc length of trace laid since the start (the initial clamp edge excluded)."""
        return self._deposited_length

    @property
    def suspended_nodes(self) -> np.ndarray:
        """The free part of the rod, from the contact node to the top, (m, 3)."""
        return self.rod.nodes[self.n_deposited :]

    def stats(self) -> dict:
        r = self.rod
        return {
            "time": self.time, "steps": r.steps, "newton_iterations": r.newton_iterations,
            "halvings": r.halvings, "events": self.events,
            "event_failures": self.event_failures,
            "immediate_deposits": self.immediate_deposits, "n_nodes": r.n_nodes,
            "deposited_length": self.deposited_length, "vdw_work": self.vdw_work,
            "sticking_loss": self.sticking_loss, "snaps": self.snaps,
        }  # fmt: skip

    # ---- exact snapshot and restore ---------------------------------------------------
    def snapshot(self) -> dict:
        return {
            "rod": self.rod.snapshot(), "n_deposited": self.n_deposited, "beta0": self.beta0,
            "deposited_length": self._deposited_length, "snapped": self.snapped.copy(),
            "snaps": self.snaps,
            "trace": self._trace[: self._n_archived].copy(), "time": self.time,
            "vdw_work": self.vdw_work, "events": self.events, "sticking_loss": self.sticking_loss,
            "event_failures": self.event_failures,
            "immediate_deposits": self.immediate_deposits,
        }  # fmt: skip

    def restore(self, snap: dict) -> None:
        self.rod.restore(snap["rod"])
        self.n_deposited = snap["n_deposited"]
        self.beta0 = snap["beta0"]
        self._deposited_length = snap["deposited_length"]
        self.snapped = snap["snapped"].copy()
        self.snaps = snap["snaps"]
        self._trace = np.zeros((max(1024, 2 * len(snap["trace"])), 3))
        self._n_archived = 0
        self._archive(snap["trace"])
        self.time = snap["time"]
        self.vdw_work = snap["vdw_work"]
        self.sticking_loss = snap["sticking_loss"]
        self.events = snap["events"]
        self.event_failures = snap["event_failures"]
        self.immediate_deposits = snap["immediate_deposits"]


def z_mirrored(snap: dict) -> dict:
    """The mirror image in z (z -> -z) of a :meth:`DepositionSim.snapshot`, for the same
    configuration: a state of the same simulator, which lays the mirrored trace under the
    mirrored flow (phi -> -phi; both substrates, the rod and the drag are symmetric under
    it; tests/test_deposition.py). The reflection is improper, so the twist angles change
    sign with the z components: theta (the material frame's angle from the reference
    director d1, with d2 = t x d1) and the reference twist; a DOF's generalised force,
    velocity and anchor follow its coordinate."""
    rod = {k: (v.copy() if isinstance(v, np.ndarray) else v) for k, v in snap["rod"].items()}
    for key in ("q", "u", "ext_force", "sub_anchor"):  # (x, y, z, theta) per node
        dof = rod[key].reshape(-1, 4)
        dof[:, 2:] *= -1.0
    for key in ("tangents_old", "d1_old"):
        rod[key][:, 2] *= -1.0
    rod["flow"][2] *= -1.0
    rod["ref_twist_old"] *= -1.0
    trace = snap["trace"].copy()
    trace[:, 2] *= -1.0
    return {**snap, "rod": rod, "trace": trace, "snapped": snap["snapped"].copy()}


def initial_shape(
    height: float,
    radius: float,
    delta: float,
    coarse_delta: float | None = None,
    fine_length: float = math.inf,
) -> tuple[np.ndarray, np.ndarray]:
    """Start-up state (docs/model.md §4): a node on the substrate behind the origin, an arc
    of radius R_i from flat to vertical, then a vertical straight part up to y = height.
    Consecutive nodes are exactly delta apart (chords); with ``coarse_delta``, spacing
    switches to it once the arc length from the origin exceeds ``fine_length``.
    Returns the nodes and the nominal rest lengths of the edges."""
    coarse = coarse_delta or delta
    pts = [np.array([-delta, 0.0, 0.0]), np.array([0.0, 0.0, 0.0])]
    rest = [delta]
    dphi = 2.0 * math.asin(delta / (2.0 * radius))
    phi = dphi
    while phi < 0.5 * math.pi:
        pts.append(np.array([radius * math.sin(phi), radius * (1.0 - math.cos(phi)), 0.0]))
        rest.append(delta)
        phi += dphi
    last = pts[-1]
    arc = (len(pts) - 2) * delta
    dx = radius - last[0]  # first vertical node: on x = radius, delta from the last arc node
    y = last[1] + math.sqrt(max(delta * delta - dx * dx, 0.0))
    step = delta
    while y <= height + 1e-9:
        pts.append(np.array([radius, y, 0.0]))
        rest.append(step)
        step = delta if arc < fine_length else coarse
        arc += step
        y += step
    return np.array(pts), np.array(rest)


def default_config(preset: str, **changes) -> DepositionConfig:
    """The validated configuration of a preset (``units.paper_groups`` groups, mesh and
    start-up from ``presets.MESH``); ``changes`` go to DimensionlessParams fields or
    DepositionConfig fields, by name. The preset's graded mesh follows a changed
    ``delta_bar`` (``presets.graded_coarse``); ``coarse_delta=None`` makes the rod uniform."""
    from dataclasses import fields

    from cnt_env.presets import graded_coarse, mesh_for
    from cnt_env.units import paper_groups

    d = mesh_for(preset)
    param_names = {f.name for f in fields(DimensionlessParams)}
    groups = {k: v for k, v in changes.items() if k in param_names}
    rest = {k: v for k, v in changes.items() if k not in param_names}
    params = paper_groups(preset, **{"delta_bar": d["delta_bar"], **groups})
    if "coarse_delta" not in rest:
        rest["coarse_delta"] = graded_coarse(d["coarse_delta"], params.delta_bar)
    rest.setdefault("fine_length", d["fine_length"])
    rest.setdefault("initial_radius", d["initial_radius"])
    return DepositionConfig(params=params, **rest)

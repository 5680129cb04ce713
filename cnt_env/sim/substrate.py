"""Substrates: what happens to a node once it is deposited (docs/model.md §5).

A substrate decides which DOFs of a deposited node stay free, which deposited nodes stay
in the solve, and whether deposited edges reorient after a step. The simulator
(``deposition.py``) calls these hooks; per-edge substrate state (``snapped``) is an array
the simulator owns and shifts with the rod, indexed like the rod's edges.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from numba import njit

from cnt_env import numerics
from cnt_env.sim.stepper import Rod

SLIDING_OPTIONS = ("B", "C", "none")
#: How a snap (critical-curvature rule) is applied [choice]: "jump" moves the edge's newer
#: node onto the step line (x and z, keeping the edge length) between steps; "constraint"
#: prescribes only its x (fixed at the snapped value) and lets the next implicit solve
#: restore the length; "penalty" adds a stiff spring in x to the snapped line inside the
#: solve (forces.add_substrate), so nothing jumps.
SNAP_OPTIONS = ("jump", "constraint", "penalty")
#: DOFs of the oldest retained deposited node that are clamped: "xyz", or "xy" (z slides
#: like every other deposited node: the steps do not vary along z).
TAIL_CLAMP_OPTIONS = ("xyz", "xy")


def check_sliding_options(
    sliding: str,
    friction: float,
    snap: str,
    snap_stiffness: float,
    tail_clamp: str,
    snap_length: float | None = None,
) -> None:
    """Validate the stepped substrate's named options (raises ValueError naming the field);
    shared by :class:`Stepped` and ``DepositionConfig``."""
    if sliding not in SLIDING_OPTIONS:
        raise ValueError(f"sliding must be one of {SLIDING_OPTIONS}, got {sliding!r}")
    if not (math.isfinite(friction) and friction >= 0):
        raise ValueError(f"friction must be finite and >= 0, got {friction!r}")
    if snap not in SNAP_OPTIONS:
        raise ValueError(f"snap must be one of {SNAP_OPTIONS}, got {snap!r}")
    if not (math.isfinite(snap_stiffness) and snap_stiffness > 0):
        raise ValueError(f"snap_stiffness must be finite and > 0, got {snap_stiffness!r}")
    if tail_clamp not in TAIL_CLAMP_OPTIONS:
        raise ValueError(f"tail_clamp must be one of {TAIL_CLAMP_OPTIONS}, got {tail_clamp!r}")
    if snap_length is not None and not (math.isfinite(snap_length) and snap_length > 0):
        raise ValueError(f"snap_length must be None or finite and > 0, got {snap_length!r}")


@dataclass(frozen=True)
class FlatSticky:
    """Flat sticky substrate (static coils): a deposited node is fixed in x, y and z.

    A frictionless flat substrate gives no coils; stickiness stands in for roughness.
    Only the last ``keep_deposited`` deposited nodes influence the free rod (the bending
    stencil of node c-1 reaches back to c-2), so older ones leave the solve.
    """

    name: str = "flat"
    keep_deposited: int = 2
    tail_length: float = math.inf

    def deposit(self, rod: Rod, node: int) -> None:
        """Project node onto y = 0, stop it, and fix all three coordinates."""
        i = 4 * node
        rod.q[i + 1] = 0.0
        rod.u[i : i + 3] = 0.0
        rod.fixed[i : i + 3] = 1

    def after_step(self, rod: Rod, n_deposited: int, snapped: np.ndarray) -> int:
        """Nothing moves on a sticky substrate. Returns the number of edges snapped (0)."""
        return 0


@dataclass(frozen=True)
class Stepped:
    """Substrate with steps along z (serpentines), docs/model.md §5.

    A deposited node keeps y = 0 and slides along the steps (z). A deposited edge e
    snaps into the steps when |e.x| < kappa_c delta |e.z| (the small-angle form of
    2 tan(psi/2) < kappa_c delta, psi the angle between e and z): it is turned along z
    keeping its length, by moving its newer node (edges are processed oldest first, so
    a chain of snapped edges stays aligned). ``sliding`` [choice]:

    * ``"B"``: deposited nodes are fixed in x from touchdown and free in z;
    * ``"C"``: deposited nodes are free in x and z until their edge snaps, then fixed
      in x;
    * ``"none"``: deposited nodes are fixed in x and z (no sliding; a snap still turns
      the edge).

    Deposited nodes stay in the solve (they slide, and drag acts on them) up to
    ``tail_length`` of arc behind the contact; the oldest retained node is clamped.

    ``friction`` (eta >= 0, per unit length, in units of the drag coefficient mu) adds a
    viscous resistance -eta l_i u to every sliding DOF of a deposited node (z, and x while
    it is free under "C"), l_i its Voronoi length; 0 leaves only the gas drag. ``snap``
    is one of SNAP_OPTIONS; ``snap_stiffness`` (e_v / L_vb^2 per unit length) is the
    penalty spring's stiffness.

    ``snap_length`` [choice]: the length l in the rule |e.x| < kappa_c l |e.z|. None
    (default) is the edge's own length, the rule as the paper prints it with its delta ~
    L_vb: on a finer mesh its window for a straight edge, kappa_c delta radians, narrows
    with delta. A number fixes l (L_vb), so the window is the paper's at l = 1 whatever
    the mesh (RESULTS.md, issue 12, "The snap rule's length").
    """

    kappa_c: float
    sliding: str = "B"
    # a snap that would turn an edge by more than this against a neighbour is skipped:
    # it would fold the trace into a hairpin (a pi turn, where the curvature is singular)
    max_snap_turn: float = math.radians(150.0)
    tail_length: float = 195.0
    friction: float = 0.0
    snap: str = "jump"
    snap_stiffness: float = 1.0e4
    tail_clamp: str = "xyz"
    snap_length: float | None = None
    name: str = "stepped"
    keep_deposited: int = 0  # not used: the tail is kept by arc length

    def __post_init__(self) -> None:
        if not (math.isfinite(self.kappa_c) and self.kappa_c > 0):
            raise ValueError(f"kappa_c must be finite and > 0, got {self.kappa_c!r}")
        if not (self.tail_length > 0):
            raise ValueError(f"tail_length must be > 0, got {self.tail_length!r}")
        check_sliding_options(
            self.sliding, self.friction, self.snap, self.snap_stiffness, self.tail_clamp,
            self.snap_length,
        )  # fmt: skip

    def deposit(self, rod: Rod, node: int) -> None:
        i = 4 * node
        rod.q[i + 1] = 0.0
        rod.u[i + 1] = 0.0
        rod.fixed[i + 1] = 1
        if self.sliding in ("B", "none"):
            rod.u[i] = 0.0
            rod.fixed[i] = 1
        if self.sliding == "none":
            rod.u[i + 2] = 0.0
            rod.fixed[i + 2] = 1
        if self.friction > 0.0:
            eta = self.friction * rod.voronoi_lengths[node]
            rod.sub_friction[i] = eta  # only acts while x is free (fixed rows are identity)
            rod.sub_friction[i + 2] = eta

    def after_step(self, rod: Rod, n_deposited: int, snapped: np.ndarray) -> int:
        """Apply the critical-curvature rule to every deposited edge not yet snapped."""
        q = rod.q
        count = 0
        j = 0
        while True:  # the scan for edges past the rule is compiled (_next_to_snap)
            j = _next_to_snap(q, rod.rest_lengths, snapped, j, n_deposited - 1, self.kappa_c,
                              self.snap_length or 0.0)  # fmt: skip
            if j < 0:
                return count
            a, b = 4 * j, 4 * (j + 1)
            ex = q[b] - q[a]
            ez = q[b + 2] - q[a + 2]
            if not self._would_fold(q, j, math.copysign(1.0, ez), rod.n_nodes):
                self._snap(rod, j, ex, ez)
                snapped[j] = True
                count += 1
            j += 1

    def _snap(self, rod: Rod, j: int, ex: float, ez: float) -> None:
        """Turn edge j (nodes j, j+1) along z by moving its newer node (see SNAP_OPTIONS)."""
        q = rod.q
        a, b = 4 * j, 4 * (j + 1)
        if self.snap == "penalty":
            # the line x = x*: node a's prescribed (or anchored) x, else its current x
            x_star = q[a]
            if not rod.fixed[a] and rod.sub_stiffness[a] > 0.0:
                x_star = rod.sub_anchor[a]
            k = self.snap_stiffness * rod.voronoi_lengths[j + 1]
            for i in (a, b):
                if rod.fixed[i] and i == a:
                    continue
                rod.fixed[i] = 0
                rod.sub_stiffness[i] = k
                rod.sub_anchor[i] = x_star
            return
        if self.snap == "jump":
            length = math.hypot(ex, ez)
            q[b + 2] = q[a + 2] + math.copysign(length, ez)
        q[b] = q[a]
        rod.u[b] = 0.0
        for node in (j, j + 1):  # aligned with the steps: x is locked
            rod.fixed[4 * node] = 1
            rod.u[4 * node] = 0.0

    def _would_fold(self, q: np.ndarray, j: int, sz: float, n_nodes: int) -> bool:
        """Does edge j, turned to (0, 0, sz), make a turn > max_snap_turn with a neighbour?"""
        limit = math.cos(self.max_snap_turn)
        for k in (j - 1, j + 1):
            if not 0 <= k < n_nodes - 1:
                continue
            a, b = 4 * k, 4 * (k + 1)
            e = q[b : b + 3] - q[a : a + 3]
            if sz * e[2] / numerics.norm(e) < limit:
                return True
        return False


@njit(cache=True)
def _next_to_snap(q: np.ndarray, rest_lengths: np.ndarray, snapped: np.ndarray, j: int,
                  end: int, kappa_c: float, snap_length: float) -> int:  # fmt: skip
    """The first edge j' in [j, end) not yet snapped whose direction is within the
    critical-curvature rule, |e_x| < kappa_c l |e_z| (docs/model.md §5), or -1; l is
    the edge's rest length, or ``snap_length`` when > 0."""
    while j < end:
        if not snapped[j]:
            a, b = 4 * j, 4 * (j + 1)
            ell = snap_length if snap_length > 0.0 else rest_lengths[j]
            if abs(q[b] - q[a]) < kappa_c * ell * abs(q[b + 2] - q[a + 2]):
                return j
        j += 1
    return -1


Substrate = FlatSticky | Stepped

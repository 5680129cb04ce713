"""The action map both ways and the layout of the vector observation of ``CNTDeposit-v0``.

Action. ``Box(-1, 1, (2,))`` is mapped onto the disk of flows of speed <= v̄_max by the
elliptical grid map (:func:`flow_from_action`); :func:`action_from_flow` is its inverse,
for scripted policies.

Observation. :class:`ObservationLayout` names the slices of the flat vector (sizes in
``structure``), its bounds, and builds it from the simulator's arrays (the env's docstring
has the table with units).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np
from gymnasium import spaces

__all__ = [
    "ACTION_Z_MIRROR",
    "LAID_RATIO_BOUND",
    "LEAN_HEIGHTS",
    "LEAN_HEIGHT_FRACTIONS",
    "POSITION_BOUND",
    "ObservationLayout",
    "action_from_flow",
    "flow_from_action",
    "keepout_in_view",
    "rod_features",
    "trace_points",
]

#: Bound (L_vb) of every position in the vector observation; values are clipped to it.
POSITION_BOUND = 1000.0
#: Bound of the laid-length / target-length ratio in the observation.
LAID_RATIO_BOUND = 100.0
#: Heights (L_vb) at which the lean of the suspended rod is observed: two absolute ones
#: near the contact, where the next trace is shaped, and fractions of Hbar.
LEAN_HEIGHTS = (2.0, 8.0)
LEAN_HEIGHT_FRACTIONS = (0.5, 1.0)


def keepout_in_view(kx: float, kz: float) -> bool:
    """Whether an observed nearest keep-out point (kx, kz) (offsets from the contact, L_vb)
    is a keep-out. A route without one is observed at the far point (geometry.FAR in both
    offsets, clipped to (POSITION_BOUND, POSITION_BOUND)); a point at the bound in either
    offset, a keep-out at least 1000 L_vb away, reads as none too. The one test of it, for
    the keep-out gate (policies/residual.py) and the z-mirror (which keeps the far point)."""
    return max(abs(kx), abs(kz)) < POSITION_BOUND


def flow_from_action(action: np.ndarray, vbar_max: float) -> tuple[float, float]:
    """Map a clipped action in [-1, 1]^2 to a flow ``(vbar, phi)``.

    The square is mapped onto the disk of radius ``vbar_max`` by the elliptical grid
    map u = a_x sqrt(1 - a_z^2 / 2), w = a_z sqrt(1 - a_x^2 / 2): smooth, one-to-one,
    the edges' midpoints and the corners all land on the rim. (u, w) are the flow's x and
    z components over ``vbar_max``.
    """
    ax, az = float(action[0]), float(action[1])
    u = ax * math.sqrt(1.0 - 0.5 * az * az)
    w = az * math.sqrt(1.0 - 0.5 * ax * ax)
    vbar = min(vbar_max * math.hypot(u, w), vbar_max)
    phi = math.atan2(w, u) if vbar > 0.0 else 0.0
    return vbar, phi


#: Signs that map an action to the one of the flow's mirror image in z (phi -> -phi): the
#: elliptical grid map keeps the sign of each component (u ~ a_x, w ~ a_z).
ACTION_Z_MIRROR = np.array([1.0, -1.0], dtype=np.float32)


def action_from_flow(vbar: float, phi: float, vbar_max: float) -> np.ndarray:
    """The action whose flow is ``(vbar, phi)``: the inverse of :func:`flow_from_action`,
    disk -> square (Fong 2015, the "elliptical grid" inverse). float32 (2,) in [-1, 1]."""
    r = min(max(vbar / vbar_max, 0.0), 1.0)
    u, w = r * math.cos(phi), r * math.sin(phi)
    s2 = 2.0 * math.sqrt(2.0)
    d = u * u - w * w

    def half_diff(a: float, b: float) -> float:
        return 0.5 * math.sqrt(max(a, 0.0)) - 0.5 * math.sqrt(max(b, 0.0))

    x = half_diff(2.0 + d + s2 * u, 2.0 + d - s2 * u)
    z = half_diff(2.0 - d + s2 * w, 2.0 - d - s2 * w)
    return np.clip(np.array([x, z], dtype=np.float32), -1.0, 1.0)


def rod_features(nodes: np.ndarray, contact3: np.ndarray,
                 lean_heights: tuple[float, ...]) -> np.ndarray:  # fmt: skip
    """Contact height, contact-edge direction, and the rod's horizontal offset at the lean
    heights, relative to the contact point. ``nodes`` (k, 3): the suspended rod's nodes
    from the contact node up; ``contact3`` (3,): the contact point."""
    out = np.zeros(3 + 2 * len(lean_heights))
    if len(nodes) == 0:
        return out
    c = nodes[0]
    out[0] = c[1]
    h = np.array([c[0] - contact3[0], c[2] - contact3[2]])
    norm = math.hypot(h[0], h[1])
    out[1:3] = h / norm if norm > 1e-12 else (1.0, 0.0)
    ys = nodes[:, 1]
    for j, height in enumerate(lean_heights):
        above = np.flatnonzero(ys >= height)
        if above.size == 0:
            p = nodes[-1]
        elif above[0] == 0:
            p = nodes[0]
        else:
            i = above[0]
            y0, y1 = ys[i - 1], ys[i]
            t = (height - y0) / (y1 - y0) if y1 > y0 else 1.0
            p = nodes[i - 1] + t * (nodes[i] - nodes[i - 1])
        out[3 + 2 * j] = p[0] - contact3[0]
        out[4 + 2 * j] = p[2] - contact3[2]
    return out


def trace_points(xz: np.ndarray, k: int, window: float) -> np.ndarray:
    """K points (k, 2) evenly spaced in arc length over the last ``window`` L_vb of the
    trace ``xz`` (n, 2), oldest first, the last one ``window / k`` before its end (the
    start of the trace repeats where it is shorter)."""
    # not patterns.arc_length: that one rejects the non-finite state of a failed step
    s = np.concatenate([[0.0], np.cumsum(np.hypot(*np.diff(xz, axis=0).T))])
    at = s[-1] - window * (np.arange(k, 0, -1) / k)
    return np.column_stack([np.interp(at, s, xz[:, c]) for c in (0, 1)])


@dataclass(frozen=True, eq=False)
class ObservationLayout:
    """The flat vector observation: K trace points, M target points, the flow, the rod
    features at ``lean_heights``, four progress values and, with ``route``, the corridor's
    half-width and the nearest keep-out point."""

    n_trace_points: int
    n_target_points: int
    lean_heights: tuple[float, ...]
    route: bool = False
    structure: dict[str, int] = field(init=False)
    slices: dict[str, slice] = field(init=False)
    low: np.ndarray = field(init=False, repr=False)
    high: np.ndarray = field(init=False, repr=False)
    #: signs of :meth:`z_mirror` (+-1, float32): -1 on every z offset
    z_signs: np.ndarray = field(init=False, repr=False)

    def __post_init__(self) -> None:
        k, m = self.n_trace_points, self.n_target_points
        structure = {"trace": 2 * k, "target": 2 * m, "flow": 2,
                     "rod": 3 + 2 * len(self.lean_heights), "progress": 4}  # fmt: skip
        if self.route:
            # the corridor's half-width w, and the nearest keep-out point (x, z) (L_vb)
            structure["route"] = 3
        slices, start = {}, 0
        for name, size in structure.items():
            slices[name] = slice(start, start + size)
            start += size
        object.__setattr__(self, "structure", structure)
        object.__setattr__(self, "slices", slices)
        low, high = self._bounds(start)
        object.__setattr__(self, "low", low)
        object.__setattr__(self, "high", high)
        object.__setattr__(self, "z_signs", self._z_mirror_signs())

    @property
    def size(self) -> int:
        return sum(self.structure.values())

    def _bounds(self, size: int) -> tuple[np.ndarray, np.ndarray]:
        """``(low, high)`` float32 of the vector observation."""
        low = np.full(size, -POSITION_BOUND, dtype=np.float32)
        high = np.full(size, POSITION_BOUND, dtype=np.float32)
        sl = self.slices
        low[sl["flow"]], high[sl["flow"]] = -1.0, 1.0
        rod = sl["rod"]
        low[rod.start + 1 : rod.start + 3], high[rod.start + 1 : rod.start + 3] = -1.0, 1.0
        prog = sl["progress"]
        low[prog] = 0.0
        high[prog.start : prog.start + 3] = 1.0
        high[prog.start + 3] = LAID_RATIO_BOUND
        if self.route:
            low[sl["route"].start] = 0.0
        return low, high

    def space(self) -> spaces.Box:
        return spaces.Box(self.low, self.high, dtype=np.float32)

    def z_mirror(self, obs: np.ndarray) -> np.ndarray:
        """The observation (float32) of the mirror image in z (z -> -z) of the state
        ``obs`` (d,) observes: every z offset changes sign (trace and target points, the
        flow's z, the contact edge's and the lean's z, the nearest keep-out point's z);
        heights, progress values and the corridor's width do not, nor does the point that
        stands for no keep-out (:func:`keepout_in_view`). The simulator is
        symmetric under it to the last bit (both substrates, the rod, the drag), and so is
        the env with ``start_mirror`` (tests/test_env.py): this is the observation of the
        mirrored episode."""
        obs = np.asarray(obs, dtype=np.float32)
        if obs.shape != (self.size,):
            raise ValueError(f"z_mirror needs one observation of shape ({self.size},), "
                             f"got {obs.shape}")  # fmt: skip
        out = obs * self.z_signs
        if self.route:
            k = self.slices["route"].start + 1  # w, keep-out (x, z)
            if not keepout_in_view(obs[k], obs[k + 1]):
                out[k + 1] = obs[k + 1]  # no keep-out: the far point stays where it is
        return out

    def _z_mirror_signs(self) -> np.ndarray:
        signs = np.ones(self.size, dtype=np.float32)
        sl = self.slices
        for name in ("trace", "target", "flow"):
            signs[sl[name].start + 1 : sl[name].stop : 2] = -1.0  # (x, z) pairs
        rod = sl["rod"]  # height, edge (x, z), lean (x, z) per height
        signs[rod.start + 2 : rod.stop : 2] = -1.0
        if self.route:
            signs[sl["route"].start + 2] = -1.0  # w, keep-out (x, z)
        return signs

    def build(self, trace: np.ndarray, ahead: np.ndarray, flow_xz: np.ndarray,
              rod: np.ndarray, progress: np.ndarray, trace_window: float | None = None,
              route: np.ndarray | None = None) -> np.ndarray:  # fmt: skip
        """The observation from ``trace`` (n, 3) (the last node is the contact point),
        the M target points ``ahead`` (M, 2) absolute, the flow over v̄_max (2,), the
        :func:`rod_features`, the four progress values and, with a route, ``route`` =
        (w, x, z of the nearest keep-out point, absolute); clipped to the bounds.

        The K trace points: with ``trace_window`` None the last K nodes before the contact
        point (padded with the oldest while shorter); else K points evenly spaced in arc
        length over the last ``trace_window`` L_vb of trace, ending one spacing before the
        contact point (their mean is the pattern's centre)."""
        contact = trace[-1, [0, 2]]
        k = self.n_trace_points
        if trace_window is None:
            past = trace[max(0, len(trace) - 1 - k) : len(trace) - 1][:, [0, 2]] - contact
            if len(past) == 0:
                past = np.zeros((1, 2))
            if len(past) < k:
                past = np.concatenate([np.repeat(past[:1], k - len(past), axis=0), past])
        else:
            past = trace_points(trace[:, [0, 2]], k, trace_window) - contact
        parts = [past.ravel(), (ahead - contact).ravel(), flow_xz, rod, progress]
        if self.route:
            parts.append(np.asarray(route, dtype=float) - [0.0, *contact])
        return self.clip(np.concatenate(parts))

    def clip(self, obs: np.ndarray) -> np.ndarray:
        """``obs`` clipped to the bounds, as float32."""
        return np.clip(obs, self.low, self.high).astype(np.float32)

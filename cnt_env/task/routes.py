"""Circuit routes for ``CNTDeposit-v0`` task mode ``score="corridor"`` (docs/task.md).

A :class:`Route` is how a CNT interconnect is specified and what the flow can draw: a
polyline of waypoints in the substrate plane (x, z) in L_vb, starting at the origin (the
env places it at the contact point at reset), a corridor of half-width ``width`` around
it, optional ``pads`` (segments the trace must cross, like electrodes; with a
``pad_width`` > 0, strips of that width the trace must touch) and optional ``keepouts``
(polygons the trace must not enter, like a neighbouring wire).

The corridor's default half-width, :data:`DEFAULT_HALF_WIDTH`, comes from the measured
band widths (``benchmarks/results/step_response_surrogate.json``): a constant flow across the steps
lays a serpentine band 34 L_vb peak-to-peak at v̄ = 0.13, 37 at 0.1 and 51 at 0.065 (36, 33
and 47, then 35, 34 and 49, then 35, 32 and 32 with the env's graded rod, re-measured on
the shipped simulator, docs/task.md); along
the steps an almost straight run. A corridor of half-width 18.5 holds the narrowest band
(v̄ = v̄_max) with a little room to steer. Route lengths scale with it
(:data:`ROUTE_SCALE`).

Families (drawn by :func:`sample` with the env's ``np_random`` and a ``difficulty`` in
[0, 1] that lengthens the route, adds turns and narrows the corridor; ranges below):

==============  ==========================================================================
family          shape
==============  ==========================================================================
``straight``    one run in any direction
``l_route``     Manhattan L: two legs at a right angle (the first leg axis-aligned)
``u_route``     Manhattan U: out, across, back
``staircase``   Manhattan steps alternating x and z legs
``detour``      a straight run blocked by a keep-out rectangle, routed around it
``arc``         a circular arc
``pads``        point to point through 1-3 pad segments across the route
``band``        a straight band the serpentine must fill: a wide corridor (w ~ 15-20)
==============  ==========================================================================

``HELD_OUT`` routes are fixed and named, for evaluation only (never drawn by
:func:`sample`).

:func:`resolve` turns what ``reset(options={"target": ...})`` accepts into a Route:

* a :class:`Route`;
* a family name (drawn) or a held-out name;
* an ``(n, 2)`` polyline: the default corridor, no pads or keep-outs, named ``"custom"``;
* a dict ``{"waypoints": [[x, z], ...], "width": w, "pads": [[[x0, z0], [x1, z1]], ...],
  "pad_width": p, "keepouts": [[[x, z], ...] | {"rect": [x0, z0, x1, z1]}, ...],
  "name": str}``; only ``waypoints`` is required. Everything is translated with the
  waypoints so that the route starts at the origin.

A route whose parts contradict one another is refused (``ValueError``): a waypoint inside
a keep-out or a leg crossing one (the route itself would be a short, and the contact
point starts on the route), or a pad that no point of the corridor reaches (crossing it
means leaving the corridor).
"""

from __future__ import annotations

import itertools
import json
import math
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np
from numpy.typing import ArrayLike, NDArray

from cnt_env import numerics
from cnt_env.task import targets as targets_mod
from cnt_env.task.geometry import (
    inside_polygon,
    nearest_on_boundary,
    segment_distance,
    segments_cross,
)
from cnt_env.task.targets import cumulative_length

__all__ = [
    "DEFAULT_HALF_WIDTH",
    "FAMILIES",
    "HELD_OUT",
    "Route",
    "draw",
    "episode_steps",
    "families_of",
    "held_out",
    "load_file",
    "rectangle",
    "resolve",
    "sample",
]

FloatArray = NDArray[np.float64]

#: Default corridor half-width w (L_vb): the narrowest measured band (33.9 L_vb peak to
#: peak at v̄ = 0.13, benchmarks/results/step_response_surrogate.json) fits with ~1.5 L_vb to spare.
DEFAULT_HALF_WIDTH = 18.5
#: Every length of the families and held-out routes below was designed for a band that
#: fits w = 15 (27 L_vb peak to peak, the first model's); they scale with the band, so
#: that the routes keep their shape relative to what the process draws.
ROUTE_SCALE = DEFAULT_HALF_WIDTH / 15.0
#: Narrowest corridor accepted (L_vb): below it no flow lays a band that fits.
MIN_HALF_WIDTH = 1.0
#: Shortest route accepted (L_vb): one discretisation length of trace.
MIN_ROUTE_LENGTH = 1.0
#: Default difficulty of :func:`sample` (0: short, straight, wide; 1: long, many turns).
DEFAULT_DIFFICULTY = 0.5


#: Trace laid per Hbar of simulated time (L_vb / Hbar; 1.20 L_vb per 1.5 Hbar step in
#: benchmarks/results/step_response_surrogate.json).
DEPOSITION_SPEED = 0.80
#: Progress of the pattern along a route per L_vb of trace at the slowest useful flow
#: (the serpentine across the steps at v̄ = 0.13 drifts 0.16-0.19; along the steps
#: 0.6-1.0; benchmarks/results/step_response_surrogate.json): it sets the per-route episode length.
PROGRESS_RATE = 0.17
#: Route episodes last ROUTE_STEPS_SLACK times the steps the measured rate needs, plus
#: ROUTE_STEPS_MARGIN (the pattern's response to the first turn).
ROUTE_STEPS_SLACK = 1.5
ROUTE_STEPS_MARGIN = 10


def episode_steps(length: float, control_hbar: float) -> int:
    """Episode length (control steps) of a route ``length`` L_vb long with control steps
    of ``control_hbar`` H̄: ``ROUTE_STEPS_SLACK`` times the steps its length needs at the
    measured progress rate, plus ``ROUTE_STEPS_MARGIN``."""
    laid_per_step = DEPOSITION_SPEED * control_hbar
    return math.ceil(ROUTE_STEPS_SLACK * length / (PROGRESS_RATE * laid_per_step)) + (
        ROUTE_STEPS_MARGIN
    )


@dataclass(frozen=True, eq=False)
class Route:
    """A circuit route (module doc). Arrays are float64 and read-only.

    ``waypoints`` (n, 2) from the origin; ``width`` the corridor half-width w (L_vb);
    ``pads`` (p, 2, 2) segments; ``keepouts`` a tuple of (k, 2) polygons (k >= 3);
    ``params`` what it was built from (JSON-friendly).

    ``pad_width`` (L_vb, default 0): the width of each pad as an electrode, a rectangle
    along its segment. 0 is a line, met when the trace crosses it; p > 0 a strip, met
    when the trace enters it (within p / 2 across the segment, between its ends), so a
    run lying along the electrode contacts it as a crossing does. An electrode is
    0.5-several µm wide, 4-30 L_vb on the paper's stepped substrate (L_vb = 0.128 µm),
    as wide as the serpentine's wavelength or wider (docs/task.md, "Pads")."""

    waypoints: FloatArray
    width: float = DEFAULT_HALF_WIDTH
    pads: FloatArray = field(default_factory=lambda: np.zeros((0, 2, 2)))
    keepouts: tuple[FloatArray, ...] = ()
    name: str = "custom"
    params: Mapping[str, Any] = field(default_factory=dict)
    pad_width: float = 0.0

    def __post_init__(self) -> None:
        pts = targets_mod.validated_polyline(self.waypoints)
        if not np.array_equal(pts[0], np.zeros(2)):
            raise ValueError(f"a route starts at the origin, got waypoints[0] = {pts[0].tolist()}")
        if cumulative_length(pts)[-1] < MIN_ROUTE_LENGTH:
            raise ValueError(f"a route must be at least {MIN_ROUTE_LENGTH} L_vb long")
        w = float(self.width)
        if not (math.isfinite(w) and w >= MIN_HALF_WIDTH):
            raise ValueError(f"route width (half-width, L_vb) must be >= {MIN_HALF_WIDTH}, "
                             f"got {self.width!r}")  # fmt: skip
        pads = np.array(self.pads, dtype=np.float64).reshape(-1, 2, 2)
        if not np.isfinite(pads).all():
            raise ValueError("pads must be finite segments [[x0, z0], [x1, z1]]")
        if np.any(np.hypot(*(pads[:, 1] - pads[:, 0]).T) <= 0):
            raise ValueError("a pad segment must have non-zero length")
        pw = float(self.pad_width)
        if not (math.isfinite(pw) and pw >= 0.0):
            raise ValueError(f"pad_width (L_vb) must be finite and >= 0, got {self.pad_width!r}")
        keepouts = []
        for k in self.keepouts:
            poly = np.array(k, dtype=np.float64)
            if poly.ndim != 2 or poly.shape[1] != 2 or poly.shape[0] < 3:
                raise ValueError(f"a keep-out is a polygon of >= 3 (x, z) points, got {poly.shape}")
            if not np.isfinite(poly).all():
                raise ValueError("keep-out polygons must be finite")
            # a closed ring (the first vertex repeated at the end, as GeoJSON writes it)
            # and repeated vertices are the same polygon: drop the zero-length edges
            keep = np.any(poly != np.roll(poly, -1, axis=0), axis=1)
            poly = np.ascontiguousarray(poly[keep])
            if poly.shape[0] < 3:
                raise ValueError(f"a keep-out needs >= 3 distinct (x, z) points, got "
                                 f"{poly.shape[0]}")  # fmt: skip
            poly.setflags(write=False)
            keepouts.append(poly)
        _check_consistent(pts, w, pads, keepouts, pw)
        for arr in (pts, pads):
            arr.setflags(write=False)
        object.__setattr__(self, "waypoints", pts)
        object.__setattr__(self, "width", w)
        object.__setattr__(self, "pads", pads)
        object.__setattr__(self, "pad_width", pw)
        object.__setattr__(self, "keepouts", tuple(keepouts))
        object.__setattr__(self, "params", dict(self.params))

    @property
    def points(self) -> FloatArray:
        """The waypoints (the name targets use)."""
        return self.waypoints

    @property
    def length(self) -> float:
        """Arc length (L_vb)."""
        return float(cumulative_length(self.waypoints)[-1])

    def translated(self, offset: ArrayLike) -> tuple[FloatArray, FloatArray, tuple]:
        """``(waypoints, pads, keepouts)`` moved by ``offset`` (2,)."""
        o = np.asarray(offset, dtype=np.float64)
        return self.waypoints + o, self.pads + o, tuple(k + o for k in self.keepouts)

    def to_dict(self) -> dict[str, Any]:
        """The dict format of :func:`resolve` (JSON-friendly; ``pad_width`` only when > 0)."""
        out = {
            "name": self.name,
            "waypoints": self.waypoints.tolist(),
            "width": self.width,
            "pads": self.pads.tolist(),
            "keepouts": [k.tolist() for k in self.keepouts],
        }
        if self.pad_width > 0.0:
            out["pad_width"] = self.pad_width
        return out


def _check_consistent(pts: FloatArray, width: float, pads: FloatArray,
                      keepouts: list[FloatArray], pad_width: float = 0.0) -> None:  # fmt: skip
    """Refuse a route whose parts contradict one another (module doc)."""
    legs = list(itertools.pairwise(pts))
    fix = "route the waypoints around the keep-out"
    for k, poly in enumerate(keepouts):
        # on the boundary is touching, not inside (the even-odd rule counts some edges in)
        on_edge = nearest_on_boundary(pts, poly)[1] <= 1e-9 * (1.0 + float(np.abs(pts).max()))
        inside = np.flatnonzero(inside_polygon(pts, poly) & ~on_edge)
        if inside.size:
            i = int(inside[0])
            raise ValueError(f"waypoint {i} {pts[i].tolist()} lies inside keep-out {k}: {fix}")
        edges = list(itertools.pairwise(np.vstack([poly, poly[:1]])))
        for i, (a, b) in enumerate(legs):
            if any(segments_cross(a, b, c, d) for c, d in edges) or _through_vertices(a, b, poly):
                raise ValueError(f"leg {i} of the route ({a.tolist()} -> {b.tolist()}) "
                                 f"crosses keep-out {k}: {fix}")  # fmt: skip
    for j, (c, d) in enumerate(pads):
        gap = min(segment_distance(a, b, c, d) for a, b in legs) - 0.5 * pad_width
        if gap > width:
            raise ValueError(f"pad {j} {[c.tolist(), d.tolist()]} is {gap:.3g} L_vb from the "
                             f"route, outside its corridor (half-width {width:.3g}): move the "
                             "pad onto the corridor or widen it")  # fmt: skip


def _through_vertices(a: FloatArray, b: FloatArray, poly: FloatArray) -> bool:
    """Whether leg a-b enters ``poly`` between vertices it passes through (a leg from
    corner to corner of a rectangle crosses no edge properly): the midpoints between
    the leg's ends and the vertices on it, tested for insideness."""
    ab = b - a
    length2 = numerics.dot(ab, ab)
    if length2 == 0.0:  # a repeated waypoint: its point was tested with the waypoints
        return False
    t = numerics.rows_dot(poly - a, ab) / length2
    off = np.abs((poly[:, 0] - a[0]) * ab[1] - (poly[:, 1] - a[1]) * ab[0]) / math.sqrt(length2)
    on = t[(off <= 1e-9 * (1.0 + math.sqrt(length2))) & (t > 0.0) & (t < 1.0)]
    if on.size == 0:
        return False
    ts = np.sort(np.concatenate([[0.0, 1.0], on]))
    mids = a + 0.5 * (ts[:-1] + ts[1:])[:, None] * ab
    # strictly inside: a leg along an edge has its midpoints on the boundary
    clear = nearest_on_boundary(mids, poly)[1] > 1e-9 * (1.0 + math.sqrt(length2))
    return bool((inside_polygon(mids, poly) & clear).any())


def rectangle(x0: float, z0: float, x1: float, z1: float) -> FloatArray:
    """The polygon of the axis-aligned rectangle with corners (x0, z0), (x1, z1)."""
    xa, xb = sorted((float(x0), float(x1)))
    za, zb = sorted((float(z0), float(z1)))
    if not (xb > xa and zb > za):
        raise ValueError(f"a rectangle needs x0 != x1 and z0 != z1, got {[x0, z0, x1, z1]}")
    return np.array([[xa, za], [xb, za], [xb, zb], [xa, zb]])


# --------------------------------------------------------------------------- families


def _lerp(lo: float, hi: float, t: float) -> float:
    return lo + (hi - lo) * t


def _width(rng: np.random.Generator, d: float) -> float:
    """Corridor half-width: 20 at difficulty 0 down to 13 at 1, +-1 (x ROUTE_SCALE)."""
    return ROUTE_SCALE * float(_lerp(20.0, 13.0, d) + rng.uniform(-1.0, 1.0))


def _length(rng: np.random.Generator, d: float, lo: float = 40.0, hi: float = 160.0) -> float:
    """Route length: ~lo at difficulty 0 up to ~hi at 1, +-15% (x ROUTE_SCALE)."""
    return ROUTE_SCALE * float(_lerp(lo, hi, d) * rng.uniform(0.85, 1.15))


def _axis_heading(rng: np.random.Generator) -> float:
    return float(rng.integers(4)) * math.pi / 2


def _turn(rng: np.random.Generator) -> float:
    return math.pi / 2 if rng.integers(2) else -math.pi / 2


def _straight(rng: np.random.Generator, d: float) -> Route:
    p = {"length": _length(rng, d, 30.0, 110.0), "heading": float(rng.uniform(-math.pi, math.pi))}
    return Route(targets_mod.straight_points(**p), _width(rng, d), name="straight", params=p)


def _l_route(rng: np.random.Generator, d: float) -> Route:
    total = _length(rng, d)
    split = float(rng.uniform(0.35, 0.65))
    h, t = _axis_heading(rng), _turn(rng)
    p = {"leg1": total * split, "leg2": total * (1 - split), "heading": h, "turn": t}
    pts = targets_mod.l_bend_points(p["leg1"], p["leg2"], t, h)
    return Route(pts, _width(rng, d), name="l_route", params=p)


def _u_route(rng: np.random.Generator, d: float) -> Route:
    w = _width(rng, d)
    leg = _length(rng, d, 30.0, 70.0)
    across = float(max(2.2 * w, rng.uniform(2.2, 3.0) * w))  # corridors of the legs apart
    h, t = _axis_heading(rng), _turn(rng)
    p = {"leg": leg, "across": across, "heading": h, "turn": t}
    pts = targets_mod.legs_points([leg, across, leg], [h, h + t, h + 2 * t])
    return Route(pts, w, name="u_route", params=p)


def _staircase(rng: np.random.Generator, d: float) -> Route:
    n_steps = round(_lerp(2, 5, d)) + int(rng.integers(0, 2))
    step = ROUTE_SCALE * float(rng.uniform(20.0, 35.0))
    h, t = _axis_heading(rng), _turn(rng)
    headings = [h if i % 2 == 0 else h + t for i in range(n_steps)]
    p = {"n_legs": n_steps, "leg": step, "heading": h, "turn": t}
    pts = targets_mod.legs_points([step] * n_steps, headings)
    return Route(pts, _width(rng, d), name="staircase", params=p)


def _detour(rng: np.random.Generator, d: float) -> Route:
    """Around a keep-out block in the way of the straight run (canonical frame: +x)."""
    w = _width(rng, d)
    block = ROUTE_SCALE * float(rng.uniform(15.0, 30.0))  # side of the keep-out along x
    off = float(rng.uniform(2.0, 2.6) * w)  # how far the route jogs sideways
    lead = _length(rng, d, 25.0, 45.0)
    side = 1.0 if rng.integers(2) else -1.0
    x1, x2 = lead, lead + block + 2 * w
    pts = np.array([[0, 0], [x1, 0], [x1, side * off], [x2, side * off], [x2, 0],
                    [x2 + lead, 0]], dtype=float)  # fmt: skip
    # the keep-out sits on the straight line, between the route's jogs, w from them
    kx0, kx1 = x1 + w, x2 - w
    kz = sorted((-side * 0.5 * w, side * (off - w)))
    keep = rectangle(kx0, kz[0], kx1, kz[1]) if kz[1] - kz[0] > 1 else rectangle(kx0, -2, kx1, 2)
    h = _axis_heading(rng)
    p = {"lead": lead, "block": block, "offset": off, "side": side, "heading": h}
    return Route(
        numerics.rotate(pts, h), w, keepouts=(numerics.rotate(keep, h),), name="detour", params=p
    )


def _arc(rng: np.random.Generator, d: float) -> Route:
    w = _width(rng, d)
    sweep = float(rng.uniform(math.pi / 3, _lerp(math.pi / 2, math.pi, d)))
    radius = float(max(1.5 * w, _length(rng, d) / sweep))
    sweep *= 1.0 if rng.integers(2) else -1.0
    p = {"radius": radius, "sweep": sweep, "heading": float(rng.uniform(-math.pi, math.pi))}
    return Route(targets_mod.arc_points(**p), w, name="arc", params=p)


def _pads(rng: np.random.Generator, d: float) -> Route:
    """Point to point: an L or a straight run with 1-3 pads across it."""
    base = _l_route(rng, d) if rng.integers(2) else _straight(rng, d)
    pts, w = base.waypoints, base.width
    s = cumulative_length(pts)
    n = 1 + int(rng.integers(0, 3))
    pads = []
    for f in np.sort(rng.uniform(0.3, 1.0, n)):
        at = f * s[-1]
        c = np.array([np.interp(at, s, pts[:, k]) for k in (0, 1)])
        i = min(int(np.searchsorted(s, at, side="right")) - 1, len(pts) - 2)
        t = (pts[i + 1] - pts[i]) / np.hypot(*(pts[i + 1] - pts[i]))
        nrm = np.array([-t[1], t[0]])
        pads.append([c - 0.8 * w * nrm, c + 0.8 * w * nrm])
    p = {"base": base.name, **base.params, "n_pads": n}
    return Route(pts, w, pads=np.array(pads), name="pads", params=p)


def _band(rng: np.random.Generator, d: float) -> Route:
    """A band for the serpentine to fill: a run across the steps (±x), wide corridor."""
    p = {"length": _length(rng, d, 40.0, 120.0),
         "heading": 0.0 if rng.integers(2) else math.pi}  # fmt: skip
    w = ROUTE_SCALE * float(rng.uniform(15.0, 20.0))
    return Route(targets_mod.straight_points(**p), w, name="band", params=p)


#: Training families: name -> draw(rng, difficulty) -> Route.
FAMILIES: dict[str, Callable[[np.random.Generator, float], Route]] = {
    "straight": _straight,
    "l_route": _l_route,
    "u_route": _u_route,
    "staircase": _staircase,
    "detour": _detour,
    "arc": _arc,
    "pads": _pads,
    "band": _band,
}


def draw(family: str, rng: np.random.Generator, difficulty: float = DEFAULT_DIFFICULTY) -> Route:
    """One route of ``family`` drawn from ``rng`` at ``difficulty`` in [0, 1]."""
    if family not in FAMILIES:
        raise ValueError(f"unknown route family {family!r}; choose one of {sorted(FAMILIES)}")
    if not (0.0 <= difficulty <= 1.0):
        raise ValueError(f"difficulty must be in [0, 1], got {difficulty!r}")
    return FAMILIES[family](rng, float(difficulty))


def families_of(score: str) -> Mapping[str, Any]:
    """The training families of a task: routes (``score="corridor"``) or thin polylines."""
    return FAMILIES if score == "corridor" else targets_mod.FAMILIES


#: A difficulty, or a range (lo, hi) from which each drawn route takes its own.
Difficulty = float | tuple[float, float]


def drawn_difficulty(rng: np.random.Generator, difficulty: Difficulty) -> float:
    """``difficulty``, or for a range (lo, hi) one value uniform in it from ``rng`` (the
    only draw a range adds, so a fixed difficulty's stream is unchanged)."""
    if isinstance(difficulty, tuple):
        return float(rng.uniform(*difficulty))
    return difficulty


def sample(rng: np.random.Generator, families: Sequence[str] | None = None,
           difficulty: Difficulty = DEFAULT_DIFFICULTY) -> Route:  # fmt: skip
    """A training route: a family chosen uniformly, then drawn (at ``difficulty``, or at
    one drawn from its range first). Never a held-out one."""
    names = tuple(FAMILIES) if families is None else tuple(families)
    if not names:
        raise ValueError("families must name at least one family")
    d = drawn_difficulty(rng, difficulty)
    return draw(names[int(rng.integers(len(names)))], rng, d)


# --------------------------------------------------------------------------- held out


def _held_out_specs() -> dict[str, dict[str, Any]]:
    """The held-out routes, designed at w = 15 and scaled by ROUTE_SCALE (lengths and
    widths alike)."""
    u = [[0, 0], [60, 0], [60, 40], [0, 40]]
    base = {
        # the U-turn of issue 10 (0,0)-(60,0)-(60,40)-(0,40): 160 L_vb at w = 15
        "u_turn": {"waypoints": u, "width": 15.0},
        "l_up": {"waypoints": [[0, 0], [50, 0], [50, 60]], "width": 15.0},
        "against_flow": {"waypoints": [[0, 0], [-90, 0]], "width": 15.0},
        "diagonal": {"waypoints": [[0, 0], [70, 70]], "width": 15.0},
        "staircase3": {"waypoints": [[0, 0], [30, 0], [30, 30], [60, 30], [60, 60]], "width": 15.0},
        "detour_block": {
            "waypoints": [[0, 0], [30, 0], [30, 36], [90, 36], [90, 0], [120, 0]],
            "width": 15.0,
            "keepouts": [{"rect": [45, -8, 75, 21]}],
        },
        "arc_quarter": {
            "waypoints": targets_mod.arc_points(60.0, math.pi / 2, 0.0).tolist(),
            "width": 15.0,
        },
        "pads_line": {
            "waypoints": [[0, 0], [0, 100]],
            "width": 12.0,
            "pads": [[[-10, 50], [10, 50]], [[-10, 90], [10, 90]]],
        },
        "band_fill": {"waypoints": [[0, 0], [100, 0]], "width": 18.0},
    }

    return {name: scale_design(spec) for name, spec in base.items()}


def scale_design(value: Any) -> Any:
    """A route spec (dict format, numbers only) designed at w = 15, with every length
    and width scaled by ROUTE_SCALE."""
    if isinstance(value, dict):
        return {k: scale_design(v) for k, v in value.items()}
    if isinstance(value, list):
        return [scale_design(v) for v in value]
    return ROUTE_SCALE * float(value)


#: Names of the held-out routes (evaluation only).
HELD_OUT: tuple[str, ...] = tuple(_held_out_specs())


def held_out(name: str) -> Route:
    """The held-out route ``name``."""
    specs = _held_out_specs()
    if name not in specs:
        raise ValueError(f"unknown held-out route {name!r}; choose one of {list(HELD_OUT)}")
    return from_dict({**specs[name], "name": name})


#: The keys of the route dict format (module doc), in the order the error text lists them.
ROUTE_KEYS = ("waypoints", "width", "pads", "pad_width", "keepouts", "name", "params")


def from_dict(spec: Mapping[str, Any]) -> Route:
    """A Route from the dict format (module doc), translated to start at the origin."""
    unknown = set(spec) - set(ROUTE_KEYS)
    if unknown:
        raise ValueError(f"unknown route keys {sorted(unknown)}; known: {', '.join(ROUTE_KEYS)}")
    if "waypoints" not in spec:
        raise ValueError("a route dict needs 'waypoints': [[x, z], ...]")
    pts = targets_mod.validated_polyline(spec["waypoints"])
    o = pts[0].copy()
    keepouts = []
    for k in spec.get("keepouts") or ():
        if isinstance(k, Mapping):
            if set(k) != {"rect"}:
                raise ValueError(f"a keep-out dict is {{'rect': [x0, z0, x1, z1]}}, got {k!r}")
            k = rectangle(*k["rect"])
        keepouts.append(np.asarray(k, dtype=float) - o)
    pads = np.asarray(spec.get("pads") or np.zeros((0, 2, 2)), dtype=float).reshape(-1, 2, 2)
    return Route(pts - o, float(spec.get("width", DEFAULT_HALF_WIDTH)), pads - o,
                 tuple(keepouts), str(spec.get("name", "custom")),
                 dict(spec.get("params") or {}), float(spec.get("pad_width", 0.0)))  # fmt: skip


#: Largest route file read (bytes): a route is a few hundred bytes.
MAX_ROUTE_FILE_BYTES = 1 << 24


def load_file(path: str | Path) -> dict[str, Route]:
    """Named routes from a JSON or YAML file (``.yml``/``.yaml``; anything else is read as
    JSON), for ``cnt-evaluate --route-file`` and the env's ``route_file``: a list of route
    dicts (the format of :func:`from_dict`), each with a ``name``, or a mapping
    ``{name: route dict}``.

    Every route is validated as ``reset`` would; a name must be unique and may not be a
    family or held-out name (it would be ambiguous). Raises ValueError naming the file
    and the route on any problem; nothing is half-read."""
    path = Path(path)
    try:
        if path.stat().st_size > MAX_ROUTE_FILE_BYTES:
            raise ValueError(f"{path}: over {MAX_ROUTE_FILE_BYTES} bytes, not a route file")
        text = path.read_text(encoding="utf-8")
    except (OSError, UnicodeDecodeError) as exc:
        raise ValueError(f"{path}: cannot be read as text: {exc}") from exc
    try:
        if path.suffix.lower() in (".yml", ".yaml"):
            import yaml

            data = yaml.safe_load(text)
        else:
            data = json.loads(text)
    except Exception as exc:  # a parser's own error type: reported with the file
        raise ValueError(f"{path}: not valid {path.suffix or 'JSON'}: {exc}") from exc
    if isinstance(data, Mapping):
        items = [(str(k), v) for k, v in data.items()]
    elif isinstance(data, list):
        items = [(v.get("name") if isinstance(v, Mapping) else None, v) for v in data]
    else:
        raise ValueError(f"{path}: a route file holds a list of route dicts or a mapping "
                         f"{{name: route dict}}, got {type(data).__name__}")  # fmt: skip
    if not items:
        raise ValueError(f"{path}: holds no route")
    out: dict[str, Route] = {}
    for i, (name, spec) in enumerate(items):
        where = f"{path}: route {i}" + (f" ({name!r})" if name else "")
        if not isinstance(spec, Mapping):
            raise ValueError(f"{where}: a route is a dict with 'waypoints', got {spec!r:.80}")
        if not name or not isinstance(name, str):
            raise ValueError(f"{where}: give every route a 'name' (a non-empty string)")
        if name in out or name in FAMILIES or name in HELD_OUT:
            taken = "used twice" if name in out else "a family or held-out route's name"
            raise ValueError(f"{where}: the name is {taken}; rename it")
        try:
            out[name] = from_dict({**spec, "name": name})
        except (ValueError, TypeError) as exc:
            raise ValueError(f"{where}: {exc}") from exc
    return out


def resolve(spec: Any, rng: np.random.Generator, difficulty: Difficulty = DEFAULT_DIFFICULTY,
            width: float = DEFAULT_HALF_WIDTH) -> Route:  # fmt: skip
    """What ``reset(options={"target": spec})`` accepts, as a :class:`Route` (module doc).
    A bare polyline gets the corridor half-width ``width``; a thin-task
    :class:`~cnt_env.task.targets.Target` becomes a route along its points."""
    if isinstance(spec, Route):
        return spec
    if isinstance(spec, targets_mod.Target):
        return Route(spec.points, width, name=spec.name, params=spec.params)
    if isinstance(spec, str):
        if spec in FAMILIES:
            return draw(spec, rng, drawn_difficulty(rng, difficulty))
        if spec in HELD_OUT:
            return held_out(spec)
        if spec in targets_mod.HELD_OUT or spec in targets_mod.FAMILIES:
            t = targets_mod.resolve(spec, rng)
            return Route(t.points, width, name=t.name, params=t.params)
        raise ValueError(
            f"unknown route {spec!r}: a family {sorted(FAMILIES)}, a held-out route "
            f"{list(HELD_OUT)}, a thin target name, an (n, 2) polyline or a route dict"
        )
    if isinstance(spec, Mapping):
        return from_dict(spec)
    pts = targets_mod.validated_polyline(spec)
    return Route(pts - pts[0], width)

"""Target circuit paths for ``CNTDeposit-v0``: polylines in the substrate plane.

A target is an ``(n, 2)`` float64 polyline of points ``(x, z)`` in L_vb, in the
substrate plane (docs/model.md §1: the substrate is the x-z plane, the steps of the
stepped substrate run along z). Every target starts at the origin; the env translates
it so that it starts at the contact point at reset. Curved pieces are sampled at most
``CURVE_SPACING`` apart, so the polyline itself is the path (no spline underneath).

Training families (drawn by :func:`sample` with the env's ``np_random``; the parameter
ranges are the ``*_RANGE`` constants below, lengths in L_vb, angles in rad):

==============  ==========================================================================
family          shape
==============  ==========================================================================
``straight``    a line at a heading angle
``l_bend``      two legs joined by a corner of 60°-120° to either side
``arc``         a circular arc of a given radius and sweep, to either side
``zigzag``      legs of equal length, alternately turning by ± the same angle
``serpentine``  a U-shaped meander (a circuit meander element): runs across the direction
                of progression joined by semicircles; amplitude ``A`` (half the peak-to-
                peak, the convention of ``patterns.py``) and wavelength ``lambda``
``smooth``      a random smooth curve: the heading follows a few random Fourier modes with
                bounded curvature
==============  ==========================================================================

The ``HELD_OUT`` targets are fixed, named, and never drawn by :func:`sample`: they are
for evaluation only. Most are shapes no family produces (S-curve, hairpin, square-wave
meander, spiral, jog); ``paper_serpentine`` is the paper's baseline serpentine
(A = 30, lambda = 7, docs/model.md §6; two periods), progressing along +x, across the
steps.

:func:`resolve` turns what ``reset(options={"target": ...})`` accepts (a
:class:`Target`, a family name, a held-out name, or an explicit polyline) into a
:class:`Target`.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Mapping
from dataclasses import dataclass, field
from typing import Any

import numpy as np
from numba import njit
from numpy.typing import ArrayLike, NDArray

from cnt_env import numerics
from cnt_env.patterns import arc_length

__all__ = [
    "CURVE_SPACING",
    "FAMILIES",
    "HELD_OUT",
    "MAX_TARGET_LENGTH",
    "Target",
    "cumulative_length",
    "draw",
    "held_out",
    "legs_points",
    "mark_covered",
    "polyline_distances",
    "polyline_length",
    "resample",
    "resolve",
    "sample",
    "validated_polyline",
]

FloatArray = NDArray[np.float64]

#: Largest spacing (L_vb) between consecutive points on curved pieces.
CURVE_SPACING = 0.5
#: Longest target accepted (L_vb); longer explicit polylines are rejected.
MAX_TARGET_LENGTH = 1.0e4
#: Shortest target accepted (L_vb): a degenerate one (say [[0, 0], [1e-300, 0]]) cannot
#: be scored. Routes ask for more (routes.MIN_ROUTE_LENGTH).
MIN_TARGET_LENGTH = 1.0e-6

# Parameter ranges of the training families (uniform draws; lengths in L_vb).
STRAIGHT_LENGTH_RANGE = (30.0, 120.0)
L_BEND_LEG_RANGE = (20.0, 60.0)
L_BEND_TURN_RANGE = (math.radians(60.0), math.radians(120.0))
ARC_RADIUS_RANGE = (15.0, 60.0)
ARC_SWEEP_RANGE = (math.pi / 3.0, math.pi)
ZIGZAG_LEG_RANGE = (8.0, 25.0)
ZIGZAG_TURN_RANGE = (math.radians(45.0), math.radians(120.0))
ZIGZAG_LEGS_RANGE = (3, 8)  # inclusive
SERPENTINE_AMPLITUDE_RANGE = (8.0, 35.0)  # half the peak-to-peak
SERPENTINE_WAVELENGTH_RANGE = (5.0, 15.0)
SERPENTINE_PERIODS_RANGE = (1, 2)  # inclusive
SMOOTH_LENGTH_RANGE = (40.0, 150.0)
SMOOTH_MIN_RADIUS = 8.0  # the curvature of a smooth target stays below 1 / this
SMOOTH_MODES = 3


@dataclass(frozen=True, eq=False)
class Target:
    """A target path. ``points``: (n, 2) float64 ``(x, z)`` in L_vb, ``points[0] == (0, 0)``.

    ``name`` is the family, the held-out name, or ``"custom"``; ``params`` the parameters
    it was built from (JSON-friendly, for logs).
    """

    name: str
    points: FloatArray
    params: Mapping[str, Any] = field(default_factory=dict)

    def __post_init__(self) -> None:
        pts = validated_polyline(self.points)
        if not np.array_equal(pts[0], np.zeros(2)):
            raise ValueError(f"a target starts at the origin, got points[0] = {pts[0].tolist()}")
        pts.setflags(write=False)
        object.__setattr__(self, "points", pts)
        object.__setattr__(self, "params", dict(self.params))

    @property
    def length(self) -> float:
        """Arc length (L_vb)."""
        return polyline_length(self.points)


# --------------------------------------------------------------------------- geometry


def validated_polyline(points: ArrayLike) -> FloatArray:
    """(n, 2) finite float64 copy with zero-length segments removed; raises ValueError."""
    try:
        pts = np.array(points, dtype=np.float64)
    except (TypeError, ValueError) as exc:
        raise ValueError(f"a target polyline must be numeric (n, 2) points (x, z): {exc}") from exc
    if pts.ndim != 2 or pts.shape[1] != 2 or pts.shape[0] < 2:
        raise ValueError(
            f"a target polyline must have shape (n >= 2, 2) as (x, z), got {pts.shape}"
        )
    if not np.isfinite(pts).all():
        raise ValueError("a target polyline must be finite (no NaN or inf)")
    seg = np.hypot(*np.diff(pts, axis=0).T)
    keep = np.concatenate([[True], seg > 0.0])
    pts = pts[keep]
    if pts.shape[0] < 2:
        raise ValueError("a target polyline must have non-zero length")
    length = polyline_length(pts)
    if not length >= MIN_TARGET_LENGTH:
        raise ValueError(
            f"target length {length:.6g} L_vb is below MIN_TARGET_LENGTH = {MIN_TARGET_LENGTH:g}"
        )
    if length > MAX_TARGET_LENGTH:
        raise ValueError(
            f"target length {length:.6g} L_vb exceeds MAX_TARGET_LENGTH = {MAX_TARGET_LENGTH:g}"
        )
    return pts


def cumulative_length(points: ArrayLike) -> FloatArray:
    """Arc length (L_vb) at each vertex of an (n, 2) polyline, from 0
    (:func:`cnt_env.patterns.arc_length`)."""
    return arc_length(points)


def polyline_length(points: ArrayLike) -> float:
    """Arc length of an (n, 2) polyline."""
    return float(cumulative_length(points)[-1])


def resample(points: ArrayLike, spacing: float) -> tuple[FloatArray, FloatArray]:
    """Points along the polyline at most ``spacing`` apart, keeping every vertex.

    Returns ``(samples (m, 2), arc length of each sample (m,))``.
    """
    if not (math.isfinite(spacing) and spacing > 0):
        raise ValueError(f"spacing must be finite and > 0, got {spacing!r}")
    p = np.asarray(points, dtype=np.float64)
    seg = np.hypot(*np.diff(p, axis=0).T)
    n_sub = np.maximum(1, np.ceil(seg / spacing).astype(np.int64))
    starts = np.repeat(p[:-1], n_sub, axis=0)
    deltas = np.repeat(np.diff(p, axis=0) / n_sub[:, None], n_sub, axis=0)
    k = np.arange(int(n_sub.sum())) - np.repeat(np.cumsum(n_sub) - n_sub, n_sub)
    samples = np.concatenate([starts + k[:, None] * deltas, p[-1:]])
    s0 = np.concatenate([[0.0], np.cumsum(seg)])
    s = np.concatenate([np.repeat(s0[:-1], n_sub) + k * np.repeat(seg / n_sub, n_sub), s0[-1:]])
    return samples, s


@njit(cache=True)
def polyline_distances(points: FloatArray, vertices: FloatArray, out: FloatArray) -> None:
    """``out[i]`` = distance from ``points[i]`` (p, 2) to the polyline ``vertices`` (n, 2)."""
    for i in range(points.shape[0]):
        px, pz = points[i, 0], points[i, 1]
        best = np.inf
        for j in range(vertices.shape[0] - 1):
            ax, az = vertices[j, 0], vertices[j, 1]
            dx, dz = vertices[j + 1, 0] - ax, vertices[j + 1, 1] - az
            rx, rz = px - ax, pz - az
            len2 = dx * dx + dz * dz
            t = (rx * dx + rz * dz) / len2 if len2 > 0.0 else 0.0
            t = min(max(t, 0.0), 1.0)
            ex, ez = rx - t * dx, rz - t * dz
            d2 = ex * ex + ez * ez
            if d2 < best:
                best = d2
        out[i] = np.sqrt(best)


@njit(cache=True)
def mark_covered(samples: FloatArray, points: FloatArray, tol: float, hit: np.ndarray) -> None:
    """Set ``hit[i]`` where ``samples[i]`` lies within ``tol`` of one of ``points``."""
    tol2 = tol * tol
    for i in range(samples.shape[0]):
        if hit[i]:
            continue
        sx, sz = samples[i, 0], samples[i, 1]
        for j in range(points.shape[0]):
            dx, dz = sx - points[j, 0], sz - points[j, 1]
            if dx * dx + dz * dz <= tol2:
                hit[i] = True
                break


def _arc(start: FloatArray, heading: float, radius: float, sweep: float) -> FloatArray:
    """Points of a circular arc from ``start`` (excluded) leaving along ``heading``;
    ``sweep`` > 0 turns counter-clockwise in (x, z)."""
    n = max(2, math.ceil(abs(sweep) * radius / CURVE_SPACING))
    n += n % 2  # even: the arc's midpoint (a serpentine's apex) is a vertex
    sign = 1.0 if sweep > 0 else -1.0
    centre = start + radius * sign * np.array([-math.sin(heading), math.cos(heading)])
    angles = heading - sign * math.pi / 2 + np.linspace(0.0, sweep, n + 1)[1:]
    return centre + radius * np.column_stack([np.cos(angles), np.sin(angles)])


def legs_points(lengths: ArrayLike, headings: ArrayLike) -> FloatArray:
    """Polyline from the origin with straight legs of the given lengths and headings."""
    steps = np.column_stack([np.cos(headings), np.sin(headings)]) * np.asarray(lengths)[:, None]
    return np.concatenate([np.zeros((1, 2)), np.cumsum(steps, axis=0)])


# --------------------------------------------------------------------------- builders


def straight_points(length: float, heading: float) -> FloatArray:
    return legs_points([length], [heading])


def l_bend_points(leg1: float, leg2: float, turn: float, heading: float) -> FloatArray:
    return legs_points([leg1, leg2], [heading, heading + turn])


def arc_points(radius: float, sweep: float, heading: float) -> FloatArray:
    return np.concatenate([np.zeros((1, 2)), _arc(np.zeros(2), heading, radius, sweep)])


def zigzag_points(leg: float, turn: float, n_legs: int, heading: float) -> FloatArray:
    # the first leg leaves at heading - turn/2 so that the zig-zag progresses along heading
    signs = np.where(np.arange(n_legs) % 2 == 0, -0.5, 0.5)
    return legs_points(np.full(n_legs, leg), heading + signs * turn)


def serpentine_points(
    amplitude: float, wavelength: float, periods: int, heading: float, side: int = 1
) -> FloatArray:
    """U-shaped meander progressing along ``heading``: runs of ``2 amplitude - wavelength/2``
    across it, joined by semicircles of diameter ``wavelength / 2``, so that the
    peak-to-peak extent is ``2 amplitude`` (patterns.py: the amplitude is half the
    peak-to-peak). Starts at the origin in the middle of a run, heading to ``side``
    (+1: left of the progression, -1: right)."""
    r = wavelength / 4.0
    run = 2.0 * amplitude - 2.0 * r
    if run <= 0:
        raise ValueError(f"serpentine amplitude {amplitude} must exceed wavelength / 4")
    pts = [np.zeros((1, 2)), np.array([[0.0, side * run / 2.0]])]
    direction = side
    for _ in range(2 * periods):
        start = pts[-1][-1]
        # canonical frame: progression along +x, runs along +-z
        arc = _arc(start, direction * math.pi / 2, r, -direction * math.pi)
        pts.append(arc)
        direction = -direction
        end = arc[-1]
        pts.append(np.array([[end[0], end[1] + direction * run]]))
    # end in the middle of the last run, where it started (in z)
    last = pts.pop()
    pts.append(np.array([[last[0, 0], last[0, 1] - direction * run / 2.0]]))
    return numerics.rotate(np.concatenate(pts), heading)


def smooth_points(
    length: float, heading: float, amplitudes: ArrayLike, phases: ArrayLike
) -> FloatArray:
    """Curve whose curvature is ``sum_k a_k sin(2 pi k s / length + p_k)``, integrated
    from the origin along ``heading`` (|curvature| <= sum |a_k|)."""
    n = max(2, math.ceil(length / CURVE_SPACING))
    s = np.linspace(0.0, length, n + 1)
    k = np.arange(1, len(amplitudes) + 1)
    kappa = np.sum(
        np.asarray(amplitudes)[:, None]
        * np.sin(2.0 * math.pi * k[:, None] * s[None, :] / length + np.asarray(phases)[:, None]),
        axis=0,
    )
    ds = length / n
    theta = heading + np.concatenate([[0.0], np.cumsum(0.5 * (kappa[1:] + kappa[:-1]) * ds)])
    mid = 0.5 * (theta[1:] + theta[:-1])
    return legs_points(np.full(n, ds), mid)


# --------------------------------------------------------------------------- families


def _heading(rng: np.random.Generator) -> float:
    return float(rng.uniform(-math.pi, math.pi))


def _side(rng: np.random.Generator) -> int:
    return 1 if rng.integers(2) == 1 else -1


def _straight(rng: np.random.Generator) -> Target:
    p = {"length": float(rng.uniform(*STRAIGHT_LENGTH_RANGE)), "heading": _heading(rng)}
    return Target("straight", straight_points(**p), p)


def _l_bend(rng: np.random.Generator) -> Target:
    p = {
        "leg1": float(rng.uniform(*L_BEND_LEG_RANGE)),
        "leg2": float(rng.uniform(*L_BEND_LEG_RANGE)),
        "turn": _side(rng) * float(rng.uniform(*L_BEND_TURN_RANGE)),
        "heading": _heading(rng),
    }
    return Target("l_bend", l_bend_points(**p), p)


def _arc_family(rng: np.random.Generator) -> Target:
    p = {
        "radius": float(rng.uniform(*ARC_RADIUS_RANGE)),
        "sweep": _side(rng) * float(rng.uniform(*ARC_SWEEP_RANGE)),
        "heading": _heading(rng),
    }
    return Target("arc", arc_points(**p), p)


def _zigzag(rng: np.random.Generator) -> Target:
    p = {
        "leg": float(rng.uniform(*ZIGZAG_LEG_RANGE)),
        "turn": float(rng.uniform(*ZIGZAG_TURN_RANGE)),
        "n_legs": int(rng.integers(ZIGZAG_LEGS_RANGE[0], ZIGZAG_LEGS_RANGE[1] + 1)),
        "heading": _heading(rng),
    }
    return Target("zigzag", zigzag_points(**p), p)


def _serpentine(rng: np.random.Generator) -> Target:
    p = {
        "amplitude": float(rng.uniform(*SERPENTINE_AMPLITUDE_RANGE)),
        "wavelength": float(rng.uniform(*SERPENTINE_WAVELENGTH_RANGE)),
        "periods": int(rng.integers(SERPENTINE_PERIODS_RANGE[0], SERPENTINE_PERIODS_RANGE[1] + 1)),
        "heading": _heading(rng),
        "side": _side(rng),
    }
    return Target("serpentine", serpentine_points(**p), p)


def _smooth(rng: np.random.Generator) -> Target:
    # mode amplitudes split a curvature budget 1 / SMOOTH_MIN_RADIUS at random
    weights = rng.dirichlet(np.ones(SMOOTH_MODES))
    signs = np.where(rng.integers(2, size=SMOOTH_MODES) == 1, 1.0, -1.0)
    p = {
        "length": float(rng.uniform(*SMOOTH_LENGTH_RANGE)),
        "heading": _heading(rng),
        "amplitudes": [float(a) for a in signs * weights / SMOOTH_MIN_RADIUS],
        "phases": [float(v) for v in rng.uniform(0.0, 2.0 * math.pi, SMOOTH_MODES)],
    }
    return Target("smooth", smooth_points(**p), p)


#: Training families: name -> draw(rng) -> Target.
FAMILIES: dict[str, Callable[[np.random.Generator], Target]] = {
    "straight": _straight,
    "l_bend": _l_bend,
    "arc": _arc_family,
    "zigzag": _zigzag,
    "serpentine": _serpentine,
    "smooth": _smooth,
}


def draw(family: str, rng: np.random.Generator) -> Target:
    """One target of ``family`` drawn from ``rng``."""
    if family not in FAMILIES:
        raise ValueError(f"unknown target family {family!r}; choose one of {sorted(FAMILIES)}")
    return FAMILIES[family](rng)


def sample(rng: np.random.Generator, families: tuple[str, ...] | None = None) -> Target:
    """A training target: a family chosen uniformly from ``families`` (default all), then
    drawn from it. Held-out targets are never returned."""
    names = tuple(FAMILIES) if families is None else tuple(families)
    if not names:
        raise ValueError("families must name at least one family")
    return draw(names[int(rng.integers(len(names)))], rng)


# --------------------------------------------------------------------------- held out


def _s_curve() -> FloatArray:
    first = arc_points(25.0, math.pi / 2, 0.0)
    second = _arc(first[-1], math.pi / 2, 25.0, -math.pi / 2)
    return np.concatenate([first, second])


def _hairpin() -> FloatArray:
    leg = straight_points(40.0, 0.0)
    turn = _arc(leg[-1], 0.0, 10.0, math.pi)
    back = turn[-1] + np.array([[-40.0, 0.0]])
    return np.concatenate([leg, turn, back])


def _square_wave() -> FloatArray:
    # circuit meander with sharp corners: pitch 20 along +x, 20 across, 3 periods
    legs, headings = [], []
    for _ in range(3):
        legs += [10.0, 20.0, 10.0, 20.0]
        headings += [0.0, math.pi / 2, 0.0, -math.pi / 2]
    return legs_points(np.array(legs), np.array(headings))


def _spiral() -> FloatArray:
    # Archimedean spiral r = b phi from the origin, 1.5 turns out to r = 25
    turns = 1.5
    b = 25.0 / (2 * math.pi * turns)
    phi = np.linspace(0.0, 2 * math.pi * turns, 2000)
    pts = np.column_stack([b * phi * np.cos(phi), b * phi * np.sin(phi)])
    s = cumulative_length(pts)
    keep = np.searchsorted(s, np.arange(0.0, s[-1], CURVE_SPACING))
    return np.concatenate([pts[keep], pts[-1:]])


def _jog() -> FloatArray:
    return legs_points(np.array([30.0, 15.0 * math.sqrt(2.0), 30.0]),
                 np.array([0.0, math.pi / 4, 0.0]))  # fmt: skip


#: Held-out evaluation targets: name -> (builder, params). Never drawn by :func:`sample`.
_HELD_OUT_BUILDERS: dict[str, tuple[Callable[[], FloatArray], dict[str, Any]]] = {
    "paper_serpentine": (
        lambda: serpentine_points(30.0, 7.0, 2, 0.0, 1),
        {"amplitude": 30.0, "wavelength": 7.0, "periods": 2, "heading": 0.0, "side": 1},
    ),
    "s_curve": (_s_curve, {"radius": 25.0, "sweeps": [math.pi / 2, -math.pi / 2]}),
    "hairpin": (_hairpin, {"leg": 40.0, "radius": 10.0}),
    "square_wave": (_square_wave, {"pitch": 20.0, "amplitude": 20.0, "periods": 3}),
    "spiral": (_spiral, {"outer_radius": 25.0, "turns": 1.5}),
    "jog": (_jog, {"leg": 30.0, "offset": 15.0}),
    "long_diagonal": (
        lambda: straight_points(150.0, math.pi / 6),
        {"length": 150.0, "heading": math.pi / 6},
    ),
}

#: Names of the held-out targets (evaluation only).
HELD_OUT: tuple[str, ...] = tuple(_HELD_OUT_BUILDERS)


def held_out(name: str) -> Target:
    """The held-out target ``name`` (deterministic; no randomness)."""
    if name not in _HELD_OUT_BUILDERS:
        raise ValueError(f"unknown held-out target {name!r}; choose one of {list(HELD_OUT)}")
    build, params = _HELD_OUT_BUILDERS[name]
    return Target(name, build(), params)


def resolve(spec: Any, rng: np.random.Generator) -> Target:
    """What ``reset(options={"target": spec})`` accepts, as a :class:`Target`.

    * a :class:`Target`: used as is;
    * a family name: drawn from ``rng``;
    * a held-out name: that target;
    * an ``(n, 2)`` polyline ``(x, z)`` in L_vb: translated so that it starts at the
      origin (the env then starts it at the contact point), named ``"custom"``.
    """
    if isinstance(spec, Target):
        return spec
    if isinstance(spec, str):
        if spec in FAMILIES:
            return draw(spec, rng)
        if spec in _HELD_OUT_BUILDERS:
            return held_out(spec)
        raise ValueError(
            f"unknown target {spec!r}: a family {sorted(FAMILIES)}, a held-out target "
            f"{list(HELD_OUT)}, or an (n, 2) polyline"
        )
    pts = validated_polyline(spec)
    return Target("custom", pts - pts[0])

"""Measurements of a deposited trace: coil radius, serpentine amplitude and
wavelength, loops, and the pattern class (docs/model.md §7).

A *trace* is an ``(n, 2)`` float array of points ``(x, z)`` in the substrate
plane, ordered by deposition (arc length increasing), in units of L_vb. The
simulator's ``(n, 3)`` points ``(x, y=0, z)`` are accepted too; ``y`` is dropped.
The steps of the stepped substrate run along z (docs/model.md §5), so U-turns are
extrema of z and a serpentine progresses across z (along x for the paper's flow).

Every measurement that takes :class:`MeasureOptions` first drops the start-up
transient (``transient_length`` of arc length, docs/model.md §7) and returns point
indices into the trace *as passed in*, so they can index it directly.

Conventions (fixed here, used everywhere):

* **Spread** is the pair ``(p16, p84)`` of the 16th and 84th percentiles of the
  per-window or per-cycle samples, i.e. median +- one sigma for Gaussian scatter.
  The *relative spread* is ``(p84 - p16) / (2 median)``.
* **Coefficient of variation** (CV) is the sample standard deviation
  (``ddof=1``) over the mean.
* **Amplitude** is half the z distance between the extreme points of two
  successive, opposite U-turns, i.e. the conventional amplitude (a sine
  ``A sin(.)`` has amplitude ``A``); the full distance is reported as
  ``peak_to_peak``. A serpentine with straight runs of length ``L`` along z,
  joined by semicircles of diameter ``lambda / 2``, has peak-to-peak
  ``L + lambda / 2``. [Choice] docs/model.md §7 words the amplitude as "the z
  distance between successive opposite U-turns"; read literally that is the
  peak-to-peak value, which on our serpentine baseline is twice the paper's
  Abar ~ 30, while the conventional half matches it (benchmarks/RESULTS.md).
* **Wavelength** is the distance, projected on the direction of progression,
  between two successive U-turns on the same side (absolute value). A U-turn's
  position here is its *centre*: the midpoint of the two points where the trace
  crosses the level ``uturn_prominence / 2`` below (above) the extremum on
  either side of it. It is the centre of a semicircular U-turn whatever the
  sampling, and insensitive to where noise puts the extreme sample on a
  rounded top.
* **Cycles**: ``n_cycles = (n_uturns - 1) // 2``; one cycle is two half-cycles.
* **Loops** (docs/model.md §7): the tangent turns by 2 pi or more between
  successive U-turns (``n_loops``; a tolerance of ``LOOP_TURNING_TOLERANCE``
  absorbs noise and the tangent at the U-turn), or the trace crosses itself
  (``n_self_crossings``, adjacent segments excluded).

Nothing here is random: every result is a deterministic function of the input.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from numbers import Integral, Real
from typing import Any

import numpy as np
from numpy.typing import ArrayLike, NDArray
from scipy.signal import find_peaks

from cnt_env.presets import SETTLED_FRACTION

__all__ = [
    "LOOP_TURNING_TOLERANCE",
    "PATTERNS",
    "SUBSTRATES",
    "MeasureOptions",
    "arc_length",
    "classify",
    "coil_radius",
    "drop_transient",
    "fit_circle",
    "has_loops",
    "measure",
    "self_crossings",
    "serpentine_measures",
    "uturns",
]

#: Pattern classes returned by :func:`classify` (docs/model.md §7, plus two fall-backs).
PATTERNS: tuple[str, ...] = (
    "coil",
    "serpentine-coil",
    "periodic-serpentine",
    "irregular-serpentine",
    "straight",
    "too_short",
    "unknown",
)
SUBSTRATES: tuple[str, ...] = ("flat", "stepped")

#: Fewest points a measured (post-transient) trace may have.
MIN_MEASURED_POINTS = 3
#: Slack on "the tangent turns by 2 pi" (rad): a U-turn-to-U-turn interval counts
#: k loops when its net turning is at least 2 pi k - LOOP_TURNING_TOLERANCE.
#: An interval of a loop-free serpentine turns by about 0 (apex to apex), a
#: coil's half-turn by pi, so pi/2 of slack cannot create a loop.
LOOP_TURNING_TOLERANCE = 0.5 * math.pi
#: A trace without U-turns or loops is "straight" when chord / arc length >= this.
STRAIGHT_MIN_CHORD_RATIO = 0.9

_SPREAD_PERCENTILES = (16.0, 84.0)
# Coil windows need enough points for a circle fit to mean anything.
_MIN_WINDOW_POINTS = 8
# A coil window must be within this relative tolerance of its circle's
# circumference (times coil_window_turns).
_TURN_LENGTH_TOLERANCE = 0.25
# First guess of the turning-rate scale (L_vb), about one turn of the paper's coil.
_FIRST_TURN_SCALE = 50.0
# U-turn prominence is evaluated within this arc length around each extremum
# (scipy's ``wlen``). It bounds the cost on traces whose extrema drift
# monotonically (otherwise O(n * n_peaks)) and is far longer than any half-cycle.
_PROMINENCE_WINDOW_ARC = 2000.0
# A U-turn's centre (its position along the progression) is taken on the level
# this fraction of uturn_prominence below (above) its extremum, in z.
_CAP_DEPTH = 0.5
# Batch sizes: array elements per circle-fit batch, candidate pairs per chunk.
_FIT_BATCH_ELEMENTS = 1_000_000
_PAIR_CHUNK = 1_000_000
# Grid cell = this many median segment lengths; segments whose bounding box
# covers more cells than _LONG_SEGMENT_CELLS are tested against all segments.
_CELL_SEGMENTS = 1.5
# Self-crossings whose later segments are closer than this arc length (L_vb) count as
# one loop event.
_CROSSING_EVENT_ARC = 20.0
_LONG_SEGMENT_CELLS = 64

FloatArray = NDArray[np.float64]
IntArray = NDArray[np.int64]


# --------------------------------------------------------------------------- options


def _check_float(
    name: str, value: Any, *, allow_zero: bool = False, upper: float | None = None
) -> None:
    if isinstance(value, bool) or not isinstance(value, Real):
        raise ValueError(f"MeasureOptions.{name} must be a real number, got {value!r}")
    v = float(value)
    if not math.isfinite(v):
        raise ValueError(f"MeasureOptions.{name} must be finite, got {v}")
    if v < 0.0 or (v == 0.0 and not allow_zero):
        kind = "non-negative" if allow_zero else "positive"
        raise ValueError(f"MeasureOptions.{name} must be {kind}, got {v}")
    if upper is not None and v > upper:
        raise ValueError(f"MeasureOptions.{name} must be at most {upper}, got {v}")


def _check_int(name: str, value: Any) -> None:
    if isinstance(value, bool) or not isinstance(value, Integral) or value < 1:
        raise ValueError(f"MeasureOptions.{name} must be an integer >= 1, got {value!r}")


@dataclass(frozen=True)
class MeasureOptions:
    """How a trace is measured (docs/model.md §7). Lengths in L_vb.

    The first six fields are the documented interface; the last five tune the
    classifier and the cost bound and rarely need changing.

    Attributes:
        transient_length: arc length dropped from the start of the trace before
            anything is measured (the start-up transient, docs/model.md §6 "Start-up").
        coil_window_turns: length of a coil-fit window, in turns of the trace.
        coil_max_rel_residual: a window is rejected when the RMS radial residual
            of its circle fit exceeds this fraction of the fitted radius.
        uturn_prominence: prominence (in z, L_vb) an extremum of z needs to be a
            U-turn.
        periodic_cv_max: a serpentine is periodic when the CVs of amplitude and
            wavelength over its settled part (``settled_fraction``) are both below
            this ...
        periodic_min_cycles: ... and it has at least this many cycles (fewer cycles
            with CVs below the bound: "too_short", periodicity cannot be confirmed).
        settled_fraction: the periodic / irregular decision takes the CVs over the
            last this fraction of the measured half-cycles (amplitudes) and of each
            side's U-turn spacings (wavelengths): the pattern the run settles into. A
            start-up whose amplitude decays over several cycles is not irregularity
            (at v̄ = 0.005-0.019 a cycle is 200-450 L_vb of trace, and a fixed
            ``transient_length`` drops less than one). The serpentine-coil rule counts
            the loops of the same settled part: loops of the start-up alone do not make
            a serpentine-coil. 1.0 judges the whole measured trace. The reported
            ``amplitude_cv`` and ``wavelength_cv`` are always the whole measured
            trace's.
        serpentine_coil_loop_density: a serpentine is a serpentine-coil when it has
            at least this many loops per cycle ...
        serpentine_coil_min_loops: ... and at least this many loops in all (one
            stray loop does not make a serpentine-coil).
        min_judged_cycles: fewer cycles than this, and not a serpentine-coil:
            "too_short" (neither periodicity nor irregularity can be judged).
        min_judged_length: a measured trace shorter than this (L_vb) is "too_short".
        coil_max_rel_spread: a coil needs relative radius spread
            ``(p84 - p16) / (2 median)`` below this.
        coil_min_coverage: a coil needs its accepted windows to cover at least
            this fraction of the measured arc length.
        coil_min_turn_sign_fraction: a coil needs at least this fraction of its
            accepted windows to turn the same way (turning "about monotone"), or ...
        coil_min_run_turns: ... every run of its accepted windows that turn the same
            way (in trace order) to span at least this many turns: a coil that
            reverses its handedness between two long coiled stretches (the H-bar = 200
            coil reverses once: 86% of its windows one way) is a coil, alternating
            loops (runs of one or two turns) are not.
        coil_loose_rel_residual: for the class only, a window counts towards the
            coil coverage when it is one turn of a circle (turning and length tests)
            with an RMS residual up to this fraction of its radius: a coil whose centre
            still drifts (a loose start-up coil) is a coil; its radius comes from the
            strict windows only.
        coil_min_strict_coverage: the strict windows give the radius only when they
            cover at least this fraction of the measured arc; below it the coil is a
            rosette that closes within ``coil_max_rel_residual`` only by chance, and its
            radius comes from the loose windows (``radius_windows`` "loose"). One stray
            circular window of a precessing start-up coil once gave R = 10.7 where the
            loops' radius was ~8.
        rough_turning_angle: median turning angle per vertex (rad) above which the
            trace is too rough to be a rod trace (noise, random walk): "unknown".
        crossing_pair_budget: most candidate segment pairs examined for
            self-crossings. Past it the count is a lower bound and
            ``self_crossings_complete`` is False (only piled-up coils get there).
    """

    transient_length: float = 200.0
    coil_window_turns: float = 1.0
    coil_max_rel_residual: float = 0.05
    uturn_prominence: float = 3.0
    periodic_cv_max: float = 0.10
    periodic_min_cycles: int = 10
    settled_fraction: float = SETTLED_FRACTION
    serpentine_coil_loop_density: float = 0.2
    serpentine_coil_min_loops: int = 2
    min_judged_cycles: int = 3
    min_judged_length: float = 100.0
    coil_max_rel_spread: float = 0.10
    coil_min_coverage: float = 0.8
    coil_min_turn_sign_fraction: float = 0.9
    coil_min_run_turns: float = 3.0
    coil_loose_rel_residual: float = 0.25
    coil_min_strict_coverage: float = 0.5
    rough_turning_angle: float = 0.25 * math.pi
    crossing_pair_budget: int = 2_000_000

    def __post_init__(self) -> None:
        _check_float("transient_length", self.transient_length, allow_zero=True)
        _check_float("coil_window_turns", self.coil_window_turns)
        _check_float("coil_max_rel_residual", self.coil_max_rel_residual)
        _check_float("uturn_prominence", self.uturn_prominence)
        _check_float("periodic_cv_max", self.periodic_cv_max)
        _check_int("periodic_min_cycles", self.periodic_min_cycles)
        _check_float("settled_fraction", self.settled_fraction, upper=1.0)
        _check_float("serpentine_coil_loop_density", self.serpentine_coil_loop_density)
        _check_int("serpentine_coil_min_loops", self.serpentine_coil_min_loops)
        _check_int("min_judged_cycles", self.min_judged_cycles)
        _check_float("min_judged_length", self.min_judged_length, allow_zero=True)
        _check_float("coil_max_rel_spread", self.coil_max_rel_spread)
        _check_float("coil_min_coverage", self.coil_min_coverage, upper=1.0)
        _check_float("coil_min_turn_sign_fraction", self.coil_min_turn_sign_fraction, upper=1.0)
        _check_float("coil_min_run_turns", self.coil_min_run_turns)
        _check_float("coil_loose_rel_residual", self.coil_loose_rel_residual)
        _check_float(
            "coil_min_strict_coverage", self.coil_min_strict_coverage, allow_zero=True, upper=1.0
        )
        _check_float("rough_turning_angle", self.rough_turning_angle, upper=math.pi)
        _check_int("crossing_pair_budget", self.crossing_pair_budget)


_DEFAULT_OPTIONS = MeasureOptions()


# --------------------------------------------------------------------------- input


def _plane(trace: ArrayLike, min_points: int = 2) -> FloatArray:
    """Validated ``(n, 2)`` float64 copy-or-view of a trace as ``(x, z)``."""
    try:
        arr = np.asarray(trace, dtype=np.float64)
    except (TypeError, ValueError) as exc:
        raise ValueError(f"trace must be a numeric (n, 2) or (n, 3) array: {exc}") from exc
    if arr.ndim != 2 or arr.shape[1] not in (2, 3):
        raise ValueError(
            f"trace must have shape (n, 2) as (x, z) or (n, 3) as (x, y, z); got {arr.shape}"
        )
    if arr.shape[0] < min_points:
        raise ValueError(f"trace is too short: {arr.shape[0]} points, need at least {min_points}")
    bad = ~np.isfinite(arr).all(axis=1)
    if bad.any():
        raise ValueError(f"trace has NaN or inf at point {int(np.flatnonzero(bad)[0])}")
    if arr.shape[1] == 3:
        arr = arr[:, [0, 2]]
    return arr


def arc_length(trace: ArrayLike) -> FloatArray:
    """Cumulative arc length at each point, starting at 0 (docs/model.md §7), shape ``(n,)``."""
    p = _plane(trace)
    s = np.empty(p.shape[0])
    s[0] = 0.0
    np.cumsum(np.hypot(np.diff(p[:, 0]), np.diff(p[:, 1])), out=s[1:])
    return s


def drop_transient(trace: ArrayLike, length: float) -> NDArray[np.float64]:
    """The trace from the first point at arc length >= ``length`` on (docs/model.md §7).

    The columns are kept as given ((n, 2) or (n, 3)). Raises ValueError when
    nothing would be left.
    """
    if isinstance(length, bool) or not isinstance(length, Real) or not length >= 0.0:
        raise ValueError(f"transient length must be a finite number >= 0, got {length!r}")
    if not math.isfinite(float(length)):
        raise ValueError(f"transient length must be finite, got {length!r}")
    s = arc_length(trace)  # validates
    arr = np.asarray(trace, dtype=np.float64)
    start = int(np.searchsorted(s, float(length), side="left"))
    if start >= s.shape[0]:
        raise ValueError(
            f"trace has arc length {s[-1]:.6g} L_vb, not more than the transient "
            f"{float(length):.6g} L_vb: nothing left to measure. Simulate longer or lower "
            "MeasureOptions.transient_length."
        )
    return arr[start:]


@dataclass(frozen=True)
class _Measured:
    """The measured part of a trace, with what every measurement needs.

    points: (n, 2) nodes (x, z); s: (n,) arc length from the first measured node;
    heading: (n,) unwrapped tangent angle atan2(dz, dx) of the segment leaving
    each node (the last node repeats the last segment; zero-length segments take
    the previous heading); offset: index of points[0] in the trace as passed in.
    """

    points: FloatArray
    s: FloatArray
    heading: FloatArray
    offset: int


def _headings(p: FloatArray) -> FloatArray:
    d = np.diff(p, axis=0)
    length = np.hypot(d[:, 0], d[:, 1])
    valid = length > 0.0
    if not valid.any():
        raise ValueError("trace is degenerate: all measured points coincide")
    angle = np.arctan2(d[:, 1], d[:, 0])
    # forward-fill zero-length segments (back-fill any leading ones)
    src = np.where(valid, np.arange(valid.size), -1)
    src = np.maximum.accumulate(src)
    src[src < 0] = int(np.flatnonzero(valid)[0])
    seg_heading = np.unwrap(angle[src])
    return np.append(seg_heading, seg_heading[-1])


def _prepare(trace: ArrayLike, options: MeasureOptions) -> _Measured:
    full = _plane(trace)
    s_full = np.empty(full.shape[0])
    s_full[0] = 0.0
    np.cumsum(np.hypot(np.diff(full[:, 0]), np.diff(full[:, 1])), out=s_full[1:])
    start = int(np.searchsorted(s_full, options.transient_length, side="left"))
    n_left = full.shape[0] - start
    if n_left < MIN_MEASURED_POINTS:
        raise ValueError(
            f"trace is too short: {s_full[-1]:.6g} L_vb of arc length and {full.shape[0]} "
            f"points leave {max(n_left, 0)} points after dropping transient_length="
            f"{options.transient_length:g} L_vb; need at least {MIN_MEASURED_POINTS}. "
            "Simulate longer or lower MeasureOptions.transient_length."
        )
    p = np.ascontiguousarray(full[start:])
    return _Measured(points=p, s=s_full[start:] - s_full[start], heading=_headings(p), offset=start)


def _options(options: MeasureOptions | None) -> MeasureOptions:
    if options is None:
        return _DEFAULT_OPTIONS
    if not isinstance(options, MeasureOptions):
        raise ValueError(f"options must be a MeasureOptions or None, got {type(options).__name__}")
    return options


# --------------------------------------------------------------------------- statistics


def _spread(values: FloatArray) -> tuple[float, float]:
    if values.size == 0:
        return (math.nan, math.nan)
    lo, hi = np.percentile(values, _SPREAD_PERCENTILES)
    return (float(lo), float(hi))


def _median(values: FloatArray) -> float:
    return float(np.median(values)) if values.size else math.nan


def _cv(values: FloatArray) -> float:
    if values.size < 2:
        return math.nan
    mean = float(np.mean(values))
    return float(np.std(values, ddof=1)) / abs(mean) if mean != 0.0 else math.nan


# --------------------------------------------------------------------------- circle fits


def _fit_circles(
    x: FloatArray, z: FloatArray, mask: NDArray[np.bool_]
) -> tuple[FloatArray, FloatArray, FloatArray, FloatArray]:
    """Taubin circle fits of many windows at once.

    ``x``, ``z``, ``mask`` are ``(n_windows, m)``; ``mask`` marks real points
    (padding rows are zeroed, which leaves the SVD unchanged). Follows Chernov's
    SVD form of Taubin's fit. Returns centre x, centre z, radius, RMS radial
    residual, each ``(n_windows,)``; degenerate windows give NaN or inf.
    """
    count = mask.sum(axis=1).astype(np.float64)
    xm = np.where(mask, x, 0.0).sum(axis=1) / count
    zm = np.where(mask, z, 0.0).sum(axis=1) / count
    xc = np.where(mask, x - xm[:, None], 0.0)
    zc = np.where(mask, z - zm[:, None], 0.0)
    r2 = xc * xc + zc * zc
    r2_mean = r2.sum(axis=1) / count
    with np.errstate(divide="ignore", invalid="ignore"):
        norm = 2.0 * np.sqrt(r2_mean)
        w = np.where(mask, (r2 - r2_mean[:, None]) / norm[:, None], 0.0)
        design = np.stack([w, xc, zc], axis=-1)
        design = np.nan_to_num(design, nan=0.0, posinf=0.0, neginf=0.0)
        _, _, vt = np.linalg.svd(design, full_matrices=False)
        coef = vt[:, 2, :]  # right singular vector of the smallest singular value
        a = coef[:, 0] / norm
        b, c = coef[:, 1], coef[:, 2]
        d = -r2_mean * a
        cx = -b / (2.0 * a) + xm
        cz = -c / (2.0 * a) + zm
        radius = np.sqrt(b * b + c * c - 4.0 * a * d) / (2.0 * np.abs(a))
        dist = np.hypot(x - cx[:, None], z - cz[:, None]) - radius[:, None]
        rms = np.sqrt(np.where(mask, dist * dist, 0.0).sum(axis=1) / count)
    return cx, cz, radius, rms


def fit_circle(points: ArrayLike) -> tuple[float, float, float, float]:
    """Algebraic least-squares circle through ``points`` (docs/model.md §7, "Coil radius").

    Uses Taubin's fit (in Chernov's SVD form) rather than Kasa's: Kasa's
    minimises the algebraic distance with no normalisation and is biased towards
    small radii on short or noisy arcs, while Taubin's normalisation by the
    gradient makes it nearly unbiased and, unlike Pratt's, it needs no
    generalised eigenproblem. ``points`` is ``(n >= 3, 2)`` (x, z) or ``(n, 3)``.

    Returns ``(cx, cz, radius, rms_residual)``, the residual being the RMS of
    ``|p - c| - radius``. Collinear points give a huge or infinite radius.
    """
    p = _plane(points, min_points=3)
    cx, cz, radius, rms = _fit_circles(p[None, :, 0], p[None, :, 1], np.ones((1, p.shape[0]), bool))
    return float(cx[0]), float(cz[0]), float(radius[0]), float(rms[0])


def _turning_rate(s: FloatArray, heading: FloatArray, scale: float) -> float:
    """Median |net turning| / arc length over windows of arc length ``scale``."""
    end = np.searchsorted(s, s + scale, side="left")
    ok = end < s.size
    if not ok.any():
        return math.nan
    start = np.flatnonzero(ok)
    end = end[ok]
    return float(np.median(np.abs(heading[end] - heading[start]) / (s[end] - s[start])))


def _turn_length(s: FloatArray, heading: FloatArray) -> float:
    """Arc length over which the tangent turns by 2 pi, on median (inf if it does not)."""
    total = float(s[-1])
    scale = min(_FIRST_TURN_SCALE, 0.5 * total)
    for _ in range(2):  # one refinement with a window of one estimated turn
        rate = _turning_rate(s, heading, scale)
        if not rate > 0.0:
            return math.inf
        scale = 2.0 * math.pi / rate
        if scale > total:
            return scale
    return scale


def _coil(m: _Measured, options: MeasureOptions) -> dict[str, Any]:
    s, p, heading = m.s, m.points, m.heading
    total = float(s[-1])
    window = _turn_length(s, heading) * options.coil_window_turns
    empty = np.empty(0)
    result: dict[str, Any] = {
        "median": math.nan,
        "spread": (math.nan, math.nan),
        "n_windows": 0,
        "n_rejected": 0,
        "radii": empty,
        "window_length": float(window),
        "coverage": 0.0,
        "loose_coverage": 0.0,
        "turn_sign_fraction": math.nan,
        "min_sign_run_turns": 0.0,
        "radius_windows": "strict",
    }
    if not math.isfinite(window) or window > total:
        return result
    stride = 0.25 * window
    starts = stride * np.arange(math.floor((total - window) / stride) + 1)
    i0 = np.searchsorted(s, starts, side="left")
    i1 = np.searchsorted(s, starts + window, side="right")
    keep = (i1 - i0) >= _MIN_WINDOW_POINTS
    starts, i0, i1 = starts[keep], i0[keep], i1[keep]
    n_win = starts.size
    if n_win == 0:
        return result
    radius = np.empty(n_win)
    rms = np.empty(n_win)
    counts = i1 - i0
    # Batches of windows, padded to the batch's longest window.
    batch = max(1, _FIT_BATCH_ELEMENTS // int(counts.max()))
    for b0 in range(0, n_win, batch):
        b1 = min(n_win, b0 + batch)
        cols = np.arange(int(counts[b0:b1].max()))
        mask = cols[None, :] < counts[b0:b1, None]
        idx = np.minimum(i0[b0:b1, None] + cols[None, :], s.size - 1)
        _, _, radius[b0:b1], rms[b0:b1] = _fit_circles(p[idx, 0], p[idx, 1], mask)
    turning = heading[i1 - 1] - heading[i0]
    with np.errstate(invalid="ignore", divide="ignore"):
        one_turn = (
            np.isfinite(radius)
            # a window of one turn must turn by about 2 pi and be about one
            # circumference long; a big circle through a meander is neither
            & (np.abs(turning) >= math.pi * options.coil_window_turns)
            & (
                np.abs(window / (2.0 * math.pi * options.coil_window_turns * radius) - 1.0)
                <= _TURN_LENGTH_TOLERANCE
            )
        )
        accepted = one_turn & (rms <= options.coil_max_rel_residual * radius)
        loose = one_turn & (rms <= options.coil_loose_rel_residual * radius)
    radii = radius[accepted]
    result["n_windows"] = n_win
    result["n_rejected"] = int(n_win - radii.size)
    result["radii"] = radii
    if radii.size:
        result["coverage"] = _coverage(starts[accepted], window, total)
    if loose.any():
        result["loose_coverage"] = _coverage(starts[loose], window, total)
    # the strict windows set the radius when they cover enough of the arc; else the loose
    # ones (a coil that almost never closes within 5%, a precessing rosette), which say so
    strict = radii.size > 0 and (
        result["coverage"] >= options.coil_min_strict_coverage or not loose.any()
    )
    if strict or loose.any():
        use = accepted if strict else loose
        result["median"] = _median(radius[use])
        result["spread"] = _spread(radius[use])
        signs = np.sign(turning[use])
        result["turn_sign_fraction"] = float(max((signs > 0).mean(), (signs < 0).mean()))
        result["min_sign_run_turns"] = _min_sign_run(signs, starts[use], window, options)
        if not strict:
            result["radius_windows"] = "loose"
    return result


def _coverage(starts: FloatArray, window: float, total: float) -> float:
    """Fraction of the measured arc ``total`` inside windows of length ``window`` that
    start at ``starts`` (ascending)."""
    covered = float(np.minimum(np.diff(starts), window).sum()) + window
    return min(1.0, covered / total)


def _min_sign_run(
    signs: FloatArray, starts: FloatArray, window: float, options: MeasureOptions
) -> float:
    """The shortest span, in turns, of a run of windows (trace order) turning the same
    way: from the first window's start to the last one's end."""
    cuts = np.flatnonzero(np.diff(signs) != 0) + 1
    first = np.concatenate(([0], cuts))
    last = np.concatenate((cuts - 1, [signs.size - 1]))
    spans = (starts[last] - starts[first] + window) / window * options.coil_window_turns
    return float(spans.min())


def coil_radius(trace: ArrayLike, options: MeasureOptions | None = None) -> dict[str, Any]:
    """Coil radius from circle fits over sliding windows (docs/model.md §7, "Coil radius").

    The window is ``coil_window_turns`` turns long, a turn being the arc length
    over which the tangent turns by 2 pi on median (from the windowed turning
    rate, refined once); the stride is a quarter window. Each window gets a
    Taubin fit (:func:`fit_circle`) and is rejected when its RMS residual exceeds
    ``coil_max_rel_residual`` times its radius, or when it is not one turn of
    its circle: it turns by less than half the expected angle, or its length is
    not within 25% of the fitted circumference (times ``coil_window_turns``).

    Returns ``median`` (NaN if no window is accepted), ``spread`` = (p16, p84) of
    the accepted radii, ``n_windows`` (fitted), ``n_rejected``, ``radii``
    (accepted, in trace order), ``window_length``, ``coverage`` (fraction of the
    measured arc length inside accepted windows) and ``turn_sign_fraction``. When the
    accepted windows cover less than ``coil_min_strict_coverage`` (none, or a few that
    close by chance) but some are one turn within ``coil_loose_rel_residual`` (a coil
    that precesses, a rosette), ``median``, ``spread`` and ``turn_sign_fraction`` come
    from those loose windows and ``radius_windows`` says ``"loose"`` (else
    ``"strict"``); ``loose_coverage`` is their coverage.
    """
    options = _options(options)
    return _coil(_prepare(trace, options), options)


# --------------------------------------------------------------------------- U-turns


def _uturns(m: _Measured, options: MeasureOptions) -> dict[str, Any]:
    z = m.points[:, 1]
    spacing = float(m.s[-1]) / (z.size - 1)
    wlen = None
    if spacing > 0.0 and m.s[-1] > _PROMINENCE_WINDOW_ARC:
        wlen = max(3, int(_PROMINENCE_WINDOW_ARC / spacing) | 1)
    top, _ = find_peaks(z, prominence=options.uturn_prominence, wlen=wlen)
    bottom, _ = find_peaks(-z, prominence=options.uturn_prominence, wlen=wlen)
    idx = np.concatenate([top, bottom]).astype(np.int64)
    side = np.concatenate([np.ones(top.size, np.int64), -np.ones(bottom.size, np.int64)])
    order = np.argsort(idx, kind="stable")
    idx, side = idx[order], side[order]
    if idx.size > 1:
        # Two same-side extrema in a row: keep the more extreme (first on ties),
        # so that U-turns alternate between the two sides.
        run = np.concatenate([[0], np.cumsum(side[1:] != side[:-1])])
        order = np.lexsort((idx, -side * z[idx], run))
        first = order[np.concatenate([[True], run[order][1:] != run[order][:-1]])]
        idx, side = idx[first], side[first]
    return {
        "indices": idx + m.offset,
        "sides": side,
        "positions": m.points[idx].copy(),
        "centres": _cap_centres(m.points, idx, side, _CAP_DEPTH * options.uturn_prominence),
        "arc_length": m.s[idx].copy(),
        "local_indices": idx,
    }


def _cap_centres(p: FloatArray, idx: IntArray, side: IntArray, depth: float) -> FloatArray:
    """Midpoint of where each U-turn's cap meets the level ``depth`` below its extremum.

    The cap is the contiguous run of points within ``depth`` (in z) of the
    extremum; its two ends are interpolated onto the level. For a semicircular
    U-turn the midpoint is the centre, whatever the sampling phase, and noise
    moves it far less than it moves the extreme sample on a rounded top.
    """
    z = p[:, 1]
    out = np.empty((idx.size, 2))
    n = z.size
    for k, (i, sgn) in enumerate(zip(idx, side, strict=True)):
        level = z[i] - sgn * depth
        lo = int(idx[k - 1]) if k > 0 else 0
        hi = int(idx[k + 1]) if k + 1 < idx.size else n - 1
        outside = np.flatnonzero(sgn * (z[lo : hi + 1] - level) < 0.0) + lo
        cut = int(np.searchsorted(outside, i))
        ends = []
        for o, inner in (
            (int(outside[cut - 1]), int(outside[cut - 1]) + 1) if cut > 0 else (lo, lo),
            (int(outside[cut]), int(outside[cut]) - 1) if cut < outside.size else (hi, hi),
        ):
            if o == inner:  # the cap runs into the neighbouring U-turn or the trace end
                ends.append(p[o])
            else:
                w = (level - z[o]) / (z[inner] - z[o])
                ends.append(p[o] + w * (p[inner] - p[o]))
        out[k] = 0.5 * (ends[0] + ends[1])
    return out


def uturns(trace: ArrayLike, options: MeasureOptions | None = None) -> dict[str, Any]:
    """U-turns: extrema of z against arc length with prominence >= ``uturn_prominence``
    (docs/model.md §7, "Serpentine amplitude and wavelength").

    Maxima and minima come from ``scipy.signal.find_peaks`` on z and -z, merged
    in trace order; of two same-side extrema in a row only the more extreme is
    kept, so sides alternate. Returns ``indices`` (into the trace as passed in),
    ``sides`` (+1 maximum of z, -1 minimum), ``positions`` ((k, 2) as (x, z), the
    extreme points), ``centres`` ((k, 2), U-turn centres, see the module docstring)
    and ``arc_length`` (from the start of the measured trace).
    """
    options = _options(options)
    out = _uturns(_prepare(trace, options), options)
    del out["local_indices"]
    return out


def _direction(
    m: _Measured, flow_direction: ArrayLike | None, u: dict[str, Any] | None = None
) -> FloatArray | None:
    if flow_direction is None:
        # progression of same-side U-turn centres (the trace's end points fall anywhere
        # along a run, which would tilt an end-to-end estimate), else end to end
        d = m.points[-1] - m.points[0]
        if u is not None:
            for s in (1, -1):
                c = u["centres"][u["sides"] == s]
                if len(c) >= 2:
                    d = c[-1] - c[0]
                    break
    else:
        try:
            d = np.asarray(flow_direction, dtype=np.float64).reshape(-1)
        except (TypeError, ValueError):
            d = np.empty(0)
        if d.shape != (2,) or not np.isfinite(d).all():
            raise ValueError(
                f"flow_direction must be two finite numbers (x, z), got {flow_direction!r}"
            )
        if not np.hypot(d[0], d[1]) > 0.0:
            raise ValueError("flow_direction must be a non-zero vector (x, z)")
    norm = float(np.hypot(d[0], d[1]))
    return d / norm if norm > 0.0 else None


def _last(values: FloatArray, fraction: float) -> FloatArray:
    return values[values.size - math.ceil(fraction * values.size) :]


def _serpentine(
    m: _Measured, u: dict[str, Any], flow_direction: ArrayLike | None, settled: float = 1.0
) -> dict[str, Any]:
    idx, side = u["local_indices"], u["sides"]
    peak_to_peak = np.abs(np.diff(m.points[idx, 1]))
    amplitudes = 0.5 * peak_to_peak
    direction = _direction(m, flow_direction, u)
    if direction is None:
        per_side = [np.empty(0), np.empty(0)]
    else:
        along = u["centres"] @ direction
        per_side = [np.abs(np.diff(along[side > 0])), np.abs(np.diff(along[side < 0]))]
    wavelengths = np.concatenate(per_side)
    settled_amplitudes = _last(amplitudes, settled)
    # the settled part starts at this U-turn (ordinal)
    settled_uturn = amplitudes.size - settled_amplitudes.size
    return {
        "amplitude": _median(amplitudes),
        "peak_to_peak": _median(peak_to_peak),
        "amplitude_spread": _spread(amplitudes),
        "amplitude_cv": _cv(amplitudes),
        "wavelength": _median(wavelengths),
        "wavelength_spread": _spread(wavelengths),
        "wavelength_cv": _cv(wavelengths),
        "settled_uturn": settled_uturn,
        "settled_amplitude_cv": _cv(settled_amplitudes),
        "settled_wavelength_cv": _cv(np.concatenate([_last(w, settled) for w in per_side])),
        "n_uturns": int(idx.size),
        "n_cycles": max(0, (int(idx.size) - 1) // 2),
        "settled_cycles": max(0, (int(idx.size) - settled_uturn - 1) // 2),
        "amplitudes": amplitudes,
        "wavelengths": wavelengths,
        "direction": (math.nan, math.nan) if direction is None else tuple(map(float, direction)),
    }


def serpentine_measures(
    trace: ArrayLike,
    options: MeasureOptions | None = None,
    flow_direction: ArrayLike | None = (1.0, 0.0),
) -> dict[str, Any]:
    """Serpentine amplitude and wavelength from the U-turns (docs/model.md §7).

    Amplitude: median |dz| / 2 between successive (opposite) U-turns (``peak_to_peak``
    is the median |dz|). Wavelength:
    median |distance along the direction of progression| between successive
    same-side U-turns, both sides pooled. The direction of progression is
    ``flow_direction`` as (x, z), or, if None, the mean displacement of the
    measured trace (end minus start).

    Returns ``amplitude``, ``amplitude_spread`` (p16, p84), ``amplitude_cv``, the
    same three for ``wavelength``, ``settled_amplitude_cv`` and ``settled_wavelength_cv``
    (over the last ``options.settled_fraction`` of the samples), ``n_uturns``,
    ``n_cycles`` and the samples ``amplitudes``, ``wavelengths``. Values without
    samples are NaN.
    """
    options = _options(options)
    m = _prepare(trace, options)
    return _serpentine(m, _uturns(m, options), flow_direction, options.settled_fraction)


# --------------------------------------------------------------------------- loops


def _cross_test(
    ax: FloatArray,
    az: FloatArray,
    bx: FloatArray,
    bz: FloatArray,
    cx: FloatArray,
    cz: FloatArray,
    dx: FloatArray,
    dz: FloatArray,
) -> NDArray[np.bool_]:
    """Whether segments a-b and c-d cross, element by element.

    Orientation tests with 0 counted as positive: a crossing through a shared
    vertex of the other polyline counts once, a tangential touch twice (parity
    is right); exact degeneracies are measure-zero for real traces.
    """
    ex, ez = bx - ax, bz - az
    fx, fz = dx - cx, dz - cz
    o1 = ex * (cz - az) - ez * (cx - ax) >= 0.0
    o2 = ex * (dz - az) - ez * (dx - ax) >= 0.0
    o3 = fx * (az - cz) - fz * (ax - cx) >= 0.0
    o4 = fx * (bz - cz) - fz * (bx - cx) >= 0.0
    return (o1 != o2) & (o3 != o4)


def _crossing_pairs(p: FloatArray, budget: int) -> tuple[IntArray, bool]:
    """Crossing pairs of non-adjacent segments of polyline ``p`` ((n, 2)).

    A uniform grid (cell = ``_CELL_SEGMENTS`` median segment lengths) hashes the
    segments' bounding boxes; a pair sharing several cells is tested only in the
    cell of the lower-left corner of its bounding-box intersection, so each pair
    is tested once. Segments spanning many cells are tested against all others.
    Cost ~ n log n plus the number of candidate pairs, capped by ``budget``.
    Returns sorted (k, 2) original segment indices (i < j) and whether the
    search was complete. Zero-length segments are skipped; segments separated
    only by zero-length ones count as adjacent.
    """
    d = np.diff(p, axis=0)
    seg_len = np.hypot(d[:, 0], d[:, 1])
    seg_ids = np.flatnonzero(seg_len > 0.0)
    n_seg = seg_ids.size
    empty = np.empty((0, 2), np.int64)
    if n_seg < 3:
        return empty, True
    ax, az = p[seg_ids, 0], p[seg_ids, 1]
    bx, bz = p[seg_ids + 1, 0], p[seg_ids + 1, 1]
    lox, loz = np.minimum(ax, bx), np.minimum(az, bz)
    hix, hiz = np.maximum(ax, bx), np.maximum(az, bz)
    cell = _CELL_SEGMENTS * float(np.median(seg_len[seg_ids]))
    clx = np.floor((lox - lox.min()) / cell).astype(np.int64)
    clz = np.floor((loz - loz.min()) / cell).astype(np.int64)
    nx = np.floor((hix - lox.min()) / cell).astype(np.int64) - clx + 1
    nz = np.floor((hiz - loz.min()) / cell).astype(np.int64) - clz + 1
    n_cells = nx * nz
    is_long = n_cells > _LONG_SEGMENT_CELLS

    found: list[IntArray] = []

    def test(i: IntArray, j: IntArray) -> None:
        """Record the crossing pairs among segment pairs (i, j), i < j."""
        ok = (
            (j - i > 1)
            & (np.maximum(lox[i], lox[j]) <= np.minimum(hix[i], hix[j]))
            & (np.maximum(loz[i], loz[j]) <= np.minimum(hiz[i], hiz[j]))
        )
        i, j = i[ok], j[ok]
        hit = _cross_test(ax[i], az[i], bx[i], bz[i], ax[j], az[j], bx[j], bz[j])
        if hit.any():
            found.append(np.stack([i[hit], j[hit]], axis=1))

    # Long segments against every segment (a long-long pair once).
    examined = 0
    all_ids = np.arange(n_seg)
    for i in np.flatnonzero(is_long):
        j = all_ids[~is_long | (all_ids > i)]
        if examined + j.size > budget:
            return _finish(found, seg_ids, empty), False
        test(np.minimum(i, j), np.maximum(i, j))
        examined += j.size

    # Grid over the short segments: one entry per (segment, covered cell),
    # sorted by cell and, within a cell, by segment.
    short = np.flatnonzero(~is_long)
    reps = n_cells[short]
    e_seg = np.repeat(short, reps)
    local = np.arange(e_seg.size) - np.repeat(np.cumsum(reps) - reps, reps)
    e_x = clx[e_seg] + local // nz[e_seg]
    e_z = clz[e_seg] + local % nz[e_seg]
    key = e_x * (int(e_z.max()) + 1) + e_z
    order = np.argsort(key, kind="stable")
    key, e_seg, e_x, e_z = key[order], e_seg[order], e_x[order], e_z[order]
    e_clx, e_clz = clx[e_seg], clz[e_seg]  # entry-local copies: gathers stay in cache
    n_ent = key.size
    new_group = np.concatenate([[True], key[1:] != key[:-1]])
    group_end = np.append(np.flatnonzero(new_group)[1:], n_ent)
    partners = group_end[np.cumsum(new_group) - 1] - np.arange(n_ent) - 1
    cum = np.concatenate([[0], np.cumsum(partners)])
    complete = examined + int(cum[-1]) <= budget
    limit = min(int(cum[-1]), budget - examined)
    pos = 0
    while pos < n_ent and cum[pos] < limit:
        end = int(np.searchsorted(cum, min(cum[pos] + _PAIR_CHUNK, limit), side="right")) - 1
        rows = np.arange(pos, max(end, pos + 1))
        cnt = partners[rows]
        first = np.repeat(rows, cnt)
        second = first + 1 + np.arange(first.size) - np.repeat(np.cumsum(cnt) - cnt, cnt)
        # test a pair only in the cell holding the corner of its box intersection
        home = (np.maximum(e_clx[first], e_clx[second]) == e_x[first]) & (
            np.maximum(e_clz[first], e_clz[second]) == e_z[first]
        )
        test(e_seg[first[home]], e_seg[second[home]])
        pos = int(rows[-1]) + 1
    return _finish(found, seg_ids, empty), complete


def _finish(found: list[IntArray], seg_ids: IntArray, empty: IntArray) -> IntArray:
    if not found:
        return empty
    pairs = seg_ids[np.concatenate(found)]
    order = np.lexsort((pairs[:, 1], pairs[:, 0]))
    return pairs[order]


def self_crossings(
    trace: ArrayLike, max_candidate_pairs: int = _DEFAULT_OPTIONS.crossing_pair_budget
) -> tuple[IntArray, bool]:
    """Pairs of non-adjacent segments of the whole trace that cross (docs/model.md §7, loops).

    Segment ``i`` joins points ``i`` and ``i + 1``. Grid-hashed, about
    O(n log n + candidates). No transient is dropped here. Returns ``(pairs,
    complete)``: sorted (k, 2) int array with ``i < j``, and False when more than
    ``max_candidate_pairs`` candidates existed (then ``pairs`` is a subset).
    """
    _check_int("crossing_pair_budget", max_candidate_pairs)
    return _crossing_pairs(_plane(trace), int(max_candidate_pairs))


def _events(closing: FloatArray) -> int:
    """Crossing events: crossing pairs whose later segments (where a loop closes, sorted
    arc lengths ``closing``) lie within _CROSSING_EVENT_ARC of each other are one event (a
    loop may cross itself and its neighbouring legs a few times)."""
    return int(1 + np.count_nonzero(np.diff(closing) > _CROSSING_EVENT_ARC)) if closing.size else 0


def _loops(
    m: _Measured, options: MeasureOptions, u: dict[str, Any], settled_uturn: int = 0
) -> dict[str, Any]:
    n = m.points.shape[0]
    bounds = np.unique(np.concatenate([[0], u["local_indices"], [n - 1]]))
    turning = np.diff(m.heading[bounds])
    per_interval = np.floor((np.abs(turning) + LOOP_TURNING_TOLERANCE) / (2.0 * math.pi))
    pairs, complete = _crossing_pairs(m.points, options.crossing_pair_budget)
    n_loops = int(per_interval.sum())
    closing = np.sort(m.s[pairs[:, 1]])
    # the settled part (MeasureOptions.settled_fraction): from its first U-turn on
    start = int(u["local_indices"][settled_uturn]) if settled_uturn > 0 else 0
    settled_loops = int(per_interval[bounds[:-1] >= start].sum())
    settled_events = _events(closing[closing >= m.s[start]])
    return {
        "has_loops": bool(n_loops > 0 or pairs.shape[0] > 0),
        "n_loops": n_loops,
        "n_loop_events": max(n_loops, _events(closing)),
        "settled_loop_events": max(settled_loops, settled_events),
        "n_self_crossings": int(pairs.shape[0]),
        "self_crossings_complete": bool(complete),
        "interval_turning": turning,
    }


def has_loops(trace: ArrayLike, options: MeasureOptions | None = None) -> dict[str, Any]:
    """Loops of a serpentine-coil (docs/model.md §7, "Pattern class").

    Two independent counts on the measured trace: ``n_loops``, full turns of the
    tangent between successive U-turns (also from the start to the first and
    from the last to the end; an interval turning by theta counts
    floor((|theta| + LOOP_TURNING_TOLERANCE) / 2 pi)); and ``n_self_crossings``,
    crossings of non-adjacent segments (:func:`self_crossings`). ``has_loops``
    is True if either is non-zero. Also ``self_crossings_complete`` and
    ``interval_turning`` (net turning of each interval, rad).

    A loop wide enough to make its own U-turns (z excursion above
    ``uturn_prominence``) is split into half-turns and escapes ``n_loops``; a
    real loop crosses itself, so ``n_self_crossings`` still catches it.
    """
    options = _options(options)
    m = _prepare(trace, options)
    return _loops(m, options, _uturns(m, options))


# --------------------------------------------------------------------------- classes


def _median_vertex_turning(m: _Measured) -> float:
    turn = np.diff(m.heading[:-1])  # per interior vertex (zero-length segments give 0)
    d = np.diff(m.points, axis=0)
    real = np.hypot(d[:, 0], d[:, 1]) > 0.0
    both = real[1:] & real[:-1]
    return float(np.median(np.abs(turn[both]))) if both.any() else 0.0


def _pattern(
    options: MeasureOptions,
    substrate: str,
    rough: float,
    chord_ratio: float,
    length: float,
    coil: dict[str, Any],
    serp: dict[str, Any],
    loops: dict[str, Any],
) -> str:
    if rough > options.rough_turning_angle:
        return "unknown"
    if length < options.min_judged_length:
        return "too_short"
    median = coil["median"]
    # a stepped trace with U-turns whose tangent never makes a full turn (no loop, no
    # self-crossing) is a meander, not a coil, however well its caps fit one circle
    meander = substrate == "stepped" and serp["n_uturns"] >= 2 and not loops["has_loops"]
    if math.isfinite(median) and not meander:
        p16, p84 = coil["spread"]
        if (
            (p84 - p16) / (2.0 * median) < options.coil_max_rel_spread
            and coil["loose_coverage"] >= options.coil_min_coverage
            and (
                coil["turn_sign_fraction"] >= options.coil_min_turn_sign_fraction
                or coil["min_sign_run_turns"] >= options.coil_min_run_turns
            )
        ):
            return "coil"
    if substrate == "stepped" and serp["n_uturns"] >= 2:
        cycles = serp["n_cycles"]
        # loops of the settled pattern: a start-up's loops do not make a serpentine-coil
        events = loops["settled_loop_events"]
        if events >= options.serpentine_coil_min_loops and (
            events >= options.serpentine_coil_loop_density * max(serp["settled_cycles"], 1)
        ):
            return "serpentine-coil"
        if cycles < options.min_judged_cycles:
            return "too_short"
        regular = (  # the settled pattern's spread (MeasureOptions.settled_fraction)
            serp["settled_amplitude_cv"] < options.periodic_cv_max
            and serp["settled_wavelength_cv"] < options.periodic_cv_max
        )
        if regular:
            return "periodic-serpentine" if cycles >= options.periodic_min_cycles else "too_short"
        return "irregular-serpentine"
    if serp["n_uturns"] == 0 and not loops["has_loops"] and chord_ratio >= STRAIGHT_MIN_CHORD_RATIO:
        return "straight"
    return "unknown"


def measure(
    trace: ArrayLike,
    options: MeasureOptions | None = None,
    substrate: str = "flat",
    flow_direction: ArrayLike | None = (1.0, 0.0),
) -> dict[str, Any]:
    """Every measurement of docs/model.md §7 on the trace, as a JSON-friendly dict.

    ``substrate`` is ``"flat"`` or ``"stepped"`` (see :func:`classify`);
    ``flow_direction`` is the direction of progression for the wavelength
    (:func:`serpentine_measures`). Absent values are ``float('nan')``; spreads are
    ``[p16, p84]`` lists. Keys: ``pattern``, ``substrate``, ``measured_length``,
    ``transient_length``, ``n_points``, ``coil_radius``, ``coil_radius_spread``,
    ``coil_n_windows``, ``coil_n_rejected``, ``coil_coverage``, ``coil_loose_coverage``,
    ``coil_radius_windows`` (``"strict"``, or ``"loose"`` when the windows that close
    within ``coil_max_rel_residual`` cover less than ``coil_min_strict_coverage`` and
    the radius is the loose windows'), ``amplitude``,
    ``amplitude_spread``, ``amplitude_cv``, ``wavelength``, ``wavelength_spread``,
    ``wavelength_cv``, ``settled_amplitude_cv`` and ``settled_wavelength_cv`` (the CVs
    over the last ``settled_fraction`` of the U-turns, which decide periodic against
    irregular), ``settled_loop_events`` (the loop events of that part, which decide
    serpentine-coil), ``wavelength_progression`` (same-side U-turn spacing along
    the trace's own direction of progression, ``progression_direction``; with the
    paper's frame, wavelength along x, it differs when the flow is oblique),
    ``n_cycles``, ``n_uturns``, ``n_loops``, ``n_loop_events``, ``loop_density``
    (loop events per cycle), ``n_self_crossings``, ``self_crossings_complete``,
    ``median_vertex_turning``.
    """
    options = _options(options)
    if substrate not in SUBSTRATES:
        raise ValueError(f"substrate must be one of {SUBSTRATES}, got {substrate!r}")
    m = _prepare(trace, options)
    coil = _coil(m, options)
    u = _uturns(m, options)
    serp = _serpentine(m, u, flow_direction, options.settled_fraction)
    loops = _loops(m, options, u, serp["settled_uturn"])
    rough = _median_vertex_turning(m)
    length = float(m.s[-1])
    chord = float(np.hypot(*(m.points[-1] - m.points[0])))
    pattern = _pattern(options, substrate, rough, chord / length, length, coil, serp, loops)
    prog = _serpentine(m, u, None)
    cycles = max(int(serp["n_cycles"]), 1)
    return {
        "pattern": pattern,
        "substrate": substrate,
        "measured_length": length,
        "transient_length": float(options.transient_length),
        "settled_fraction": float(options.settled_fraction),
        "n_points": int(m.points.shape[0]),
        # a loose (rosette) radius only where the trace is a coil
        "coil_radius": float(coil["median"])
        if coil["radius_windows"] == "strict" or pattern == "coil"
        else math.nan,
        "coil_radius_spread": [float(v) for v in coil["spread"]],
        "coil_n_windows": int(coil["n_windows"]),
        "coil_n_rejected": int(coil["n_rejected"]),
        "coil_coverage": float(coil["coverage"]),
        "coil_loose_coverage": float(coil["loose_coverage"]),
        "coil_radius_windows": coil["radius_windows"],
        "amplitude": float(serp["amplitude"]),
        "peak_to_peak": float(serp["peak_to_peak"]),
        "amplitude_spread": [float(v) for v in serp["amplitude_spread"]],
        "amplitude_cv": float(serp["amplitude_cv"]),
        "wavelength": float(serp["wavelength"]),
        "wavelength_spread": [float(v) for v in serp["wavelength_spread"]],
        "wavelength_cv": float(serp["wavelength_cv"]),
        "settled_amplitude_cv": float(serp["settled_amplitude_cv"]),
        "settled_wavelength_cv": float(serp["settled_wavelength_cv"]),
        "wavelength_progression": float(prog["wavelength"]),
        "progression_direction": [float(v) for v in prog["direction"]],
        "n_cycles": int(serp["n_cycles"]),
        "n_uturns": int(serp["n_uturns"]),
        "n_loops": int(loops["n_loops"]),
        "n_loop_events": int(loops["n_loop_events"]),
        "loop_density": float(loops["n_loop_events"]) / cycles,
        "settled_loop_events": int(loops["settled_loop_events"]),
        "n_self_crossings": int(loops["n_self_crossings"]),
        "self_crossings_complete": bool(loops["self_crossings_complete"]),
        "median_vertex_turning": rough,
    }


def classify(
    trace: ArrayLike,
    options: MeasureOptions | None = None,
    substrate: str = "flat",
    flow_direction: ArrayLike | None = (1.0, 0.0),
) -> str:
    """Pattern class of the measured trace (docs/model.md §7, "Pattern class").

    Rules, in order (the first that holds wins):

    1. ``"unknown"`` if the median turning angle per vertex exceeds
       ``rough_turning_angle``: too rough for a rod trace (noise, random walk).
    2. ``"too_short"`` if the measured arc is shorter than ``min_judged_length``.
    3. ``"coil"``: windows that are one turn of a circle with a residual up to
       ``coil_loose_rel_residual`` (a loose, drifting coil counts) cover at least
       ``coil_min_coverage`` of the measured arc length; the accepted windows
       (:func:`coil_radius`; the loose ones when the accepted ones cover less than
       ``coil_min_strict_coverage``: a rosette) have a
       relative spread
       ``(p84 - p16) / (2 median)`` is below ``coil_max_rel_spread``, and at least
       ``coil_min_turn_sign_fraction`` of them turn the same way or every run of
       them turning the same way spans ``coil_min_run_turns`` turns (a coil that
       reverses its handedness between long coiled stretches). Never on the
       ``"stepped"`` substrate for a trace with two U-turns or more and neither a loop
       nor a self-crossing: its tangent never makes a full turn, so it is a meander
       whose caps may fit one big circle loosely (a serpentine of the Ī = 30 sweep point
       did, radius 49 against its amplitude 32).
    4. On the ``"stepped"`` substrate, with at least two U-turns:
       ``"serpentine-coil"`` if its settled part (the last ``settled_fraction`` of
       the U-turns) has at least ``serpentine_coil_min_loops`` loop events and at
       least ``serpentine_coil_loop_density`` of them per cycle (a loop event: a full
       turn of the tangent between U-turns, or a cluster of self-crossings; one stray
       loop, or loops of the start-up alone, do not make a serpentine-coil); else ``"too_short"``
       below ``min_judged_cycles`` cycles; else ``"periodic-serpentine"`` if the CVs
       of amplitude and wavelength over the settled part (the last
       ``settled_fraction`` of the U-turns) are both below ``periodic_cv_max`` and it
       has at least ``periodic_min_cycles`` cycles (``"too_short"`` with fewer:
       regular, but not long enough to call periodic); else
       ``"irregular-serpentine"`` (the spread persists after the start-up).
    5. ``"straight"``: no U-turns, no loops, chord / arc length >=
       ``STRAIGHT_MIN_CHORD_RATIO``.
    6. ``"unknown"`` otherwise. On the ``"flat"`` substrate the serpentine classes
       are never returned (they are defined relative to the steps along z), so
       the answer is coil, straight or unknown.
    """
    return str(measure(trace, options, substrate, flow_direction)["pattern"])

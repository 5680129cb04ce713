"""The agreement score Φ of a trace against a target: one implementation per task mode,
incremental for the env and batch for the constant-flow search (``policies/constant.py``).

Two modes: ``"corridor"`` (:class:`RouteScore`, the default of the route task: progress
inside a corridor, pads, completion, no shorts) and ``"thin"`` (:class:`ThinScore`, the v0
task: agreement with a thin polyline). Both have ``update(trace, n_frozen) -> metrics`` and
``potentials(metrics) -> terms``, whose sum is Φ.

Thin-polyline score (``score="thin"``, the v0 task; docs/task.md). With the tolerance band
τ_b (L_vb) and the trace laid since reset:

* coverage C: fraction of the target's arc length within τ_b of a trace node;
* precision P: fraction of the trace nodes within τ_b of the target (0 before any);
* progress G: arc length of the furthest covered target point over the target length;

Φ = w_c C + w_p P + w_g G (each term in [0, 1], the weights sum to at most 1 in the
defaults).

Incremental use. Trace nodes that left the solve never move again, so their contribution
is accumulated once (``n_frozen`` of :meth:`ThinScore.update`); the deposited nodes still in
the solve (they may slide on the stepped substrate) are re-measured every call.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from typing import Any

import numpy as np
from numba import njit

from cnt_env import numerics
from cnt_env.patterns import MeasureOptions, measure
from cnt_env.task import geometry
from cnt_env.task import targets as targets_mod

__all__ = [
    "COVERAGE_SPACING",
    "ROUTE_TERMS",
    "ROUTE_WEIGHTS",
    "THIN_TERMS",
    "THIN_WEIGHTS",
    "RouteScore",
    "ThinScore",
    "covered",
    "distances",
    "pattern_measures",
    "route_score",
    "score_route_trace",
    "score_trace",
]

#: Pattern measurements of the episode's trace kept in info["pattern"] (patterns.measure).
PATTERN_KEYS = ("pattern", "measured_length", "amplitude", "peak_to_peak", "wavelength",
                "coil_radius", "n_uturns", "n_cycles", "n_loops", "n_self_crossings")  # fmt: skip
_MEASURE_OPTIONS = MeasureOptions(transient_length=0.0)
#: Largest spacing (L_vb) of the target samples used for coverage.
COVERAGE_SPACING = 0.5
#: Terms of the thin score, in the order of its weights.
THIN_TERMS = ("coverage", "precision", "progress")
#: Default weights (w_c, w_p, w_g) of the thin score.
THIN_WEIGHTS = (0.5, 0.25, 0.25)


def pattern_measures(trace: np.ndarray, substrate: str) -> dict[str, Any] | None:
    """The :data:`PATTERN_KEYS` measures of ``trace`` (n, 3) (:func:`cnt_env.patterns.measure`,
    NaN where one does not apply); None when it is too short or degenerate to measure."""
    try:
        m = measure(trace, _MEASURE_OPTIONS, substrate=substrate, flow_direction=None)
    except ValueError:
        return None
    return {k: m[k] for k in PATTERN_KEYS}


def distances(points: np.ndarray, vertices: np.ndarray) -> np.ndarray:
    """Distance from each point (p, 2) to the polyline ``vertices`` (n, 2)."""
    out = np.empty(len(points))
    targets_mod.polyline_distances(
        np.ascontiguousarray(points, dtype=np.float64), np.ascontiguousarray(vertices), out
    )
    return out


def covered(samples: np.ndarray, points: np.ndarray, tol: float) -> np.ndarray:
    """Which samples (s, 2) lie within ``tol`` of any of ``points`` (p, 2)."""
    hit = np.zeros(len(samples), dtype=np.bool_)
    targets_mod.mark_covered(samples, np.ascontiguousarray(points, dtype=np.float64), tol, hit)
    return hit


def arc_weights(s: np.ndarray) -> np.ndarray:
    """Trapezoid weights of samples at arc lengths ``s``, summing to 1."""
    w = np.zeros(len(s))
    w[:-1] += 0.5 * np.diff(s)
    w[1:] += 0.5 * np.diff(s)
    return w / w.sum()


class ThinScore:
    """The thin-polyline score of one episode (module doc), updated as the trace grows.

    ``target`` (n, 2) is in the same frame as the traces passed to :meth:`update`."""

    def __init__(self, target: np.ndarray, tolerance: float,
                 weights: Sequence[float] = THIN_WEIGHTS) -> None:  # fmt: skip
        self.target = np.ascontiguousarray(target, dtype=np.float64)
        self.tolerance = float(tolerance)
        self.weights = np.asarray(weights, dtype=np.float64)
        spacing = min(COVERAGE_SPACING, 0.5 * self.tolerance)
        self.samples, self.sample_s = targets_mod.resample(self.target, spacing)
        self.length = float(self.sample_s[-1])
        self.sample_w = arc_weights(self.sample_s)
        self._cov_frozen = np.zeros(len(self.sample_s), dtype=bool)
        self._frozen_upto = 0
        self._n_in_frozen = 0
        self._dist_sum_frozen = 0.0

    def update(self, trace: np.ndarray, n_frozen: int) -> dict[str, Any]:
        """Metrics of the episode's ``trace`` (n, 2), whose first ``n_frozen`` nodes never
        move again: ``coverage``, ``precision``, ``progress``, ``furthest`` (L_vb),
        ``covered_end``, ``mean_distance`` (L_vb) and ``n_laid``."""
        tol = self.tolerance
        frozen_end = max(0, min(len(trace), n_frozen))
        if frozen_end > self._frozen_upto:
            new = trace[self._frozen_upto : frozen_end]
            d = distances(new, self.target)
            self._n_in_frozen += int(np.count_nonzero(d <= tol))
            self._dist_sum_frozen += float(d.sum())
            self._cov_frozen |= covered(self.samples, new, tol)
            self._frozen_upto = frozen_end
        tail = trace[frozen_end:]
        d_tail = distances(tail, self.target)
        cov = self._cov_frozen | covered(self.samples, tail, tol)
        n_laid = len(trace)
        n_in = self._n_in_frozen + int(np.count_nonzero(d_tail <= tol))
        hit = np.flatnonzero(cov)
        return {
            "coverage": numerics.dot(self.sample_w, cov),
            "precision": n_in / n_laid if n_laid > 0 else 0.0,
            "progress": float(self.sample_s[hit[-1]] / self.length) if hit.size else 0.0,
            "furthest": float(self.sample_s[hit[-1]]) if hit.size else 0.0,
            "covered_end": bool(cov[-1]),
            "mean_distance": (self._dist_sum_frozen + float(d_tail.sum())) / n_laid
            if n_laid > 0 else 0.0,
            "n_laid": n_laid,
        }  # fmt: skip

    @staticmethod
    def succeeded(metrics: dict[str, Any]) -> bool:
        """The target is laid: its end point is covered (the env's termination)."""
        return bool(metrics["covered_end"])

    def potentials(self, metrics: dict[str, Any]) -> np.ndarray:
        """The weighted terms (w_c C, w_p P, w_g G); Φ is their sum."""
        return self.weights * np.array([metrics[k] for k in THIN_TERMS])


def score_trace(
    trace: np.ndarray,
    target: np.ndarray,
    tolerance: float,
    weights: Sequence[float] = THIN_WEIGHTS,
    n_after_step: np.ndarray | None = None,
) -> dict[str, float]:
    """Batch Φ of a whole ``trace`` (n, 2) against ``target`` (m, 2), both relative to the
    contact point at reset. With ``n_after_step`` (nodes laid after each control step) the
    trace is cut at the first step whose trace covers the end point, where the env would
    have terminated."""
    score = ThinScore(target, tolerance, weights)
    pts = np.ascontiguousarray(trace, dtype=np.float64)
    if n_after_step is not None and len(pts):
        end = np.ascontiguousarray(score.samples[-1:])
        for n in n_after_step:
            if covered(end, pts[:n], score.tolerance)[0]:
                pts = pts[:n]
                break
    m = score.update(pts, len(pts))
    out = {k: float(m[k]) for k in THIN_TERMS}
    out["score"] = float(np.sum(score.potentials(m)))
    return {"score": out["score"], **{k: out[k] for k in THIN_TERMS}}


# ---- the corridor score of a route (score="corridor", docs/task.md) ---------------------

#: Terms of the corridor score; the reward pays the change of each (``reward_<term>``).
ROUTE_TERMS = ("progress", "pads", "completion", "outside", "short")
#: Default weights of the positive terms (progress, pads, completion), normalised over
#: the terms a route has (no pads: progress and completion only).
ROUTE_WEIGHTS = (0.8, 0.2, 0.2)
#: Share of the score one L_vb of trace inside a keep-out costs: 20 L_vb of trace in a
#: keep-out (a short circuit) zero the score. The length (segments cut at the keep-outs'
#: edges), not the node count, so the penalty is the same on every mesh (the model lays
#: nodes 0.2 L_vb apart, the surrogate 1; per node, before 2026-12-07, it was 5x harsher
#: on the model) and a wire thinner than the spacing is not stepped over.
SHORT_PENALTY = 0.05
#: Largest step (in corridor half-widths) the progress may take from one trace node to the
#: next: a node projects onto the route within this arc length ahead of the furthest point
#: reached, so a fold of the route cannot be skipped through where its corridors overlap.
PROGRESS_JUMP_WIDTHS = 2.0


@njit(cache=True)
def _walk(points, verts, cum_s, width, jump, furthest):  # pragma: no cover - numba
    """Furthest arc length reached, walking ``points`` (p, 2) in order from ``furthest``:
    each point inside the corridor projects onto the route within ``jump`` ahead."""
    w2 = width * width
    for i in range(points.shape[0]):
        px, pz = points[i, 0], points[i, 1]
        limit = furthest + jump
        best, best_s = np.inf, 0.0
        for j in range(verts.shape[0] - 1):
            if cum_s[j] > limit:
                break
            ax, az = verts[j, 0], verts[j, 1]
            dx, dz = verts[j + 1, 0] - ax, verts[j + 1, 1] - az
            len2 = dx * dx + dz * dz
            t = ((px - ax) * dx + (pz - az) * dz) / len2 if len2 > 0.0 else 0.0
            t = min(max(t, 0.0), 1.0)
            s = cum_s[j] + t * (cum_s[j + 1] - cum_s[j])
            if s > limit:
                t = (limit - cum_s[j]) / (cum_s[j + 1] - cum_s[j])
                s = limit
            ex, ez = px - ax - t * dx, pz - az - t * dz
            d2 = ex * ex + ez * ez
            if d2 < best:
                best, best_s = d2, s
        if best <= w2 and best_s > furthest:
            furthest = best_s
    return furthest


@njit(cache=True)
def _touches_strip(cx, cz, dx, dz, ax, az, ex, ez, length, half):  # pragma: no cover - numba
    """Whether segment c-d meets the rectangle of half-width ``half`` along the pad from a
    with unit direction (ex, ez) and ``length`` (an electrode strip, boundary included):
    Liang-Barsky clipping of c-d in the strip's frame, u along the pad in [0, length] and
    v across it in [-half, half]."""
    uc = (cx - ax) * ex + (cz - az) * ez
    vc = (cz - az) * ex - (cx - ax) * ez
    du = (dx - cx) * ex + (dz - cz) * ez
    dv = (dz - cz) * ex - (dx - cx) * ez
    t0, t1 = 0.0, 1.0
    for p, q in ((-du, uc), (du, length - uc), (-dv, vc + half), (dv, half - vc)):
        if p == 0.0:
            if q < 0.0:
                return False
        elif p < 0.0:
            t0 = max(t0, q / p)
        else:
            t1 = min(t1, q / p)
    return t0 <= t1


@njit(cache=True)
def _mark_crossed(points, pads, hit, half):  # pragma: no cover - numba
    """Set ``hit[k]`` where the polyline ``points`` crosses pad segment k (pads (p, 2, 2)),
    or, with ``half`` > 0 (half the route's pad_width), enters its strip."""
    for k in range(pads.shape[0]):
        if hit[k]:
            continue
        ax, az = pads[k, 0, 0], pads[k, 0, 1]
        bx, bz = pads[k, 1, 0], pads[k, 1, 1]
        ex, ez = bx - ax, bz - az  # the strip's frame, once per pad
        length = math.sqrt(ex * ex + ez * ez)
        ex, ez = ex / length, ez / length
        for i in range(points.shape[0] - 1):
            cx, cz = points[i, 0], points[i, 1]
            dx, dz = points[i + 1, 0], points[i + 1, 1]
            if half > 0.0:
                if _touches_strip(cx, cz, dx, dz, ax, az, ex, ez, length, half):
                    hit[k] = True
                    break
                continue
            d1 = (bx - ax) * (cz - az) - (bz - az) * (cx - ax)
            d2 = (bx - ax) * (dz - az) - (bz - az) * (dx - ax)
            d3 = (dx - cx) * (az - cz) - (dz - cz) * (ax - cx)
            d4 = (dx - cx) * (bz - cz) - (dz - cz) * (bx - cx)
            if d1 * d2 <= 0.0 and d3 * d4 <= 0.0 and (d1 != d2) and (d3 != d4):
                hit[k] = True
                break


class RouteScore:
    """The corridor score of one episode against a route (docs/task.md), updated as the
    trace grows (the same ``update(trace, n_frozen)`` as :class:`ThinScore`).

    With G the progress (furthest arc length reached by trace inside the corridor, over
    the route length), P the fraction of pads crossed (or, with ``pad_width`` > 0,
    touched: a trace segment entering the strip of that width along the pad), C = 1 once
    G = 1, o the fraction of trace nodes outside the corridor and L_s the length of trace
    inside keep-outs (L_vb):

        A = (w_g G + w_p P + w_c C) / (w_g + w_p [pads] + w_c),
        k = min(1, SHORT_PENALTY L_s) (0.05 per L_vb),
        Φ = A (1 - o) (1 - k)  in [0, 1],

    split into the terms progress w_g G / W, pads w_p P / W, completion w_c C / W,
    outside -A o and short -A (1 - o) k, which sum to Φ."""

    def __init__(self, waypoints: np.ndarray, width: float, pads: np.ndarray,
                 keepouts: Sequence[np.ndarray], weights: Sequence[float] = ROUTE_WEIGHTS,
                 pad_width: float = 0.0) -> None:  # fmt: skip
        self.waypoints = np.ascontiguousarray(waypoints, dtype=np.float64)
        self.width = float(width)
        self.cum_s = targets_mod.cumulative_length(self.waypoints)
        self.length = float(self.cum_s[-1])
        self.jump = PROGRESS_JUMP_WIDTHS * self.width
        self.pads = np.ascontiguousarray(np.reshape(pads, (-1, 2, 2)), dtype=np.float64)
        self.pad_half = 0.5 * float(pad_width)
        self.keep_vertices, self.keep_starts = geometry.pack(tuple(keepouts))
        wg, wp, wc = (float(x) for x in weights)
        self.weights = np.array([wg, wp if len(self.pads) else 0.0, wc])
        self.samples, self.sample_s = targets_mod.resample(self.waypoints, COVERAGE_SPACING)
        self.sample_w = arc_weights(self.sample_s)
        self._frozen_upto = 0
        self._furthest = 0.0
        self._n_in = 0
        self._n_short = 0
        self._short_len = 0.0
        self._dist_sum = 0.0
        self._pads_hit = np.zeros(len(self.pads), dtype=np.bool_)
        self._cov = np.zeros(len(self.sample_s), dtype=np.bool_)

    def _scan(self, pts: np.ndarray, joint: np.ndarray, furthest: float, pads_hit: np.ndarray,
              cov: np.ndarray) -> tuple[float, int, int, float, float]:  # fmt: skip
        """Walk ``pts`` on from the state given (``pads_hit`` and ``cov`` updated in
        place); ``joint``: the node before them (0 or 1 rows), for the pad crossings and
        the short's length. Returns the furthest arc length, the nodes inside the
        corridor, the nodes in keep-outs, their length and the sum of distances."""
        furthest = _walk(pts, self.waypoints, self.cum_s, self.width, self.jump, furthest)
        d = distances(pts, self.waypoints)
        n_in = int(np.count_nonzero(d <= self.width))
        both = np.concatenate([joint, pts])  # the segments ending in pts, from the joint on
        n_short, short_len = 0, 0.0
        if len(self.keep_starts) > 1:
            keep = (self.keep_vertices, self.keep_starts)
            n_short = int(np.count_nonzero(geometry.in_polygons(pts, *keep)))
            short_len = geometry.length_in_polygons(both, *keep)  # cut at the edges
        if len(self.pads):
            _mark_crossed(both, self.pads, pads_hit, self.pad_half)
        cov |= covered(self.samples, pts, self.width)
        return furthest, n_in, n_short, short_len, float(d.sum())

    def update(self, trace: np.ndarray, n_frozen: int) -> dict[str, Any]:
        """Metrics of the episode's ``trace`` (n, 2), whose first ``n_frozen`` nodes never
        move again: ``progress``, ``furthest`` (L_vb), ``pads_crossed``, ``completed``,
        ``inside`` (fraction of nodes in the corridor; also as ``precision``),
        ``outside``, ``shorts`` (nodes in keep-outs), ``short_length`` (L_vb of trace in
        keep-outs, its segments cut at their edges), ``coverage`` (fraction of the
        route's length with trace within w), ``mean_distance`` and ``n_laid``."""
        trace = np.ascontiguousarray(trace, dtype=np.float64)
        frozen_end = max(0, min(len(trace), n_frozen))
        if frozen_end > self._frozen_upto:
            a = self._frozen_upto
            f, n_in, n_s, s_len, dsum = self._scan(
                trace[a:frozen_end], trace[max(0, a - 1) : a], self._furthest, self._pads_hit,
                self._cov)  # fmt: skip
            self._furthest, self._frozen_upto = f, frozen_end
            self._n_in += n_in
            self._n_short += n_s
            self._short_len += s_len
            self._dist_sum += dsum
        pads_hit, cov = self._pads_hit.copy(), self._cov.copy()
        a = frozen_end
        f, n_in, n_s, s_len, dsum = self._scan(trace[a:], trace[max(0, a - 1) : a],
                                               self._furthest, pads_hit, cov)  # fmt: skip
        n_laid = len(trace)
        n_in += self._n_in
        n_short = n_s + self._n_short
        inside = n_in / n_laid if n_laid else 0.0
        return {
            "progress": min(1.0, f / self.length),
            "furthest": f,
            "pads_crossed": int(np.count_nonzero(pads_hit)),
            "n_pads": len(self.pads),
            "completed": bool(f >= self.length * (1.0 - 1e-12)),
            "inside": inside,
            "precision": inside,
            "outside": (n_laid - n_in) / n_laid if n_laid else 0.0,
            "shorts": n_short,
            "short_length": self._short_len + s_len,
            "coverage": numerics.dot(self.sample_w, cov),
            "mean_distance": (self._dist_sum + dsum) / n_laid if n_laid else 0.0,
            "n_laid": n_laid,
        }

    @staticmethod
    def succeeded(metrics: dict[str, Any]) -> bool:
        """The circuit works: the route is completed, every pad is met and no trace lies
        in a keep-out (a short). Completion alone ends the episode; a route completed
        through a keep-out or past a pad is not a success (its score says by how much)."""
        return bool(
            metrics["completed"]
            and metrics["pads_crossed"] == metrics["n_pads"]
            and metrics["shorts"] == 0
            and metrics["short_length"] == 0.0
        )

    def potentials(self, metrics: dict[str, Any]) -> np.ndarray:
        """The terms of Φ in the order of :data:`ROUTE_TERMS`; Φ is their sum."""
        w = self.weights / self.weights.sum()
        pads = metrics["pads_crossed"] / metrics["n_pads"] if metrics["n_pads"] else 0.0
        pos = w * np.array([metrics["progress"], pads, float(metrics["completed"])])
        a = float(pos.sum())
        o = metrics["outside"]
        k = min(1.0, SHORT_PENALTY * metrics["short_length"])
        # short = -A (1 - o) k written as -(A - A o) k: the sum left to right is then
        # x - x k with x = A - A o as rounded, >= 0 to the last bit and exactly 0 when
        # k = 1 (A (1 - o) k gave -1.1e-16 on a full short)
        kept = a - a * o
        return np.array([pos[0], pos[1], pos[2], -a * o, -kept * k])


def route_score(route: Any) -> RouteScore:
    """A fresh :class:`RouteScore` of ``route`` (a :class:`~cnt_env.task.routes.Route`)."""
    return RouteScore(route.waypoints, route.width, route.pads, route.keepouts,
                      pad_width=route.pad_width)  # fmt: skip


def score_route_trace(trace: np.ndarray, route: Any,
                      n_after_step: np.ndarray | None = None) -> dict[str, float]:  # fmt: skip
    """Batch corridor Φ of a whole ``trace`` (n, 2) against ``route`` (a
    :class:`~cnt_env.task.routes.Route`), both relative to the contact point at reset.
    With ``n_after_step`` (nodes laid after each control step, as many steps as the
    episode may take) the trace is cut at the first step that completes the route, where
    the env would have terminated."""
    pts = np.ascontiguousarray(trace, dtype=np.float64)
    cuts = [len(pts)] if n_after_step is None else [int(n) for n in n_after_step]
    score = route_score(route)
    done = 0
    for n in cuts:  # frozen up to the previous cut: the walk is incremental
        m = score.update(pts[:n], done)
        done = n
        if m["completed"]:
            break
    out = {k: float(m[k]) for k in ("progress", "coverage", "precision", "inside", "shorts")}
    out["completed"] = float(m["completed"])
    out["score"] = float(np.sum(score.potentials(m)))
    return out

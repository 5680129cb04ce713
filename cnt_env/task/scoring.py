"""The agreement score Φ of a trace against a target: one implementation, incremental for
the env and batch for the constant-flow search (``policies/constant.py``).

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

from collections.abc import Sequence
from typing import Any

import numpy as np

from cnt_env.task import targets as targets_mod

__all__ = [
    "COVERAGE_SPACING",
    "THIN_TERMS",
    "THIN_WEIGHTS",
    "ThinScore",
    "covered",
    "distances",
    "score_trace",
]

#: Largest spacing (L_vb) of the target samples used for coverage.
COVERAGE_SPACING = 0.5
#: Terms of the thin score, in the order of its weights.
THIN_TERMS = ("coverage", "precision", "progress")
#: Default weights (w_c, w_p, w_g) of the thin score.
THIN_WEIGHTS = (0.5, 0.25, 0.25)


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
            "coverage": float(np.dot(self.sample_w, cov)),
            "precision": n_in / n_laid if n_laid > 0 else 0.0,
            "progress": float(self.sample_s[hit[-1]] / self.length) if hit.size else 0.0,
            "furthest": float(self.sample_s[hit[-1]]) if hit.size else 0.0,
            "covered_end": bool(cov[-1]),
            "mean_distance": (self._dist_sum_frozen + float(d_tail.sum())) / n_laid
            if n_laid > 0 else 0.0,
            "n_laid": n_laid,
        }  # fmt: skip

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

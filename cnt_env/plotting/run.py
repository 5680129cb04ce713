"""The figure of one deposition run (``cnt-sim run --png``): the trace from above and
the suspended rod from the side, drawn with the top view's colours
(:mod:`cnt_env.plotting.topview`)."""

from __future__ import annotations

import math
import os
from collections.abc import Mapping
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np

from cnt_env.plotting.topview import rgb01

if TYPE_CHECKING:  # imported when used: patterns loads scipy.signal (~2 s)
    from cnt_env.patterns import MeasureOptions

__all__ = ["last_turn_circle", "plot_run", "uturn_markers"]

# Circles drawn on the top view: the median of this many one-turn windows, a quarter
# turn apart, ending at the end of the trace.
_LAST_WINDOWS = 4
_MIN_WINDOW_POINTS = 8


def last_turn_circle(trace: Any, radius: float) -> tuple[float, float, float] | None:
    """Median circle ``(cx, cz, r)`` of the last one-turn windows of ``trace``.

    A turn is ``2 pi radius`` of arc length (``radius`` is the measured coil
    radius). Up to ``_LAST_WINDOWS`` windows, a quarter turn apart and ending at
    the end of the trace, each get :func:`patterns.fit_circle`; the median of
    centres and radii is returned. None when ``radius`` is not finite or the
    trace is shorter than one turn.
    """
    from cnt_env.patterns import arc_length, fit_circle

    if radius is None or not math.isfinite(radius) or radius <= 0.0:
        return None
    pts = np.asarray(trace, dtype=np.float64)
    s = arc_length(pts)
    turn = 2.0 * math.pi * radius
    fits = []
    for k in range(_LAST_WINDOWS):
        end = s[-1] - 0.25 * k * turn
        start = end - turn
        if start < 0.0:
            break
        window = pts[(s >= start) & (s <= end)]
        if window.shape[0] >= _MIN_WINDOW_POINTS:
            fits.append(fit_circle(window)[:3])
    if not fits:
        return None
    cx, cz, r = np.median(np.array(fits), axis=0)
    return float(cx), float(cz), float(r)


def uturn_markers(
    trace: Any, measurement: Mapping[str, Any] | None, options: MeasureOptions | None = None
) -> dict[str, Any] | None:
    """The U-turns to mark on a stepped run's trace (:func:`patterns.uturns`), or None.

    Only for a measurement on the ``"stepped"`` substrate: there U-turns are the
    serpentine's turning points (on a flat one they would only mark a coil's wobble).
    ``options`` default to the measurement's transient with the other measurement
    defaults, i.e. what ``cnt-sim run`` measured with. None when the trace is too
    short to measure.
    """
    from cnt_env.patterns import MeasureOptions, uturns

    measurement = measurement or {}
    if measurement.get("substrate") != "stepped":
        return None
    if options is None:
        transient = measurement.get("transient_length")
        options = (
            MeasureOptions()
            if transient is None
            else MeasureOptions(transient_length=float(transient))
        )
    try:
        return uturns(trace, options)
    except ValueError:
        return None


def _rod_plane_coordinate(rod: np.ndarray) -> tuple[np.ndarray, str]:
    """Horizontal coordinate of the rod's nodes in its own (vertical) plane, and a label."""
    horizontal = rod[:, [0, 2]] - rod[0, [0, 2]]
    direction = horizontal[-1]
    norm = float(np.hypot(*direction))
    if norm > 1e-9:
        return horizontal @ (direction / norm), "horizontal, in the rod's plane"
    return rod[:, 0], "x"


def plot_run(
    trace: Any,
    suspended: Any,
    measurement: Mapping[str, Any] | None,
    path: str | os.PathLike[str],
    *,
    title: str | None = None,
    options: MeasureOptions | None = None,
) -> Path:
    """Write a PNG of a run: top view of the trace and side view of the suspended rod.

    * Left: the trace in the substrate plane (x, z), equal axes, with the median
      circle of the last one-turn windows dashed (:func:`last_turn_circle`) when a
      coil radius was measured; the start-up transient (not measured) in grey. On
      the stepped substrate the U-turns are marked (:func:`uturn_markers`, with
      ``options`` or the measurement's transient), maxima of z as up-triangles and
      minima as down-triangles, and the title gives amplitude and wavelength.
    * Right: the suspended rod, height y against its horizontal position in its
      own plane (the axes are not to scale: the rod is tall and nearly straight).

    ``trace`` is ``(n, 3)`` as (x, y, z); ``suspended`` ``(m, 3)`` or None;
    ``measurement`` a :func:`patterns.measure` dict or None. Lengths in L_vb.
    Returns the path written.
    """
    from matplotlib.backends.backend_agg import FigureCanvasAgg
    from matplotlib.figure import Figure

    from cnt_env.patterns import arc_length

    trace = np.asarray(trace, dtype=np.float64)
    measurement = dict(measurement or {})
    pattern = measurement.get("pattern") or "not measured"
    radius = measurement.get("coil_radius")
    radius = float(radius) if radius is not None else math.nan

    fig = Figure(figsize=(11.0, 5.0), layout="constrained")
    FigureCanvasAgg(fig)
    top, side = fig.subplots(1, 2, width_ratios=[1.6, 1.0])

    transient = measurement.get("transient_length") or 0.0
    start = int(np.searchsorted(arc_length(trace), transient)) if transient > 0 else 0
    if start > 0:
        top.plot(
            trace[: start + 1, 0],
            trace[: start + 1, 2],
            "-",
            lw=0.8,
            color=rgb01("trace_before"),
            label=f"start-up ({transient:g} L_vb, not measured)",
        )
    top.plot(trace[start:, 0], trace[start:, 2], "-", lw=0.8, color=rgb01("trace"), label="trace")
    top.plot(trace[:1, 0], trace[:1, 2], "o", ms=4, color="tab:green", label="start")
    top.plot(trace[-1:, 0], trace[-1:, 2], "s", ms=4, color=rgb01("contact"), label="end")
    circle = last_turn_circle(trace, radius) if trace.shape[0] >= 3 else None
    if circle is not None:
        cx, cz, r = circle
        phi = np.linspace(0.0, 2.0 * math.pi, 256)
        top.plot(
            cx + r * np.cos(phi),
            cz + r * np.sin(phi),
            "--",
            lw=1.2,
            color="k",
            label=f"last-turn fit, R = {r:.2f}",
        )
    marks = uturn_markers(trace, measurement, options) if trace.shape[0] >= 3 else None
    if marks is not None and len(marks["indices"]):
        idx, sides = marks["indices"], marks["sides"]
        for sign, marker, word in ((1, "^", "max z"), (-1, "v", "min z")):
            at = idx[sides == sign]
            top.plot(
                trace[at, 0],
                trace[at, 2],
                marker,
                ms=5,
                mfc="none",
                mew=1.0,
                color="tab:red" if sign > 0 else "tab:purple",
                label=f"U-turn, {word} ({at.size})",
            )
    top.set_aspect("equal", adjustable="datalim")
    top.set_xlabel("x (L_vb)")
    top.set_ylabel("z (L_vb)")
    top.set_title("top view: deposited trace")
    top.legend(loc="best", fontsize="small")

    if suspended is not None and len(suspended):
        rod = np.asarray(suspended, dtype=np.float64)
        h, where = _rod_plane_coordinate(rod)
        side.plot(h, rod[:, 1], "-", lw=1.0, color=rgb01("rod"))
        side.plot(h[:1], rod[:1, 1], "o", ms=4, color="tab:red", label="contact node")
        side.axhline(0.0, color="0.5", lw=0.8)
        side.legend(loc="best", fontsize="small")
        side.set_xlabel(f"{where} (L_vb)")
    else:
        side.text(
            0.5, 0.5, "suspended rod not saved", ha="center", va="center", transform=side.transAxes
        )
        side.set_xlabel("horizontal (L_vb)")
    side.set_ylabel("height y (L_vb)")
    side.set_title("side view: suspended rod (axes not to scale)")

    radius_text = f"R = {radius:.3g} L_vb" if math.isfinite(radius) else "no coil radius"
    if measurement.get("substrate") == "stepped":
        amplitude = float(measurement.get("amplitude") or math.nan)
        wavelength = float(measurement.get("wavelength") or math.nan)
        radius_text = (
            f"amplitude {amplitude:.3g}, wavelength {wavelength:.3g} L_vb, "
            f"{measurement.get('n_uturns', 0)} U-turns"
        )
    fig.suptitle(title or f"pattern: {pattern}, {radius_text}")
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(path, format="png", dpi=120)
    return path

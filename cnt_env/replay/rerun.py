"""The rerun side of replay: one logger for every source (rerun imported lazily).

:func:`import_rerun` imports rerun (rerun-sdk 0.41, the optional ``[rerun]`` extra) or
says how to install it. :func:`open_stream` opens one ``RecordingStream`` with the
log-time timeline and the wall-clock properties off, so the same data give the same
file. :class:`SceneLogger` logs the static scene and :class:`~cnt_env.replay.episode.Frame` s,
frame by frame (a live viewer) or column by column (``send_columns``: files, at a
fraction of the cost); both give the same rows. :func:`default_blueprint` is the layout.
The colours are the top view's own (:data:`cnt_env.plotting.PALETTE`). The entities are
listed in the package docstring (:mod:`cnt_env.replay`).
"""

from __future__ import annotations

import json
import math
from collections.abc import Mapping, Sequence
from pathlib import Path
from typing import Any

import numpy as np

from cnt_env.io import to_jsonable
from cnt_env.plotting import PALETTE
from cnt_env.replay.episode import APPLICATION_ID, Frame

__all__ = [
    "INSTALL_HINT",
    "MODES",
    "SceneLogger",
    "close_stream",
    "default_blueprint",
    "import_rerun",
    "open_stream",
]

INSTALL_HINT = 'pip install -e ".[rerun]"'
RERUN_SERIES = "0.41"
MODES = ("save", "spawn", "connect")

# Margin (L_vb) of the substrate outline around what lies on it at the start; its
# corners are rounded outwards to multiples of this too.
SUBSTRATE_MARGIN = 10.0
# Line widths, in UI points (negative radii are UI points in rerun).
LINE_POINTS = 1.5
SERIES_COLORS = {
    "reward/total": (20, 20, 20),
    "reward/return": (120, 120, 120),
    "reward/coverage": (40, 90, 230),
    "reward/precision": (230, 140, 20),
    "reward/progress": (30, 160, 60),
    "reward/failure": (220, 40, 40),
    "reward/pads": (230, 150, 20),
    "reward/completion": (40, 90, 230),
    "reward/outside": (150, 150, 150),
    "reward/short": (150, 60, 200),
    "score/score": (20, 20, 20),
    "score/coverage": (40, 90, 230),
    "score/precision": (230, 140, 20),
    "score/progress": (30, 160, 60),
    "flow/vbar": (20, 20, 20),
    "flow/phi": (150, 60, 200),
}


def import_rerun() -> Any:
    """The ``rerun`` module; an ImportError that says how to install it when missing."""
    try:
        import rerun
    except ImportError as exc:
        raise ImportError(
            "rerun replay needs the optional dependency rerun-sdk "
            f"{RERUN_SERIES}: install it with `{INSTALL_HINT}` "
            f'(or `pip install "rerun-sdk~={RERUN_SERIES}.0"`)'
        ) from exc
    return rerun


def default_blueprint(kind: str = "episode") -> Any:
    """The default layout: the 3D view and the top view on the left, the plots and the
    event log on the right. ``kind``: ``"episode"`` or ``"simulation"``."""
    import_rerun()
    import rerun.blueprint as rrb

    if kind not in ("episode", "simulation"):
        raise ValueError(f"kind must be 'episode' or 'simulation', got {kind!r}")
    scene = rrb.Vertical(
        rrb.Spatial3DView(origin="/world", name="3D"),
        rrb.Spatial2DView(origin="/top", name="Top view (x right, z down)"),
        row_shares=[3, 2],
    )
    if kind == "episode":
        plots: list[Any] = [
            rrb.TimeSeriesView(origin="/reward", name="Reward"),
            rrb.TimeSeriesView(origin="/score", name="Score"),
            rrb.Tabs(
                rrb.TimeSeriesView(origin="/metrics", name="Metrics"),
                rrb.TimeSeriesView(origin="/flow", name="Flow"),
                rrb.TimeSeriesView(origin="/pattern", name="Pattern"),
                rrb.TimeSeriesView(origin="/solver", name="Solver"),
            ),
        ]
    else:
        plots = [
            rrb.TimeSeriesView(origin="/metrics", name="Metrics"),
            rrb.TimeSeriesView(origin="/solver", name="Solver"),
        ]
    side = rrb.Vertical(*plots, rrb.TextLogView(origin="/events", name="Events"))
    return rrb.Blueprint(rrb.Horizontal(scene, side, column_shares=[3, 2]), collapse_panels=True)


def open_stream(
    rr: Any,
    recording_id: str,
    *,
    name: str,
    mode: str,
    path: Path | None = None,
    url: str | None = None,
    blueprint: Any = None,
    properties: Mapping[str, Any] | None = None,
    application_id: str = APPLICATION_ID,
) -> Any:
    """A RecordingStream with the log-time timeline and the automatic (wall-clock)
    properties off, connected to its sink."""
    rec = rr.RecordingStream(application_id, recording_id=recording_id, send_properties=False)
    rec.set_log_time_enabled(False)
    rec.set_log_tick_enabled(False)
    if mode == "save":
        assert path is not None
        path.parent.mkdir(parents=True, exist_ok=True)
        rec.save(path, default_blueprint=blueprint)
    elif mode == "spawn":
        rec.spawn(default_blueprint=blueprint)
    elif mode == "connect":
        rec.connect_grpc(url, default_blueprint=blueprint)
    else:
        raise ValueError(f"mode must be one of {MODES}, got {mode!r}")
    rec.send_recording_name(name)
    if properties:
        values = {
            k: (
                json.dumps(to_jsonable(v), allow_nan=False)
                if isinstance(v, (Mapping, list, tuple))
                else v
            )
            for k, v in to_jsonable(properties).items()
            if v is not None
        }
        if values:
            rec.send_property("cnt_env", rr.AnyValues(**values))
    return rec


def close_stream(rec: Any) -> None:
    rec.flush()
    rec.disconnect()


class SceneLogger:
    """Logs static scenes and :class:`Frame` s to one RecordingStream."""

    def __init__(self, rr: Any, rec: Any, *, flow_scale: float) -> None:
        self.rr = rr
        self.rec = rec
        self.flow_scale = flow_scale
        self._styled: set[str] = set()
        self._radius = rr.Radius.ui_points(LINE_POINTS)
        # Styles of the moving geometry, once and static: a component logged with every
        # frame costs as much as the data (rerun 0.41, ~0.1 ms per component and call).
        for path, cls, color, order in (
            ("world/trace", rr.LineStrips3D, PALETTE["trace"], None),
            ("world/rod", rr.LineStrips3D, PALETTE["rod"], None),
            ("world/flow", rr.Arrows3D, PALETTE["flow"], None),
            ("top/trace", rr.LineStrips2D, PALETTE["trace"], 2.0),
            ("top/rod", rr.LineStrips2D, PALETTE["rod"], 3.0),
            ("top/flow", rr.Arrows2D, PALETTE["flow"], 4.0),
        ):
            style: dict[str, Any] = {"colors": color, "radii": self._radius}
            if order is not None:
                style["draw_order"] = order
            rec.log(path, cls.from_fields(**style), static=True)

    def static_scene(
        self,
        *,
        target: np.ndarray | None,
        trace_before: np.ndarray | None,
        extent_points: Sequence[np.ndarray] | None,
        substrate: str | None,
    ) -> None:
        """The view coordinates, the target, the trace laid before, and (unless
        ``extent_points`` is None) the substrate outline (:meth:`substrate_outline`)."""
        rr, rec = self.rr, self.rec
        rec.log("world", rr.ViewCoordinates.RIGHT_HAND_Y_UP, static=True)
        if extent_points is not None:
            self.substrate_outline(extent_points, substrate)
        if target is not None and len(target) >= 2:
            rec.log(
                "world/target",
                rr.LineStrips3D([_lift(target)], colors=PALETTE["target"], radii=self._radius),
                static=True,
            )
            rec.log(
                "top/target",
                rr.LineStrips2D(
                    [target], colors=PALETTE["target"], radii=self._radius, draw_order=1.0
                ),
                static=True,
            )
        if trace_before is not None and len(trace_before) >= 2:
            rec.log(
                "world/trace_before",
                rr.LineStrips3D([trace_before], colors=PALETTE["trace_before"], radii=self._radius),
                static=True,
            )
            rec.log(
                "top/trace_before",
                rr.LineStrips2D(
                    [trace_before[:, [0, 2]]],
                    colors=PALETTE["trace_before"],
                    radii=self._radius,
                    draw_order=0.0,
                ),
                static=True,
            )

    def route(self, target: np.ndarray, route: Mapping[str, Any] | None) -> None:
        """The route around ``target`` (static, :func:`~cnt_env.replay.episode.route_geometry`):
        the corridor as a band of half-width w in the top view, the pads and the keep-outs
        (closed) in both views."""
        if route is None or len(target) < 2:
            return
        rr, rec, radius = self.rr, self.rec, self._radius
        band = rr.LineStrips2D([target], colors=PALETTE["corridor"], radii=route["width"],
                               draw_order=-1.0)  # fmt: skip
        rec.log("top/corridor", band, static=True)
        for name, strips in (
            ("pads", list(route["pads"])),
            ("keepouts", [np.concatenate([k, k[:1]]) for k in route["keepouts"]]),
        ):
            if not strips:
                continue
            color = PALETTE["pad" if name == "pads" else "keepout"]
            rec.log(f"world/{name}", rr.LineStrips3D([_lift(x) for x in strips], colors=color,
                                                     radii=radius), static=True)  # fmt: skip
            rec.log(f"top/{name}", rr.LineStrips2D(strips, colors=color, radii=radius,
                                                   draw_order=0.5), static=True)  # fmt: skip

    def substrate_outline(self, extent_points: Sequence[np.ndarray], substrate: str | None) -> None:
        """The substrate's outline (static): the box around ``extent_points`` ((n, 2) as
        (x, z) or (n, 3)) with a margin, its corners rounded outwards to multiples of
        ``SUBSTRATE_MARGIN``. Log it from final data (laid nodes still in the solve
        slide a little), so that a streamed and a collected recording agree."""
        rr = self.rr
        pts = [
            np.asarray(p)[:, :2] if np.shape(p)[-1] == 2 else np.asarray(p)[:, [0, 2]]
            for p in extent_points
            if len(p)
        ]
        if not pts:
            return
        xz = np.concatenate(pts)
        m = SUBSTRATE_MARGIN
        lo = np.floor((xz.min(axis=0) - m) / m) * m
        hi = np.ceil((xz.max(axis=0) + m) / m) * m
        box = np.array([[lo[0], lo[1]], [hi[0], lo[1]], [hi[0], hi[1]], [lo[0], hi[1]], lo])
        label = f"{substrate or 'flat'} substrate"
        strips = rr.LineStrips3D(
            [_lift(box)], colors=PALETTE["substrate"], radii=self._radius, labels=label
        )
        self.rec.log("world/substrate", strips, static=True)

    def frame(self, f: Frame) -> None:
        rr, rec = self.rr, self.rec
        rec.set_time("step", sequence=f.step)
        rec.set_time("sim_time", duration=f.sim_time)
        for timeline, value in f.extra_times.items():
            rec.set_time(timeline, sequence=value)
        if f.geometry:
            self._geometry(f)
        for path, value in f.scalars.items():
            if value is None or not math.isfinite(value):
                continue
            self._style(path)
            rec.log(path, rr.Scalars(value))
        for level, text in f.events:
            rec.log("events", rr.TextLog(text, level=level))

    def frames(self, frames: Sequence[Frame]) -> None:
        """Log ``frames`` column by column (``send_columns``, one call per entity): the
        same recording as :meth:`frame` for each, at a fraction of the cost. Frames with
        ``extra_times`` are not supported here."""
        rr, rec = self.rr, self.rec
        if not frames:
            return
        if any(f.extra_times for f in frames):
            raise ValueError("frames with extra_times are logged one by one (frame())")
        steps = np.array([f.step for f in frames], dtype=np.int64)
        times = np.array([f.sim_time for f in frames], dtype=np.float64)

        def send(path: str, rows: Sequence[int], columns: Any) -> None:
            idx = np.asarray(rows, dtype=np.int64)
            if idx.size:
                indexes = [
                    rr.TimeColumn("step", sequence=steps[idx]),
                    rr.TimeColumn("sim_time", duration=times[idx]),
                ]
                rec.send_columns(path, indexes=indexes, columns=columns)

        geo = [i for i, f in enumerate(frames) if f.geometry]
        for name in ("trace", "rod"):
            # one strip per row, or none before there is a line to draw (as in frame())
            rows = [[x] if len(x := getattr(frames[i], name)) >= 2 else [] for i in geo]
            lengths = [len(r) for r in rows]
            flat = [x for r in rows for x in r]
            world = rr.LineStrips3D.columns(strips=flat).partition(lengths)
            send(f"world/{name}", geo, world)
            top = rr.LineStrips2D.columns(strips=[x[:, [0, 2]] for x in flat]).partition(lengths)
            send(f"top/{name}", geo, top)
        arrows = [i for i in geo if frames[i].flow is not None and len(frames[i].rod)]
        if arrows:
            origins = np.array([frames[i].rod[0] for i in arrows])
            flows = np.array([frames[i].flow for i in arrows], dtype=np.float64)
            vectors = np.zeros((len(arrows), 3))
            vectors[:, 0], vectors[:, 2] = flows[:, 0], flows[:, 1]
            vectors *= self.flow_scale
            send("world/flow", arrows, rr.Arrows3D.columns(vectors=vectors, origins=origins))
            top = rr.Arrows2D.columns(vectors=vectors[:, [0, 2]], origins=origins[:, [0, 2]])
            send("top/flow", arrows, top)
        series: dict[str, tuple[list[int], list[float]]] = {}
        for i, f in enumerate(frames):
            for path, value in f.scalars.items():
                if value is not None and math.isfinite(value):
                    rows_, values = series.setdefault(path, ([], []))
                    rows_.append(i)
                    values.append(value)
        for path, (rows_, values) in series.items():
            self._style(path)
            send(path, rows_, rr.Scalars.columns(scalars=np.array(values)))
        events = [(i, level, text) for i, f in enumerate(frames) for level, text in f.events]
        if events:
            texts = rr.TextLog.columns(text=[e[2] for e in events], level=[e[1] for e in events])
            send("events", [e[0] for e in events], texts)

    def _style(self, path: str) -> None:
        """The SeriesLines style of a scalar series, once and static."""
        if path not in self._styled:
            self._styled.add(path)
            color = SERIES_COLORS.get(path)
            name = path.split("/", 1)[1]
            self.rec.log(path, self.rr.SeriesLines(names=name, colors=color), static=True)

    def _geometry(self, f: Frame) -> None:
        rr, rec = self.rr, self.rec
        # one row per frame even before there is a line to draw (an empty strip list)
        trace = [f.trace] if len(f.trace) >= 2 else []
        rec.log("world/trace", rr.LineStrips3D(trace))
        rec.log("top/trace", rr.LineStrips2D([t[:, [0, 2]] for t in trace]))
        rod = [f.rod] if len(f.rod) >= 2 else []
        rec.log("world/rod", rr.LineStrips3D(rod))
        rec.log("top/rod", rr.LineStrips2D([r[:, [0, 2]] for r in rod]))
        if f.flow is not None and len(f.rod):
            c = f.rod[0]
            v = np.array([f.flow[0], 0.0, f.flow[1]]) * self.flow_scale
            rec.log("world/flow", rr.Arrows3D(vectors=[v], origins=[c]))
            rec.log("top/flow", rr.Arrows2D(vectors=[v[[0, 2]]], origins=[c[[0, 2]]]))


def _lift(xz: np.ndarray) -> np.ndarray:
    """(n, 2) substrate points (x, z) -> (n, 3) at y = 0."""
    out = np.zeros((len(xz), 3))
    out[:, 0], out[:, 2] = xz[:, 0], xz[:, 1]
    return out


def episode_name(meta: Mapping[str, Any]) -> str:
    return f"episode {meta.get('episode')} (seed {meta.get('seed')}, target {meta.get('target')})"


def episode_properties(meta: Mapping[str, Any]) -> dict[str, Any]:
    return {k: v for k, v in meta.items() if k not in ("application_id",)}

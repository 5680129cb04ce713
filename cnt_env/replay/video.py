"""Episodes and runs as video: a GIF or MP4 (the optional ``[video]`` extra).

:func:`episode_frames` draws every frame of an :class:`~cnt_env.replay.episode.Episode`
with :func:`cnt_env.plotting.draw_top_view` at ONE extent for the whole episode
(:func:`episode_extent`; no re-zoom from frame to frame), with a legend and a scale bar
in L_vb and micrometres. Only the moving parts (trace, rod, contact point, flow, title)
are redrawn from frame to frame. :func:`trace_frames` does the same for a saved run
(the trace revealed in order of deposition). :func:`write_video` writes those frames, or any RGB
frames (e.g. ``env.render()`` output), to ``.gif`` (Pillow) or ``.mp4`` (ffmpeg through
imageio-ffmpeg, whose wheel ships the binary). Install the extra with
``pip install -e ".[video]"``; matplotlib is a core dependency.
"""

from __future__ import annotations

import math
import os
from collections.abc import Iterable, Iterator, Mapping
from pathlib import Path
from typing import Any

import numpy as np

from cnt_env.io import TRACE_FORMAT, load_trace
from cnt_env.plotting import TopViewRenderer, flow_arrow_scale, lvb_in_um, top_view_extent
from cnt_env.replay.episode import Episode, file_format, is_number, load_episode
from cnt_env.replay.simulation import SAVED_RUN_FRAMES
from cnt_env.replay.still import episode_extent, episode_view_kwargs

__all__ = [
    "VIDEO_FORMATS",
    "VIDEO_INSTALL_HINT",
    "episode_extent",
    "episode_frames",
    "import_imageio",
    "trace_frames",
    "write_video",
]

VIDEO_INSTALL_HINT = 'pip install -e ".[video]"'
VIDEO_FORMATS = (".gif", ".mp4")
#: Frame size (width, height) in pixels: multiples of 16, as H.264 encoders like.
DEFAULT_SIZE = (640, 640)


def import_imageio() -> Any:
    """``imageio`` (with its v3 API loaded); an ImportError that says how to install it."""
    try:
        import imageio
        import imageio.v3
    except ImportError as exc:
        raise ImportError(
            f"episode videos need the optional dependencies imageio and imageio-ffmpeg: "
            f"install them with `{VIDEO_INSTALL_HINT}` (or `pip install imageio imageio-ffmpeg`)"
        ) from exc
    return imageio


def episode_frames(
    episode: Episode | str | os.PathLike[str],
    *,
    extent: tuple[float, float, float, float] | None = None,
    size: tuple[int, int] = DEFAULT_SIZE,
    every: int = 1,
    z_down: bool = False,
) -> Iterator[np.ndarray]:
    """The frames of ``episode`` (an Episode or an episode file) as uint8 (H, W, 3)
    arrays of ``size`` = (width, height) pixels: frame 0 (the reset), every ``every``-th
    frame, and the last. ``extent`` (default :func:`episode_extent`) is the same for all."""
    if not isinstance(episode, Episode):
        episode = load_episode(episode)
    if isinstance(every, bool) or not isinstance(every, int) or every < 1:
        raise ValueError(f"every must be an int >= 1, got {every!r}")
    extent = episode_extent(episode) if extent is None else tuple(extent)
    if len(extent) != 4 or not (extent[0] < extent[1] and extent[2] < extent[3]):
        raise ValueError(f"extent must be (x0, x1, z0, z1) with x0 < x1 and z0 < z1: {extent}")
    last = len(episode.step) - 1
    indices = sorted({*range(0, last + 1, every), last})
    renderer = TopViewRenderer(extent, size, z_down=z_down, **episode_view_kwargs(episode, 0))
    meta = episode.meta
    name = f"{meta.get('recording_id') or 'episode'}: target {meta.get('target')}"
    for i in indices:
        kw = episode_view_kwargs(episode, i)
        when = f"step {int(episode.step[i])}/{last}, t = {float(episode.sim_time[i]):.4g} tau"
        yield renderer.render(kw["trace"], kw["rod"], kw["flow"], title=f"{name}\n{when}")


def trace_frames(
    saved: Mapping[str, Any] | str | os.PathLike[str],
    *,
    max_frames: int = SAVED_RUN_FRAMES,
    extent: tuple[float, float, float, float] | None = None,
    size: tuple[int, int] = DEFAULT_SIZE,
) -> Iterator[np.ndarray]:
    """The frames of a saved run (a trace file, ``cnt-sim run --out``, or
    :func:`cnt_env.io.load_trace`'s dict): a trace file has no time history, so the
    trace is revealed in order of deposition over at most ``max_frames`` frames (as
    ``cnt-sim replay`` does in rerun), the saved suspended rod on the last. One extent
    (default: the whole trace) for all."""
    from cnt_env.io import load_trace

    if not isinstance(saved, Mapping):
        saved = load_trace(saved)
    trace = np.asarray(saved["trace"], dtype=np.float64)
    params, config = saved.get("params") or {}, saved.get("config") or {}
    rod = saved.get("suspended")
    rod = None if rod is None or not len(rod) else np.asarray(rod, dtype=np.float64)
    vbar, phi = float(params.get("vbar") or 0.0), float(params.get("phi") or 0.0)
    flow = (vbar * math.cos(phi), vbar * math.sin(phi))
    extent = top_view_extent(trace, rod) if extent is None else tuple(extent)
    substrate = config.get("substrate") or "flat"
    renderer = TopViewRenderer(extent, size, rod=rod, flow=flow if vbar > 0 else None,
                               flow_scale=flow_arrow_scale(params.get("Hbar"), vbar),
                               um_per_lvb=lvb_in_um(substrate))  # fmt: skip
    n = len(trace)
    sim_time = (saved.get("stats") or {}).get("time")
    at_end = f", t = {sim_time:.4g} tau" if is_number(sim_time) else ""
    name = f"{config.get('preset', 'run')} on the {substrate} substrate"
    marks = np.unique(np.linspace(2, n, max(1, min(max_frames, n - 1))).round().astype(int))
    for k in marks:
        last = k == n
        title = f"{name}\n{k}/{n} trace nodes{at_end if last else ''}"
        yield renderer.render(trace[:k], rod if last else None,
                              flow if vbar > 0 and last else None, title=title)  # fmt: skip


def write_video(
    episode_or_frames: Episode | str | os.PathLike[str] | Mapping[str, Any] | Iterable[np.ndarray],
    path: str | os.PathLike[str],
    *,
    fps: float = 10.0,
    extent: tuple[float, float, float, float] | None = None,
    size: tuple[int, int] = DEFAULT_SIZE,
    every: int = 1,
    loop: int = 0,
) -> Path:
    """Write a video of an episode to ``path`` (``.gif`` or ``.mp4``, by its suffix).

    ``episode_or_frames``: an :class:`Episode`, an episode file (``.npz``), a saved run
    (a trace file or :func:`cnt_env.io.load_trace`'s dict: :func:`trace_frames`), or RGB
    frames (uint8 (H, W, 3) arrays of one size, e.g. ``env.render()`` output) written as
    given.
    For an episode, ``extent`` (x0, x1, z0, z1) in L_vb fixes the view (default: the
    whole episode, :func:`episode_extent`), ``size`` is (width, height) in pixels and
    ``every`` keeps every n-th step. ``fps``: frames per second; ``loop``: GIF repeats
    (0: for ever). A GIF merges identical consecutive frames. Returns the path.
    Raises ImportError (with the install hint) without the ``[video]`` extra.
    """
    imageio = import_imageio()
    path = Path(path)
    suffix = path.suffix.lower()
    if suffix not in VIDEO_FORMATS:
        raise ValueError(f"{path}: write a {' or '.join(VIDEO_FORMATS)} file")
    if not (isinstance(fps, (int, float)) and 0 < fps <= 120):
        raise ValueError(f"fps must be in (0, 120], got {fps!r}")
    source = episode_or_frames
    frames: Iterable[np.ndarray]
    if isinstance(source, (str, os.PathLike)) and file_format(source) == TRACE_FORMAT:
        source = load_trace(source)
    if isinstance(source, Mapping):
        frames = trace_frames(source, extent=extent, size=size)
    elif isinstance(source, (Episode, str, os.PathLike)):
        frames = episode_frames(source, extent=extent, size=size, every=every)
    else:
        frames = source
    path.parent.mkdir(parents=True, exist_ok=True)
    n = 0
    shape = None
    if suffix == ".gif":
        writer = imageio.v3.imopen(path, "w", extension=".gif")
        write = lambda frame: writer.write(frame, duration=1000.0 / fps, loop=loop)  # noqa: E731
    else:
        writer = imageio.v2.get_writer(path, format="FFMPEG", fps=fps, macro_block_size=16)
        write = writer.append_data
    try:
        for frame in frames:
            frame = np.asarray(frame)
            if frame.dtype != np.uint8 or frame.ndim != 3 or frame.shape[2] not in (3, 4):
                raise ValueError(
                    f"frames must be uint8 (H, W, 3) RGB arrays, got {frame.dtype} {frame.shape}"
                )
            if shape is not None and frame.shape != shape:
                raise ValueError(f"frame {n} has shape {frame.shape}, the first {shape}")
            shape = frame.shape
            write(np.ascontiguousarray(frame[:, :, :3]))
            n += 1
    finally:
        writer.close()
    if n == 0:
        path.unlink(missing_ok=True)
        raise ValueError("no frames to write")
    return path

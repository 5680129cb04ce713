"""A still frame of an episode (matplotlib), e.g. for the README: the top view of
:func:`cnt_env.plotting.draw_top_view`, as the recording's ``top`` view shows it."""

from __future__ import annotations

import os
from pathlib import Path
from typing import Any

from cnt_env.plotting import draw_top_view, flow_arrow_scale, lvb_in_um, top_view_extent
from cnt_env.replay.episode import Episode, load_episode, route_geometry

__all__ = ["episode_extent", "episode_view_kwargs", "render_top_view"]

# Nodes of the trace laid before reset that the extent still holds (the start-up arc
# of a warm start can be far longer than the episode).
_BEFORE_NODES = 50


def episode_extent(episode: Episode, *, margin: float = 0.08) -> tuple[float, float, float, float]:
    """The fixed square extent ``(x0, x1, z0, z1)`` of an episode's frames: the target
    and its route (corridor, pads, keep-outs), the episode's trace, the last few nodes
    laid before it and the rod of every frame."""
    n0 = episode.n_start
    sets: list[Any] = [episode.target, episode.trace[max(0, n0 - _BEFORE_NODES) :]]
    route = route_geometry(episode.meta)
    if route is not None and len(episode.target):
        w = route["width"]
        sets += [episode.target + d for d in ((w, w), (-w, -w))]
        sets += [*route["pads"], *route["keepouts"]]
    return top_view_extent(*sets, episode.rod_nodes, margin=margin)


def episode_view_kwargs(episode: Episode, i: int) -> dict[str, Any]:
    """The keywords of :func:`cnt_env.plotting.draw_top_view` for frame ``i`` of
    ``episode`` (its trace, target and route, rod and flow, the arrow scale and the
    scale bar's micrometres), without ``extent``."""
    f = episode.frame(i)
    meta = episode.meta
    Hbar = (meta.get("params") or {}).get("Hbar")
    route = route_geometry(meta) or {}
    return {
        "corridor": route.get("width"),
        "pads": route.get("pads", ()),
        "keepouts": route.get("keepouts", ()),
        "trace": episode.trace[: episode.trace_len[i]],
        "target": episode.target if len(episode.target) else None,
        "n_start": episode.n_start,
        "rod": f.rod,
        "flow": f.flow,
        "flow_scale": flow_arrow_scale(Hbar, meta.get("vbar_max")),
        "um_per_lvb": lvb_in_um(meta.get("substrate") or "flat"),
    }


def render_top_view(
    episode: Episode | str | os.PathLike[str],
    path: str | os.PathLike[str],
    *,
    frame: int = -1,
    dpi: int = 150,
) -> Path:
    """Save the top view of an episode's frame (default: the last) as a PNG, drawn like
    the recording's ``top`` view (:func:`cnt_env.plotting.draw_top_view`): the target,
    the trace before reset, the episode's trace, the suspended rod seen from above and
    the flow, with a legend and a scale bar, at the extent of the whole episode
    (:func:`episode_extent`, as the video's frames). x to the right, z down, as in the
    viewer."""
    from matplotlib.backends.backend_agg import FigureCanvasAgg
    from matplotlib.figure import Figure

    if not isinstance(episode, Episode):
        episode = load_episode(episode)
    i = frame % len(episode.step)
    fig = Figure(figsize=(6, 6.6), layout="constrained")
    FigureCanvasAgg(fig)
    ax = fig.add_subplot()
    draw_top_view(
        ax,
        extent=episode_extent(episode),
        z_down=True,
        legend="figure",
        **episode_view_kwargs(episode, i),
    )
    meta = episode.meta
    ax.set_title(
        f"{meta.get('recording_id', '')}: target {meta.get('target')}, "
        f"step {int(episode.step[i])}, t = {float(episode.sim_time[i]):.4g} tau",
        fontsize=9,
    )
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(path, dpi=dpi, bbox_inches="tight")
    return path

"""Figures (matplotlib, imported only when a figure is drawn).

Figures are drawn with matplotlib's object API on Agg canvases: no pyplot, no global
backend switch, so plotting works headless and does not disturb a caller's own
matplotlib state.

==============  ==========================================================================
module          job
==============  ==========================================================================
``topview``     the one top view of a trace: :data:`PALETTE`, :data:`LABELS`,
                :func:`draw_top_view`, :func:`draw_route`, :func:`top_view_extent`, the
                scale bar in L_vb and micrometres, frames (:func:`top_view_image`,
                :class:`TopViewRenderer`); used by the rerun recording, the still, the
                video, :func:`plot_run` and (for its colours) the env's raster
``run``         :func:`plot_run`: the figure of one deposition run (``cnt-sim run --png``)
==============  ==========================================================================
"""

from cnt_env.plotting.run import last_turn_circle, plot_run, uturn_markers
from cnt_env.plotting.topview import (
    FLOW_ARROW_FRACTION,
    LABELS,
    PALETTE,
    TopView,
    TopViewRenderer,
    agg_figure,
    draw_route,
    draw_top_view,
    figure_rgb,
    flow_arrow_scale,
    lvb_in_um,
    rgb01,
    top_view_extent,
    top_view_image,
)

__all__ = [
    "FLOW_ARROW_FRACTION",
    "LABELS",
    "PALETTE",
    "TopView",
    "TopViewRenderer",
    "agg_figure",
    "draw_route",
    "draw_top_view",
    "figure_rgb",
    "flow_arrow_scale",
    "last_turn_circle",
    "lvb_in_um",
    "plot_run",
    "rgb01",
    "top_view_extent",
    "top_view_image",
    "uturn_markers",
]

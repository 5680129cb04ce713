"""The top view (cnt_env.plotting): one palette, a fixed extent, the drawing and its scale bar.

Every picture of a trace (the rerun recording, the still, the video frames, ``plot_run``)
takes its colours from ``PALETTE``; frames of one episode share one extent
(``top_view_extent``), so a video never re-zooms. All drawing is on Agg figures.
"""

from __future__ import annotations

import math

import numpy as np
import pytest

from cnt_env import plotting, units
from cnt_env.plotting import (
    FLOW_ARROW_FRACTION,
    LABELS,
    PALETTE,
    draw_top_view,
    flow_arrow_scale,
    lvb_in_um,
    top_view_extent,
    top_view_image,
)


def agg_axes():
    from matplotlib.backends.backend_agg import FigureCanvasAgg
    from matplotlib.figure import Figure

    fig = Figure(figsize=(5, 5))
    FigureCanvasAgg(fig)
    return fig, fig.add_subplot()


def spiral(n: int = 120) -> np.ndarray:
    s = np.linspace(0.0, 4 * np.pi, n)
    return np.column_stack([3 * np.cos(s) + s, np.zeros(n), 3 * np.sin(s)])


def test_palette_is_rgb_and_labelled() -> None:
    for name, rgb in PALETTE.items():
        assert len(rgb) == 3 and all(isinstance(c, int) and 0 <= c <= 255 for c in rgb), name
    assert set(LABELS) <= set(PALETTE)
    assert plotting.rgb01("trace") == tuple(c / 255 for c in PALETTE["trace"])
    with pytest.raises(TypeError):
        PALETTE["trace"] = (0, 0, 0)  # read-only: one home, not a copy to edit


def test_rerun_logger_uses_the_palette() -> None:
    """The recording's colours are the palette's (no second set of colours)."""
    import inspect

    from cnt_env.replay import rerun as rerun_side

    source = inspect.getsource(rerun_side)
    for name in ("target", "trace", "trace_before", "rod", "flow", "substrate"):
        assert f'PALETTE["{name}"]' in source, name
    assert "_COLOR = (" not in source


def test_extent_holds_every_point_at_a_fixed_aspect() -> None:
    trace = spiral()
    target = np.array([[0.0, 0.0], [30.0, -5.0]])
    x0, x1, z0, z1 = top_view_extent(trace, target, margin=0.1)
    pts = np.concatenate([trace[:, [0, 2]], target])
    assert x0 < pts[:, 0].min() and x1 > pts[:, 0].max()
    assert z0 < pts[:, 1].min() and z1 > pts[:, 1].max()
    assert (x1 - x0) == pytest.approx(z1 - z0)  # aspect 1
    wide = top_view_extent(trace, aspect=2.0)
    assert (wide[1] - wide[0]) == pytest.approx(2.0 * (wide[3] - wide[2]))
    # a point: at least min_size across; nothing: centred on the origin
    x0, x1, z0, z1 = top_view_extent(np.zeros((1, 2)), min_size=10.0, margin=0.0)
    assert (x0, x1, z0, z1) == (-5.0, 5.0, -5.0, 5.0)
    assert top_view_extent(None, np.zeros((0, 3)), min_size=4.0, margin=0.0) == (-2, 2, -2, 2)


def test_lvb_in_um_comes_from_the_paper_si_values() -> None:
    assert lvb_in_um("flat") == pytest.approx(units.preset("coil").L_vb * 1e6)
    assert lvb_in_um("stepped") == pytest.approx(units.preset("serpentine").L_vb * 1e6)
    assert lvb_in_um("flat") == pytest.approx(math.sqrt(2.7e-24 / 4.39e-10) * 1e6)
    assert 0.07 < lvb_in_um("flat") < 0.08 and 0.12 < lvb_in_um("stepped") < 0.13


def test_flow_arrow_scale() -> None:
    assert flow_arrow_scale(40.0, 0.1) == pytest.approx(FLOW_ARROW_FRACTION * 40.0 / 0.1)
    assert flow_arrow_scale(None, 0.1) == flow_arrow_scale(40.0, 0.0) == 1.0


def test_draw_top_view_fixed_extent_and_update() -> None:
    fig, ax = agg_axes()
    trace = spiral()
    rod = np.column_stack([np.full(8, trace[-1, 0]), np.arange(8.0), np.full(8, trace[-1, 2])])
    target = np.array([[0.0, 0.0], [20.0, 0.0], [20.0, 10.0]])
    extent = (-10.0, 30.0, -15.0, 25.0)
    view = draw_top_view(ax, trace[:60], target, n_start=20, rod=rod, flow=(0.05, 0.0),
                         flow_scale=100.0, corridor=2.0, pads=[np.array([[5, -3], [5, 3]])],
                         keepouts=[np.array([[10, 5], [14, 5], [14, 9], [10, 9]])],
                         extent=extent, um_per_lvb=0.1)  # fmt: skip
    assert ax.get_xlim() == (-10.0, 30.0) and ax.get_ylim() == (-15.0, 25.0)
    # the earlier trace up to the contact point at reset, then this episode's
    assert np.array_equal(view.trace_before.get_xdata(), trace[:20, 0])
    assert np.array_equal(view.trace.get_xdata(), trace[19:60, 0])
    assert np.array_equal(view.contact.get_xdata(), rod[:1, 0])
    u, v = view.flow.U[0], view.flow.V[0]
    assert (u, v) == pytest.approx((5.0, 0.0))
    legend = [t.get_text() for t in ax.get_legend().get_texts()]
    for key in ("target", "trace", "trace_before", "rod", "contact", "flow", "pad", "keepout"):
        assert any(LABELS[key] in t for t in legend), key
    texts = [t.get_text() for a in ax.artists for t in a.findobj(lambda o: hasattr(o, "get_text"))]
    assert any("L_vb" in t and "µm" in t for t in texts), texts  # the scale bar
    fig.canvas.draw()

    view.update(trace, rod[::-1], (0.0, -0.02))  # a later frame: the view does not move
    fig.canvas.draw()
    assert ax.get_xlim() == (-10.0, 30.0) and ax.get_ylim() == (-15.0, 25.0)
    assert len(view.trace.get_xdata()) == len(trace) - 19
    assert (view.flow.U[0], view.flow.V[0]) == pytest.approx((0.0, -2.0))


def test_top_view_image_size_and_z_down() -> None:
    trace = spiral(40)
    img = top_view_image(trace, size=(320, 256), extent=(-5, 20, -5, 20), z_down=True)
    assert img.shape == (256, 320, 3) and img.dtype == np.uint8
    _, ax = agg_axes()
    draw_top_view(ax, trace, z_down=True, legend=False, scale_bar=False)
    lo, hi = ax.get_ylim()
    assert lo > hi  # z grows downwards, as in the rerun viewer
    assert ax.get_legend() is None


def test_plot_run_uses_the_palette(tmp_path, monkeypatch: pytest.MonkeyPatch) -> None:
    import matplotlib.figure
    from matplotlib.colors import to_rgb

    made = []
    original = matplotlib.figure.Figure.savefig

    def keep(self, *args, **kwargs):
        made.append(self)
        return original(self, *args, **kwargs)

    monkeypatch.setattr(matplotlib.figure.Figure, "savefig", keep)
    plotting.plot_run(spiral(), None, None, tmp_path / "run.png")
    top = made[0].axes[0]
    colours = {line.get_label(): to_rgb(line.get_color()) for line in top.get_lines()}
    assert colours["trace"] == pytest.approx(plotting.rgb01("trace"))


def test_draw_route_alone() -> None:
    """The route without a trace, for figures that draw their own traces over it."""
    fig, ax = agg_axes()
    target = np.array([[0.0, 0.0], [20.0, 0.0], [20.0, 15.0]])
    plotting.draw_route(ax, target, target_done=target[:2], corridor=3.0,
                        pads=[np.array([[20.0, 10.0], [24.0, 10.0]])])  # fmt: skip
    labels = {line.get_label(): line for line in ax.get_lines()}
    assert np.array_equal(labels[LABELS["target"]].get_xydata(), target)
    assert labels[LABELS["target"]].get_color() == plotting.rgb01("target")
    assert LABELS["target_done"] in labels and LABELS["pad"] in labels
    assert len(ax.collections) == 1  # the corridor band
    fig.canvas.draw()
    # with a pad width, the electrode's rectangle (4 x 3 along the pad) under its line
    fig, ax = agg_axes()
    plotting.draw_route(ax, target, corridor=3.0, pad_width=3.0,
                        pads=[np.array([[20.0, 10.0], [24.0, 10.0]])])  # fmt: skip
    (xy,) = [p.get_xy() for p in ax.patches if len(p.get_xy())]  # (fill([]) is empty)
    assert np.allclose([xy[:, 0].min(), xy[:, 0].max(), xy[:, 1].min(), xy[:, 1].max()],
                       [20.0, 24.0, 8.5, 11.5])  # fmt: skip
    fig.canvas.draw()


def test_renderer_blits_the_same_picture_as_a_full_draw() -> None:
    """TopViewRenderer draws the static part once; its frames match a full draw."""
    trace = spiral(80)
    target = np.array([[0.0, 0.0], [20.0, 0.0]])
    rod = np.column_stack([np.full(5, trace[-1, 0]), np.arange(5.0), np.linspace(0, 3, 5)])
    kw = dict(target=target, n_start=10, corridor=2.0, flow_scale=40.0, um_per_lvb=0.1,
              target_done=np.zeros((0, 2)), rod=rod, flow=(0.0, 0.0))  # fmt: skip
    extent = top_view_extent(trace, target)
    renderer = plotting.TopViewRenderer(extent, (320, 320), **kw)
    first = renderer.render(trace[:20], title="a")
    state = dict(rod=rod, flow=(0.05, 0.02), target_done=np.array([[0.0, 0.0], [8.0, 0.0]]))
    frame = renderer.render(trace, title="b\nc", **state)
    assert frame.shape == (320, 320, 3) and not np.array_equal(first, frame)
    full = top_view_image(trace, size=(320, 320), title="b\nc", extent=extent,
                          **{**kw, **state})  # fmt: skip
    # the same picture, up to antialiasing where moving lines cross the kept background
    differ = (np.abs(frame.astype(int) - full.astype(int)).max(axis=2) > 64).mean()
    assert differ < 0.03, differ

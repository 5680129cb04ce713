"""Software rasteriser of ``CNTDeposit-v0``: the image observation, the rendered top view
and the matplotlib window of ``render_mode="human"``.

Pixel coordinates are (col, row-from-bottom): x to the right, z up. Images are uint8
(rows top-down, cols, 3).
"""

from __future__ import annotations

import math
from typing import Any, NamedTuple

import numpy as np

from cnt_env.task import geometry, scoring

__all__ = ["RouteLayers", "Window", "draw", "image_observation", "path_head", "top_view"]

#: Values of the route's layers in the image observation (``image_layers="route"``):
#: channel 1, the corridor band under the route's line (255; 128 where reached);
#: channel 2, keep-outs and pads under the suspended rod (255).
CORRIDOR_VALUE = 64
KEEPOUT_VALUE = 96
PAD_VALUE = 160


def draw(img: np.ndarray, points: np.ndarray, color: int | tuple[int, int, int],
         width: int = 1, channel: int | None = None) -> None:  # fmt: skip
    """Rasterise the polyline ``points`` (pixel coordinates (col, row-from-bottom)) into
    ``img`` (rows top-down), clipped to the image, ``width`` pixels wide: every channel
    set to ``color``, or only ``channel`` set to the value ``color``."""
    if len(points) == 0:
        return
    h, w = img.shape[:2]
    if len(points) == 1:
        samples = points
    else:
        seg = np.diff(points, axis=0)
        n_sub = np.maximum(1, np.ceil(2.0 * np.max(np.abs(seg), axis=1)).astype(np.int64))
        n_sub = np.minimum(n_sub, 4 * (h + w))  # a segment far longer than the view
        k = np.arange(int(n_sub.sum())) - np.repeat(np.cumsum(n_sub) - n_sub, n_sub)
        t = k / np.repeat(n_sub, n_sub)
        samples = np.repeat(points[:-1], n_sub, axis=0) + t[:, None] * np.repeat(seg, n_sub, 0)
        samples = np.concatenate([samples, points[-1:]])
    cols = np.floor(samples[:, 0]).astype(np.int64)
    rows = h - 1 - np.floor(samples[:, 1]).astype(np.int64)
    lo = -(width // 2)
    for dr in range(lo, lo + width):
        for dc in range(lo, lo + width):
            r, c = rows + dr, cols + dc
            ok = (r >= 0) & (r < h) & (c >= 0) & (c < w)
            if channel is None:
                img[r[ok], c[ok]] = color
            else:
                img[r[ok], c[ok], channel] = color


def path_head(path: np.ndarray, path_s: np.ndarray, s: float) -> np.ndarray:
    """The polyline ``path`` (n, 2), with arc lengths ``path_s`` (n,), from its start to
    arc length ``s``."""
    cut = int(np.searchsorted(path_s, s, side="right"))
    head = [np.interp(s, path_s, path[:, k]) for k in (0, 1)]
    return np.concatenate([path[:cut], [head]])


def _pixels(centre: np.ndarray, scale: float, size: int):
    def px(points: np.ndarray) -> np.ndarray:
        return (points - centre) * scale + 0.5 * size

    return px


class RouteLayers(NamedTuple):
    """What the image observation shows of a route besides its line (absolute, L_vb):
    the corridor half-width, the pads (p, 2, 2) with their width, the keep-outs."""

    width: float
    pads: np.ndarray
    pad_width: float
    keepouts: tuple[np.ndarray, ...]


def _pixel_centres(centre: np.ndarray, scale: float, size: int) -> np.ndarray:
    """World (x, z) of every pixel's centre, (size * size, 2) in the image's row-major
    order (rows top-down): the inverse of ``_pixels`` at col + 0.5, row-from-bottom + 0.5."""
    k = (np.arange(size) + 0.5 - 0.5 * size) / scale
    x = np.tile(centre[0] + k, size)
    z = np.repeat(centre[1] + k[::-1], size)
    return np.column_stack([x, z])


def image_observation(size: int, extent: float, trace_xz: np.ndarray, n0: int,
                      target: np.ndarray, target_done: np.ndarray | None,
                      rod_xz: np.ndarray,
                      route: RouteLayers | None = None) -> np.ndarray:  # fmt: skip
    """The ``(size, size, 3)`` uint8 image observation: ``extent`` L_vb square centred on
    the contact point (the last of ``trace_xz``). Channel 0: the trace (255 laid since node
    ``n0``, 128 before); channel 1: the target (255, and 128 over ``target_done``, the part
    already reached); channel 2: the suspended rod's horizontal projection.

    With ``route``, the route's layers lie under those: in channel 1 the corridor
    (``CORRIDOR_VALUE`` where a pixel's centre is within ``width`` of the target line, the
    score's "inside"), in channel 2 the keep-outs filled (``KEEPOUT_VALUE``) and the pads
    (``PAD_VALUE``: the line, and its rectangle when ``pad_width`` > 0)."""
    img = np.zeros((size, size, 3), dtype=np.uint8)
    scale = size / extent
    px = _pixels(trace_xz[-1], scale, size)
    if route is not None:
        centres = _pixel_centres(trace_xz[-1], scale, size)
        band = scoring.distances(centres, target) <= route.width
        img[..., 1].flat[band] = CORRIDOR_VALUE
        if route.keepouts:
            inside = geometry.in_polygons(centres, *geometry.pack(route.keepouts))
            img[..., 2].flat[inside] = KEEPOUT_VALUE
        if len(route.pads):
            if route.pad_width > 0.0:
                strips = geometry.in_pad_strips(centres, route.pads, 0.5 * route.pad_width)
                img[..., 2].flat[strips] = PAD_VALUE
            for pad in route.pads:
                draw(img, px(pad), PAD_VALUE, channel=2)
    draw(img, px(trace_xz[:n0]), 128, channel=0)
    draw(img, px(trace_xz[n0 - 1 :]), 255, channel=0)
    draw(img, px(target), 255, channel=1)
    if target_done is not None:
        draw(img, px(target_done), 128, channel=1)
    draw(img, px(rod_xz), 255, channel=2)
    return img


Extra = tuple[tuple[np.ndarray, tuple[int, int, int]], ...]


def top_view(size: int, trace_xz: np.ndarray, n0: int, target: np.ndarray,
             target_done: np.ndarray | None, rod_xz: np.ndarray, flow: tuple[float, float],
             vbar_max: float, min_extent: float, extra: Extra = ()) -> np.ndarray:  # fmt: skip
    """The rendered frame (uint8 (size, size, 3)), fitted to the target, the recent trace
    and the rod: target (red, dark over ``target_done``), earlier trace (grey), this
    episode's trace (blue), the rod (green), the contact point (black) and the flow
    (arrow in the lower-left corner, length v̄ / v̄_max). ``extra``: more polylines
    (absolute, L_vb) drawn first, with their colours (corridor edges, pads, keep-outs)."""
    img = np.full((size, size, 3), 255, dtype=np.uint8)
    recent = trace_xz[max(0, n0 - 50) :]
    box = np.concatenate([target, recent, rod_xz])
    lo, hi = box.min(axis=0), box.max(axis=0)
    extent = 1.15 * max(float(np.max(hi - lo)), min_extent)
    px = _pixels(0.5 * (lo + hi), size / extent, size)
    for pts, color in extra:
        draw(img, px(pts), color)
    draw(img, px(target), (240, 150, 150), width=2)
    if target_done is not None:
        draw(img, px(target_done), (190, 30, 30), width=2)
    draw(img, px(trace_xz[:n0]), (170, 170, 170))
    draw(img, px(trace_xz[n0 - 1 :]), (30, 80, 220), width=2)
    draw(img, px(rod_xz), (40, 160, 40))
    draw(img, px(trace_xz[-1:]), (0, 0, 0), width=3)
    vbar, phi = flow
    base = np.array([0.1 * size, 0.1 * size])
    tip = base + (0.08 * size * vbar / vbar_max) * np.array([math.cos(phi), math.sin(phi)])
    draw(img, np.array([base, tip]), (0, 0, 0), width=2)
    return img


class Window:
    """The matplotlib window of ``render_mode="human"`` (created on the first frame)."""

    def __init__(self, fps: float) -> None:
        self.fps = float(fps)
        self._fig: Any = None
        self._image: Any = None

    def show(self, frame: np.ndarray) -> None:
        import matplotlib
        import matplotlib.pyplot as plt

        if self._fig is None:
            self._fig, ax = plt.subplots(figsize=(5, 5))
            ax.set_axis_off()
            self._image = ax.imshow(frame)
        else:
            self._image.set_data(frame)
        backend = matplotlib.get_backend().lower()
        try:
            from matplotlib.backends import BackendFilter, backend_registry

            interactive = backend not in backend_registry.list_builtin(
                BackendFilter.NON_INTERACTIVE
            )
        except ImportError:  # older matplotlib
            interactive = backend not in ("agg", "pdf", "ps", "svg", "cairo", "pgf", "template")
        if interactive:
            plt.pause(1.0 / self.fps)
        else:
            self._fig.canvas.draw()

    def close(self) -> None:
        if self._fig is not None:
            import matplotlib.pyplot as plt

            plt.close(self._fig)
            self._fig = None
            self._image = None

    def __getstate__(self) -> dict[str, Any]:
        return {"fps": self.fps, "_fig": None, "_image": None}

"""The image observation's route layers (cnt_env/task/raster.py): pixel counts in closed
form on a 64-pixel, 64 L_vb view (1 L_vb per pixel, pixel centres at k + 0.5 - 32)."""

from __future__ import annotations

import numpy as np
import pytest

from cnt_env.task import raster
from cnt_env.task.raster import CORRIDOR_VALUE, KEEPOUT_VALUE, PAD_VALUE, RouteLayers

SIZE = 64
NO_ROD = np.zeros((0, 2))
CONTACT = np.array([[0.0, 0.0]])  # the contact point at the origin: the view's centre
LINE = np.array([[-40.0, 0.0], [40.0, 0.0]])  # a route along x through the view


def image(route: RouteLayers | None, target: np.ndarray = LINE) -> np.ndarray:
    return raster.image_observation(SIZE, 64.0, CONTACT, 1, target, None, NO_ROD, route)


def layers(width: float = 5.0, pads=(), pad_width: float = 0.0, keepouts=()) -> RouteLayers:
    return RouteLayers(width, np.asarray(pads, float).reshape(-1, 2, 2), pad_width,
                       tuple(np.asarray(k, float) for k in keepouts))  # fmt: skip


def test_pixel_centres_invert_the_pixel_map() -> None:
    centre, scale = np.array([3.25, -7.5]), 2.0
    c = raster._pixel_centres(centre, scale, SIZE)
    px = raster._pixels(centre, scale, SIZE)(c)  # (col, row-from-bottom)
    rows, cols = np.divmod(np.arange(SIZE * SIZE), SIZE)  # row-major, rows top-down
    np.testing.assert_allclose(px, np.column_stack([cols, SIZE - 1 - rows]) + 0.5, atol=1e-12)


@pytest.mark.parametrize("width", [2.0, 5.0, 12.0])
def test_corridor_band_is_every_pixel_within_the_half_width(width: float) -> None:
    img = image(layers(width))
    ch = img[..., 1]
    rows_in = int(np.sum(np.abs(np.arange(SIZE) + 0.5 - 32) <= width))  # 2 floor(w + 0.5)
    assert np.count_nonzero(ch) == SIZE * rows_in
    assert np.count_nonzero(ch == 255) == SIZE  # the route's line, drawn over the band
    assert np.count_nonzero(ch == CORRIDOR_VALUE) == SIZE * (rows_in - 1)
    assert not img[..., 2].any()  # no keep-out, no pad, no rod


def test_keepout_is_filled_and_pads_are_strips_with_flat_ends() -> None:
    keep = [[10, 10], [20, 10], [20, 20], [10, 20]]
    pad = [[[-20, -10], [-20, 10]]]  # along z at x = -20
    img = image(layers(pads=pad, pad_width=4.0, keepouts=[keep]))
    ch = img[..., 2]
    assert np.count_nonzero(ch == KEEPOUT_VALUE) == 10 * 10  # centres 10.5 ... 19.5
    # |x + 20| <= 2: 4 columns; 0 <= u <= 20: centres -9.5 ... 9.5, 20 rows
    assert np.count_nonzero(ch == PAD_VALUE) == 4 * 20 + 1  # + the line's end pixel, z = 10
    line = image(layers(pads=pad, pad_width=0.0))[..., 2]
    assert np.count_nonzero(line == PAD_VALUE) == 21  # a line pad: one pixel per L_vb
    assert np.count_nonzero(np.any(line, axis=0)) == 1  # in one column


def test_route_layers_lie_under_the_trace_line_and_rod() -> None:
    keep = [[-30, -30], [30, -30], [30, 30], [-30, 30]]  # the whole view but its border
    trace = np.array([[-10.0, 0.0], [0.0, 0.0]])
    rod = np.array([[0.0, 0.0], [0.0, 8.0]])
    with_route = raster.image_observation(SIZE, 64.0, trace, 1, LINE, None, rod,
                                          layers(keepouts=[keep]))  # fmt: skip
    without = raster.image_observation(SIZE, 64.0, trace, 1, LINE, None, rod)
    assert np.array_equal(with_route[..., 0], without[..., 0])  # the trace as before
    on_line = without[..., 1] == 255
    assert np.array_equal(with_route[..., 1][on_line], without[..., 1][on_line])
    on_rod = without[..., 2] == 255
    assert np.array_equal(with_route[..., 2][on_rod], without[..., 2][on_rod])
    assert np.all(with_route[..., 2][~on_rod & (with_route[..., 2] > 0)] == KEEPOUT_VALUE)

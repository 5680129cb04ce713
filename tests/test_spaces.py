"""The action map both ways and the vector observation layout (cnt_env/task/spaces.py)."""

from __future__ import annotations

import math

import numpy as np
import pytest

from cnt_env.task.spaces import (
    POSITION_BOUND,
    ObservationLayout,
    action_from_flow,
    flow_from_action,
    keepout_in_view,
    rod_features,
)


@pytest.mark.parametrize("a", [(-1, -1), (1, 1), (1, 0), (0, -1), (0.3, -0.7), (0, 0)])
def test_flow_map_stays_in_the_disk_and_inverts(a) -> None:
    vbar, phi = flow_from_action(np.array(a, dtype=float), 0.13)
    assert 0.0 <= vbar <= 0.13
    back = action_from_flow(vbar, phi, 0.13)
    assert np.allclose(back, a, atol=1e-6)


def test_corners_and_edge_midpoints_land_on_the_rim() -> None:
    for a in [(1, 0), (0, 1), (1, 1), (-1, 1)]:
        assert flow_from_action(np.array(a, float), 0.1)[0] == pytest.approx(0.1)
    assert flow_from_action(np.array([1.0, 1.0]), 1.0)[1] == pytest.approx(math.pi / 4)


def test_layout_slices_bounds_and_build() -> None:
    layout = ObservationLayout(4, 3, (2.0, 8.0))
    assert layout.structure == {"trace": 8, "target": 6, "flow": 2, "rod": 7, "progress": 4}
    assert layout.size == 27 and layout.slices["rod"] == slice(16, 23)
    assert layout.space().shape == (27,)
    trace = np.column_stack([np.arange(3.0), np.zeros(3), np.zeros(3)])
    ahead = np.array([[5.0, 0.0], [6.0, 0.0], [2000.0, 0.0]])
    obs = layout.build(trace, ahead, np.array([1.0, 0.0]), np.zeros(7), np.zeros(4))
    assert obs.dtype == np.float32
    # the trace is padded with its oldest point, relative to the contact point (2, 0)
    assert obs[:8].tolist() == [-2, 0, -2, 0, -2, 0, -1, 0]
    assert obs[8:14].tolist() == [3, 0, 4, 0, 1000, 0]  # clipped to POSITION_BOUND


def test_rod_features_interpolate_the_lean() -> None:
    nodes = np.array([[1.0, 0.5, 0.0], [1.0, 2.5, 0.0], [3.0, 8.5, 1.0]])
    f = rod_features(nodes, np.zeros(3), (2.0, 20.0))
    assert f[0] == 0.5 and f[1:3].tolist() == [1.0, 0.0]
    assert f[3:5].tolist() == [1.0, 0.0]  # height 2 lies between nodes 0 and 1: both x=1
    assert f[5:7].tolist() == [3.0, 1.0]  # above the rod: its top
    assert rod_features(np.zeros((0, 3)), np.zeros(3), (2.0,)).tolist() == [0, 0, 0, 0, 0]


@pytest.mark.parametrize("route", [None, "keepout", "none"])
@pytest.mark.parametrize("window", [None, 6.0])
def test_z_mirror_gives_the_observation_of_the_mirror_image(route, window) -> None:
    """The observation of a state mirrored in z (every z -> -z: trace, target, flow, rod,
    keep-out point) is ``z_mirror`` of the state's observation; the far point that stands
    for no keep-out (the env's contact + FAR) stays the far point."""
    from cnt_env.task.geometry import FAR

    rng = np.random.default_rng(3)
    layout = ObservationLayout(5, 4, (2.0, 8.0, 3.5), route=route is not None)
    trace = np.column_stack([np.cumsum(rng.uniform(0.5, 1.5, 12)), np.zeros(12),
                             rng.normal(0.0, 3.0, 12)])  # fmt: skip
    nodes = np.column_stack([trace[-1, 0] + rng.normal(0, 1, 6), np.linspace(0.2, 12.0, 6),
                             trace[-1, 2] + rng.normal(0, 1, 6)])  # fmt: skip
    ahead = rng.normal(0.0, 20.0, (4, 2))
    flow = np.array([0.3, -0.6])

    def obs(z: float) -> np.ndarray:
        t, n = trace * [1.0, 1.0, z], nodes * [1.0, 1.0, z]
        rod = rod_features(n, t[-1], layout.lean_heights)
        keep = None
        if route == "keepout":
            keep = np.array([15.0, 3.0, -8.0 * z])
        elif route == "none":  # the env's nearest keep-out point when there is none
            keep = np.array([15.0, *(t[-1, [0, 2]] + FAR)])
        return layout.build(t, ahead * [1.0, z], flow * [1.0, z], rod, np.arange(4.0) / 4,
                            window, keep)  # fmt: skip

    assert np.array_equal(obs(-1.0), layout.z_mirror(obs(1.0)))
    assert np.array_equal(layout.z_mirror(layout.z_mirror(obs(1.0))), obs(1.0))
    assert not np.array_equal(obs(-1.0), obs(1.0))  # the mirror image is another state
    with pytest.raises(ValueError, match="one observation"):
        layout.z_mirror(obs(1.0)[None])


def test_keepout_in_view_reads_the_bound_as_none() -> None:
    """One test of "no keep-out" for the gate and the z-mirror: the far point the env writes
    (clipped to the bound in both offsets) and a point at the bound in either offset are
    none; anything inside the bound is a keep-out, and z_mirror flips only those."""
    b = POSITION_BOUND
    assert keepout_in_view(999.0, -999.0) and keepout_in_view(0.0, 0.0)
    for far in ((b, b), (b, 5.0), (5.0, -b), (-b, -b)):
        assert not keepout_in_view(*far)
    layout = ObservationLayout(5, 4, (2.0, 8.0), route=True)
    k = layout.slices["route"].start + 1
    for point, mirrored in (((b, b), (b, b)), ((b, 5.0), (b, 5.0)), ((12.0, 5.0), (12.0, -5.0))):
        obs = np.zeros(layout.size, dtype=np.float32)
        obs[k : k + 2] = point
        assert layout.z_mirror(obs)[k : k + 2].tolist() == list(mirrored)


def test_action_z_mirror_is_the_flows_mirror_image() -> None:
    from cnt_env.task.spaces import ACTION_Z_MIRROR

    for a in [(0.3, -0.7), (1.0, 1.0), (-0.2, 0.4)]:
        v, phi = flow_from_action(np.array(a), 0.13)
        vm, phim = flow_from_action(np.array(a) * ACTION_Z_MIRROR, 0.13)
        assert vm == pytest.approx(v) and phim == pytest.approx(-phi)

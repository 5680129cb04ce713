"""benchmarks/outside_where.py: the outside length of a trace, split at its first L_vb,
against closed forms; and the reading of a cnt-evaluate directory."""

from __future__ import annotations

import itertools
import json

import numpy as np
import pytest

from benchmarks import outside_where as ow  # the repo root is on pytest's pythonpath


def _trace(points: list[tuple[float, float]], step: float = 0.5) -> np.ndarray:
    """A polyline through ``points`` sampled every ``step`` (nodes as the trace's)."""
    pts = np.asarray(points, dtype=float)
    out = []
    for a, b in itertools.pairwise(pts):
        n = round(float(np.hypot(*(b - a))) / step)
        out += [a + (b - a) * k / n for k in range(n)]
    return np.array([*out, pts[-1]])


def test_outside_lengths_split_a_known_excursion() -> None:
    """Along x for 10, out to z = 30 and back (a 20 + 20 excursion, of which 2 x 10 + 0.5
    beyond the half-width 20), then along x: the excursion lies within the first 60 L_vb
    of trace, none after. Nodes 0.5 apart resolve each of the two crossings of the
    corridor's edge to half a node: +-1 in all."""
    route = np.array([[0.0, 0.0], [200.0, 0.0]])
    trace = _trace([(0, 0), (10, 0), (10, 30), (10.5, 30), (10.5, 0), (100, 0)])
    early, late, laid = ow.outside_lengths(trace, route, 20.0, first=60.0)
    assert laid == pytest.approx(10 + 30 + 0.5 + 30 + 89.5)
    assert early == pytest.approx(2 * 10 + 0.5, abs=1.0)
    assert late == 0.0
    # the same excursion after the first 10 L_vb counts as "after"
    early, late, _ = ow.outside_lengths(trace, route, 20.0, first=10.0)
    assert early == 0.0 and late == pytest.approx(2 * 10 + 0.5, abs=1.0)
    # inside a corridor wider than the excursion: nothing outside
    assert ow.outside_lengths(trace, route, 31.0, first=60.0)[:2] == (0.0, 0.0)


def test_analyse_reads_an_evaluation_directory(tmp_path) -> None:
    """Per-policy means and per-episode rows from episodes.json + traces.npz, the
    keep-out route skipped; the route's width is the held-out route's."""
    from cnt_env.task import routes

    w = routes.held_out("u_turn").width
    inside = _trace([(0, 0), (100, 0)])
    # out to w + 10 and back within the first 60 L_vb: 2 x 10 + 1 outside
    excursion = _trace([(0, 0), (5, 0), (5, w + 10), (6, w + 10), (6, 0), (100, 0)])
    route = np.array([[0.0, 0.0], [300.0, 0.0]])
    rows = [{"policy": "a", "target": "u_turn", "seed": 0, "score": 1.0},
            {"policy": "b", "target": "u_turn", "seed": 0, "score": 0.9},
            {"policy": "b", "target": "detour_block", "seed": 0, "score": 0.5}]  # fmt: skip
    (tmp_path / "episodes.json").write_text(json.dumps(rows))
    np.savez(tmp_path / "traces.npz", trace_0=inside, target_0=route, trace_1=excursion,
             target_1=route, trace_2=excursion, target_2=route)  # fmt: skip
    rep = ow.analyse(tmp_path, 60.0, {"detour_block"})
    assert rep["summary"]["a"]["outside_first"] == 0.0
    assert rep["summary"]["a"]["precision"] == 1.0
    b = rep["summary"]["b"]
    assert b["episodes"] == 1 and b["outside_first"] == pytest.approx(21.0, abs=1.0)
    assert b["precision_without_first"] == 1.0 > b["precision"]
    assert [e["target"] for e in rep["episodes"]] == ["u_turn", "u_turn"]


def test_outside_by_leg_finds_each_excursion_and_its_side() -> None:
    """An L route, (0,0) -> (100,0) -> (100,100), w = 20: an excursion 30 to +z off the
    first leg (its left, heading +x) and one 30 to +x off the second (its right, heading
    +z), each 2 x 10 + 0.5 beyond the corridor (to half a node at each of its crossings)."""
    route = np.array([[0.0, 0.0], [100.0, 0.0], [100.0, 100.0]])
    trace = _trace([(0, 0), (40, 0), (40, 30), (40.5, 30), (40.5, 0), (100, 0), (100, 60),
                    (130, 60), (130, 60.5), (100, 60.5), (100, 100)])  # fmt: skip
    by = ow.outside_by_leg(trace, route, 20.0)
    assert by.shape == (2, 2)
    assert by[0, 0] == pytest.approx(20.5, abs=1.0) and by[0, 1] == 0.0
    assert by[1, 1] == pytest.approx(20.5, abs=1.0) and by[1, 0] == 0.0
    # the total is outside_lengths' (both parts)
    early, late, _ = ow.outside_lengths(trace, route, 20.0, first=60.0)
    assert by.sum() == pytest.approx(early + late)
    # the mirror image (z -> -z) swaps the sides
    mirror = ow.outside_by_leg(trace * [1, -1], route * [1, -1], 20.0)
    assert np.allclose(mirror, by[:, ::-1])


def test_corner_overshoot_measures_a_run_past_each_corner() -> None:
    """An L route (0,0)-(50,0)-(50,60), half-width 15. A trace that runs along x to 62,
    comes back and climbs overshot the corner by 12; its later swing out to x = 80 near
    the first leg's line comes after it reached the next leg's midpoint (50, 30) and is
    not counted. A trace that cuts the corner along (40,0)-(48,30) leaves the first leg's
    band (|z| <= 15) at x = 44: 6 early (-6, to the nodes' 0.5 spacing)."""
    wp = np.array([[0.0, 0.0], [50.0, 0.0], [50.0, 60.0]])
    late = _trace([(0, 0), (62, 0), (55, 5), (50, 40), (50, 60), (80, 5)])
    assert ow.corner_overshoot(late, wp, 15.0) == pytest.approx([12.0])
    early = _trace([(0, 0), (40, 0), (48, 30), (50, 60)])
    assert ow.corner_overshoot(early, wp, 15.0) == pytest.approx([-6.0], abs=0.2)

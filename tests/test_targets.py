"""Target paths (cnt_env.task.targets): every family's geometry, determinism given the seed,
the held-out set, and what reset(options={"target": ...}) accepts."""

from __future__ import annotations

import math
import re

import numpy as np
import pytest

from cnt_env.task import targets as T


def rng(seed: int = 0) -> np.random.Generator:
    return np.random.default_rng(seed)


def headings(points: np.ndarray) -> np.ndarray:
    d = np.diff(points, axis=0)
    return np.arctan2(d[:, 1], d[:, 0])


def turning(points: np.ndarray) -> np.ndarray:
    """Signed turn at each interior vertex (rad)."""
    h = headings(points)
    return np.angle(np.exp(1j * np.diff(h)))


@pytest.mark.parametrize("family", sorted(T.FAMILIES))
def test_family_is_a_valid_target_from_the_origin(family: str) -> None:
    for seed in range(20):
        t = T.draw(family, rng(seed))
        assert t.name == family
        assert t.points.dtype == np.float64 and t.points.ndim == 2 and t.points.shape[1] == 2
        np.testing.assert_array_equal(t.points[0], [0.0, 0.0])
        assert np.isfinite(t.points).all()
        assert 5.0 < t.length < 1000.0
        seg = np.hypot(*np.diff(t.points, axis=0).T)
        assert seg.min() > 0.0
        assert not t.points.flags.writeable


@pytest.mark.parametrize("family", sorted(T.FAMILIES))
def test_family_draws_are_deterministic_given_the_seed(family: str) -> None:
    a, b, c = T.draw(family, rng(7)), T.draw(family, rng(7)), T.draw(family, rng(8))
    np.testing.assert_array_equal(a.points, b.points)
    assert a.params == b.params
    assert not (a.points.shape == c.points.shape and np.array_equal(a.points, c.points))


def test_straight_has_the_drawn_length_and_heading() -> None:
    t = T.draw("straight", rng(1))
    lo, hi = T.STRAIGHT_LENGTH_RANGE
    assert lo <= t.length <= hi
    assert t.length == pytest.approx(t.params["length"], rel=1e-12)
    end = t.points[-1]
    assert math.atan2(end[1], end[0]) == pytest.approx(t.params["heading"], abs=1e-12)


def test_l_bend_turns_once_by_the_drawn_angle() -> None:
    for seed in range(10):
        t = T.draw("l_bend", rng(seed))
        assert len(t.points) == 3
        assert abs(t.params["turn"]) >= T.L_BEND_TURN_RANGE[0]
        assert turning(t.points)[0] == pytest.approx(t.params["turn"], abs=1e-9)
        assert t.length == pytest.approx(t.params["leg1"] + t.params["leg2"])


def test_arc_is_on_a_circle_with_the_drawn_sweep() -> None:
    t = T.draw("arc", rng(2))
    r, sweep, h = t.params["radius"], t.params["sweep"], t.params["heading"]
    sign = 1.0 if sweep > 0 else -1.0
    centre = r * sign * np.array([-math.sin(h), math.cos(h)])
    np.testing.assert_allclose(np.hypot(*(t.points - centre).T), r, rtol=1e-12)
    assert np.sum(turning(t.points)) + turning(t.points)[0] == pytest.approx(sweep, rel=0.02)
    # chord sampling: consecutive points at most CURVE_SPACING apart
    assert np.hypot(*np.diff(t.points, axis=0).T).max() <= T.CURVE_SPACING + 1e-12


def test_zigzag_alternates_turns_and_progresses_along_its_heading() -> None:
    t = T.draw("zigzag", rng(3))
    turns = turning(t.points)
    assert len(turns) == t.params["n_legs"] - 1
    np.testing.assert_allclose(np.abs(turns), t.params["turn"], rtol=1e-9)
    assert np.all(np.sign(turns[1:]) == -np.sign(turns[:-1]))
    d = t.points[-1]
    h = t.params["heading"]
    along = d[0] * math.cos(h) + d[1] * math.sin(h)
    across = -d[0] * math.sin(h) + d[1] * math.cos(h)
    assert along > 0 and abs(across) <= t.params["leg"]


def test_serpentine_has_the_drawn_amplitude_and_wavelength() -> None:
    for seed in range(5):
        t = T.draw("serpentine", rng(seed))
        a, lam, h = t.params["amplitude"], t.params["wavelength"], t.params["heading"]
        # back to the canonical frame: progression along +x, runs along z
        c, s = math.cos(h), math.sin(h)
        p = t.points @ np.array([[c, -s], [s, c]])
        assert p[:, 1].max() - p[:, 1].min() == pytest.approx(2 * a, rel=1e-3)  # peak to peak
        assert p[-1, 0] - p[0, 0] == pytest.approx(t.params["periods"] * lam, rel=1e-9)
        # a meander, not a coil: it never goes backwards along the progression
        assert np.all(np.diff(p[:, 0]) >= -1e-9)
        # the ideal path length: runs of (2A - lambda/2), semicircles of radius lambda/4
        n = 2 * t.params["periods"]
        ideal = n * (2 * a - lam / 2) + n * math.pi * lam / 4
        assert t.length == pytest.approx(ideal, rel=2e-3)


def test_smooth_curvature_is_bounded() -> None:
    for seed in range(5):
        t = T.draw("smooth", rng(seed))
        seg = np.hypot(*np.diff(t.points, axis=0).T)
        kappa = np.abs(turning(t.points)) / seg[:-1]
        assert kappa.max() <= 1.0 / T.SMOOTH_MIN_RADIUS * 1.01
        assert t.length == pytest.approx(t.params["length"], rel=1e-9)


def test_sample_covers_every_family_and_never_a_held_out_target() -> None:
    g = rng(11)
    names = {T.sample(g).name for _ in range(300)}
    assert names == set(T.FAMILIES)
    assert not names & set(T.HELD_OUT)
    only = {T.sample(g, ("arc", "zigzag")).name for _ in range(50)}
    assert only == {"arc", "zigzag"}
    with pytest.raises(ValueError):
        T.sample(g, ())


@pytest.mark.parametrize("name", T.HELD_OUT)
def test_held_out_targets_are_fixed(name: str) -> None:
    a, b = T.held_out(name), T.held_out(name)
    np.testing.assert_array_equal(a.points, b.points)
    np.testing.assert_array_equal(a.points[0], [0.0, 0.0])
    assert a.name == name and 20.0 < a.length < 1000.0
    assert name not in T.FAMILIES
    # resolve ignores the generator for held-out names
    g = rng(0)
    state = g.bit_generator.state
    np.testing.assert_array_equal(T.resolve(name, g).points, a.points)
    assert g.bit_generator.state == state


def test_paper_serpentine_is_the_papers_baseline() -> None:
    t = T.held_out("paper_serpentine")
    assert t.points[:, 1].max() - t.points[:, 1].min() == pytest.approx(60.0, rel=1e-3)
    assert t.points[-1, 0] == pytest.approx(14.0)  # 2 periods of 7 along +x


def test_resolve_accepts_names_targets_and_polylines() -> None:
    g = rng(5)
    assert T.resolve("arc", g).name == "arc"
    t = T.held_out("jog")
    assert T.resolve(t, g) is t
    custom = T.resolve([[3.0, 4.0], [3.0, 4.0], [13.0, 4.0], [13.0, 14.0]], g)
    assert custom.name == "custom"
    np.testing.assert_array_equal(custom.points, [[0, 0], [10, 0], [10, 10]])  # dup dropped
    assert custom.length == pytest.approx(20.0)


@pytest.mark.parametrize(
    "bad",
    ["nope", [[0.0, 0.0]], [[0, 0], [np.nan, 1]], [[0, 0, 0], [1, 1, 1]], [[1, 1], [1, 1]],
     [[0, 0], [2e4, 0]], "straight_line", [["a", "b"], ["c", "d"]]],
)  # fmt: skip
def test_resolve_rejects_bad_targets(bad) -> None:
    with pytest.raises(ValueError):
        T.resolve(bad, rng())


def test_resample_keeps_vertices_and_spacing() -> None:
    pts = np.array([[0.0, 0.0], [3.0, 0.0], [3.0, 0.1]])
    samples, s = T.resample(pts, 0.5)
    assert np.hypot(*np.diff(samples, axis=0).T).max() <= 0.5 + 1e-12
    for v in pts:
        assert np.min(np.hypot(*(samples - v).T)) == 0.0
    assert s[-1] == pytest.approx(3.1)
    np.testing.assert_allclose(np.diff(s), np.hypot(*np.diff(samples, axis=0).T))


def test_polyline_distances_match_a_dense_brute_force() -> None:
    g = rng(4)
    poly = np.cumsum(g.normal(size=(7, 2)) * 5.0, axis=0)
    pts = g.uniform(-20, 20, size=(50, 2))
    out = np.empty(len(pts))
    T.polyline_distances(pts, poly, out)
    dense, _ = T.resample(poly, 1e-3)
    brute = np.min(np.hypot(*(pts[:, None, :] - dense[None, :, :]).transpose(2, 0, 1)), axis=1)
    np.testing.assert_allclose(out, brute, atol=1e-3)
    assert np.all(out <= brute + 1e-12)  # exact distances never exceed the sampled ones


def test_mark_covered_flags_samples_within_tolerance() -> None:
    samples = np.array([[0.0, 0.0], [1.0, 0.0], [2.0, 0.0], [3.0, 0.0]])
    hit = np.zeros(4, dtype=bool)
    T.mark_covered(samples, np.array([[1.0, 0.5], [3.0, 0.5]]), 0.5, hit)
    assert hit.tolist() == [False, True, False, True]
    T.mark_covered(samples, np.array([[0.0, 0.4]]), 0.5, hit)  # accumulates
    assert hit.tolist() == [True, True, False, True]
    T.mark_covered(samples, np.zeros((0, 2)), 0.5, hit)
    assert hit.tolist() == [True, True, False, True]


def test_patterns_measure_a_serpentine_target_as_drawn() -> None:
    """The target's amplitude and wavelength follow the conventions of patterns.py."""
    from cnt_env.patterns import MeasureOptions, measure

    pts = T.serpentine_points(amplitude=20.0, wavelength=8.0, periods=6, heading=0.0)
    m = measure(pts, MeasureOptions(transient_length=0.0), substrate="stepped")
    assert m["amplitude"] == pytest.approx(20.0, rel=0.02)
    assert m["wavelength"] == pytest.approx(8.0, rel=0.02)


# ---- routes (cnt_env/task/routes.py) --------------------------------------------------------


def test_route_families_are_valid_and_scale_with_difficulty() -> None:
    from cnt_env.task import routes

    for fam in routes.FAMILIES:
        easy = [routes.draw(fam, np.random.default_rng(s), 0.0) for s in range(8)]
        hard = [routes.draw(fam, np.random.default_rng(s), 1.0) for s in range(8)]
        for r in easy + hard:
            assert r.name == fam and np.array_equal(r.waypoints[0], [0.0, 0.0])
            assert r.width >= routes.MIN_HALF_WIDTH and r.length >= 10.0
        if fam not in ("band", "detour"):  # a detour's length follows its corridor's width
            assert np.mean([r.length for r in hard]) > np.mean([r.length for r in easy]), fam
        if fam != "band":
            assert np.mean([r.width for r in hard]) < np.mean([r.width for r in easy]), fam
    detour = routes.draw("detour", np.random.default_rng(0))
    assert len(detour.keepouts) == 1
    assert len(routes.draw("pads", np.random.default_rng(0)).pads) >= 1


def test_a_family_named_twice_is_drawn_twice_as_often() -> None:
    """``families`` is a list to draw from uniformly: repeating a name weights it (the
    keep-out curriculum, training/configs/ppo_keepout.yml)."""
    from cnt_env.task import routes

    rng = np.random.default_rng(0)
    n = 3000
    names = [routes.sample(rng, ("straight", "detour", "detour"), 0.0).name for _ in range(n)]
    share = names.count("detour") / n
    # binomial: sd of the share = sqrt(2/9 / n) ~ 0.0086; 2/3 within 4 sd
    assert abs(share - 2.0 / 3.0) < 0.035, share
    assert set(names) == {"straight", "detour"}


def test_held_out_routes_are_fixed_and_never_sampled() -> None:
    from cnt_env.task import routes

    assert "u_turn" in routes.HELD_OUT
    u = routes.held_out("u_turn")
    # designed at w = 15: 60 + 40 + 60 L_vb, scaled with the band (routes.ROUTE_SCALE)
    k = routes.ROUTE_SCALE
    assert u.width == pytest.approx(routes.DEFAULT_HALF_WIDTH) == pytest.approx(15.0 * k)
    assert u.length == pytest.approx(160.0 * k)
    rng = np.random.default_rng(0)
    names = {routes.sample(rng).name for _ in range(200)}
    assert names == set(routes.FAMILIES) and not names & set(routes.HELD_OUT)
    with pytest.raises(ValueError):
        routes.held_out("nope")


def test_route_keepouts_stay_off_the_route() -> None:
    from cnt_env.task import routes
    from cnt_env.task.scoring import RouteScore

    for name in routes.HELD_OUT:
        r = routes.held_out(name)
        line = T.resample(r.waypoints, 0.5)[0]
        m = RouteScore(r.waypoints, r.width, r.pads, r.keepouts).update(line, len(line))
        assert m["shorts"] == 0 and m["completed"] and m["pads_crossed"] == len(r.pads), name


@pytest.mark.parametrize(
    ("spec", "what"),
    [
        ({"waypoints": [[0, 0], [80, 0]], "keepouts": [{"rect": [-5, -5, 5, 5]}]}, "waypoint 0"),
        ({"waypoints": [[0, 0], [80, 0]], "keepouts": [{"rect": [30, -5, 40, 5]}]}, "leg 0"),
        ({"waypoints": [[0, 0], [40, 0], [40, 60]], "keepouts": [[[20, 30], [60, 30], [60, 40]]]},
         "leg 1"),
        ({"waypoints": [[0, 0], [80, 0]], "pads": [[[40, 19], [40, 30]]]}, "pad 0"),
        # corner to corner through a rectangle: no edge is crossed properly
        ({"waypoints": [[0, 0], [50, 50]], "keepouts": [{"rect": [20, 20, 30, 30]}]}, "leg 0"),
    ],
)  # fmt: skip
def test_a_route_whose_parts_contradict_is_refused_with_its_reason(spec, what) -> None:
    """A waypoint in a keep-out, a leg across one, a pad beyond the corridor's reach."""
    from cnt_env.task import routes

    with pytest.raises(ValueError, match=what):
        routes.from_dict(spec)


def test_a_route_beside_its_keepouts_and_pads_at_the_corridor_edge_is_accepted() -> None:
    """The limits of the check: touching a keep-out is not crossing it; a pad whose end
    is exactly w from the route is in reach. Every family draw passes (none is refused)."""
    from cnt_env.task import routes

    routes.from_dict({"waypoints": [[0, 0], [80, 0]], "keepouts": [{"rect": [30, 0, 40, 5]}],
                      "pads": [[[60, 18.5], [60, 30]]]})  # fmt: skip
    for fam in routes.FAMILIES:
        for d in (0.0, 0.5, 1.0):
            rng = np.random.default_rng(7)
            for _ in range(100):
                routes.draw(fam, rng, d)


def test_pad_width_round_trips_reaches_and_refuses_bad_values() -> None:
    """``pad_width`` (an electrode strip's width): read from and written to the dict
    format (only when > 0, so files of line pads stay as they are), reaching half of it
    further than a line pad, and refused when negative or not finite."""
    from cnt_env.task import routes

    spec = {"waypoints": [[0, 0], [80, 0]], "pads": [[[40, 21], [40, 30]]]}
    with pytest.raises(ValueError, match="pad 0"):  # 21 from the route, w 18.5
        routes.from_dict(spec)
    r = routes.from_dict({**spec, "pad_width": 6.0})  # the strip's edge at 18
    assert r.pad_width == 6.0 and r.to_dict()["pad_width"] == 6.0
    again = routes.from_dict(r.to_dict())
    assert again.pad_width == 6.0 and np.array_equal(again.pads, r.pads)
    assert "pad_width" not in routes.from_dict({"waypoints": [[0, 0], [80, 0]]}).to_dict()
    for bad in (-1.0, float("nan"), float("inf")):
        with pytest.raises(ValueError, match="pad_width"):
            routes.from_dict({**spec, "pad_width": bad})


def test_a_closed_keepout_ring_is_the_open_polygon_and_edges_are_touching() -> None:
    """GeoJSON writes a polygon's ring closed (the first vertex again at the end): the
    route keeps the polygon with its zero-length edges dropped, so the follower's plan
    and the observation see it (a closed ring made them NaN, and the follower shorted
    detour_block on every seed). A waypoint on a keep-out's edge or corner touches it,
    whichever edge (the even-odd rule counts some edges in); fewer than three distinct
    vertices is refused."""
    from cnt_env.task import routes

    ring = [[45, -8], [75, -8], [75, 21], [45, 21]]
    spec = {"waypoints": [[0, 0], [30, 0], [30, 36], [90, 36], [90, 0], [120, 0]]}
    closed = routes.from_dict({**spec, "keepouts": [[*ring, ring[0]]]})
    doubled = routes.from_dict({**spec, "keepouts": [[*ring[:2], ring[1], *ring[2:]]]})
    for r in (closed, doubled):
        np.testing.assert_array_equal(r.keepouts[0], np.array(ring, dtype=float))
    # the route's start on each edge and two corners of a 10 x 10 square, leaving it
    for x, z in ([0, 5], [5, 0], [10, 5], [5, 10], [0, 0], [10, 10]):
        away = (20.0 * np.sign(x - 5.0), 20.0 * np.sign(z - 5.0))
        routes.from_dict({"waypoints": [[0, 0], away],
                          "keepouts": [{"rect": [-x, -z, 10 - x, 10 - z]}]})  # fmt: skip
    with pytest.raises(ValueError, match="3 distinct"):
        routes.from_dict({**spec, "keepouts": [[[45, -8], [75, -8], [45, -8]]]})
    with pytest.raises(ValueError, match="inside keep-out"):
        routes.from_dict({"waypoints": [[0, 0], [20, 0]], "keepouts": [{"rect": [-1, -1, 1, 1]}]})


def test_segment_distance_and_crossing_against_closed_forms() -> None:
    from cnt_env.task.geometry import segment_distance, segments_cross

    a = np.array
    assert segments_cross(a([0, 0]), a([2, 2]), a([0, 2]), a([2, 0]))
    assert not segments_cross(a([0, 0]), a([1, 0]), a([1, 0]), a([1, 5]))  # touching
    assert segment_distance(a([0, 0]), a([2, 2]), a([0, 2]), a([2, 0])) == 0.0
    # parallel, offset by 3
    assert segment_distance(a([0, 0]), a([4, 0]), a([1, 3]), a([2, 3])) == pytest.approx(3.0)
    # end to end along a line: the gap between them
    assert segment_distance(a([0, 0]), a([1, 0]), a([4, 0]), a([6, 0])) == pytest.approx(3.0)
    # a degenerate segment (a point) to a segment: the point's distance
    assert segment_distance(a([3, 4]), a([3, 4]), a([0, 0]), a([0, -5])) == pytest.approx(5.0)


def test_a_route_file_reads_named_routes_in_json_and_yaml(tmp_path) -> None:
    """cnt-evaluate --route-file: a JSON list of named route dicts or a YAML mapping
    {name: route dict}; each route as reset builds it (moved to start at the origin)."""
    import json

    from cnt_env.task import routes as R

    route = {"name": "jog", "waypoints": [[5, 5], [65, 5], [65, 45]], "width": 16.0,
             "keepouts": [{"rect": [80, 10, 90, 30]}]}  # fmt: skip
    (tmp_path / "r.json").write_text(json.dumps([route]))
    yml = "jog:\n  waypoints: [[5, 5], [65, 5], [65, 45]]\n  width: 16.0\n"
    (tmp_path / "r.yml").write_text(yml + "  keepouts: [{rect: [80, 10, 90, 30]}]\n")
    for name in ("r.json", "r.yml"):
        got = R.load_file(tmp_path / name)
        assert list(got) == ["jog"]
        r = got["jog"]
        assert r.name == "jog" and r.width == 16.0
        assert np.array_equal(r.waypoints, [[0, 0], [60, 0], [60, 40]])
        assert np.array_equal(r.keepouts[0].min(axis=0), [75, 5])
        assert R.resolve(r.to_dict(), np.random.default_rng(0)).name == "jog"


@pytest.mark.parametrize(
    ("text", "message"),
    [
        ("[", "not valid"),
        ("[]", "holds no route"),
        ('"u_turn"', "a list of route dicts"),
        ('[{"waypoints": [[0, 0], [9, 0]]}]', "give every route a 'name'"),
        ('[{"name": "u_turn", "waypoints": [[0, 0], [9, 0]]}]', "held-out route's name"),
        (
            '[{"name": "a", "waypoints": [[0, 0], [9, 0]]}, {"name": "a", "waypoints": [[0, 0], '
            "[0, 9]]}]",
            "used twice",
        ),
        (
            '{"a": {"waypoints": [[0, 0], [40, 0]], "keepouts": [{"rect": [10, -5, 20, 5]}]}}',
            "route 0 ('a'): leg 0",
        ),
        ('{"a": {"waypoints": [[0, 0]]}}', "route 0 ('a')"),
        ('{"a": [[0, 0], [9, 0]]}', "a route is a dict"),
    ],
)
def test_a_bad_route_file_names_the_file_and_the_route(tmp_path, text, message) -> None:
    from cnt_env.task import routes as R

    path = tmp_path / "routes.json"
    path.write_text(text)
    with pytest.raises(ValueError, match=re.escape(message)) as exc:
        R.load_file(path)
    assert str(path) in str(exc.value)


def test_the_committed_breadth_route_file_holds_route_breadths_routes() -> None:
    """benchmarks/results/breadth_routes.json (cnt-evaluate --route-file) is what
    ``route_breadth.py --write-routes`` writes: the seven breadth routes, unchanged."""
    from pathlib import Path

    from benchmarks.route_breadth import routes as breadth
    from cnt_env.task import routes as R

    path = Path(__file__).parents[1] / "benchmarks/results/breadth_routes.json"
    loaded = R.load_file(path)
    designed = breadth()
    assert list(loaded) == list(designed)
    for name, spec in designed.items():
        assert loaded[name].to_dict() == R.from_dict(spec).to_dict()

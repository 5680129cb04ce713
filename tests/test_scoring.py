"""The score Φ (cnt_env/task/scoring.py): incremental and batch agree, closed forms."""

from __future__ import annotations

import numpy as np
import pytest

from cnt_env.task.scoring import ThinScore, score_trace

LINE = np.array([[0.0, 0.0], [10.0, 0.0]])


def test_a_trace_on_the_target_scores_one() -> None:
    trace = np.column_stack([np.linspace(0, 10, 21), np.zeros(21)])
    s = score_trace(trace, LINE, 1.0)
    assert s == {"score": pytest.approx(1.0), "coverage": pytest.approx(1.0),
                 "precision": 1.0, "progress": 1.0}  # fmt: skip


def test_half_the_line_closed_form() -> None:
    trace = np.column_stack([np.linspace(0, 5, 11), np.zeros(11)])
    s = score_trace(trace, LINE, 0.5)
    # covered to x = 5.5 (tolerance 0.5, samples 0.25 apart, trapezoid weights: the last
    # covered sample carries half a spacing more): C = 5.625 / 10, G = 0.55, P = 1
    assert s["coverage"] == pytest.approx(0.5625)
    assert s["progress"] == pytest.approx(0.55)
    assert s["precision"] == 1.0
    assert s["score"] == pytest.approx(0.5 * 0.5625 + 0.25 + 0.25 * 0.55)


def test_incremental_equals_batch_whatever_is_frozen() -> None:
    rng = np.random.default_rng(0)
    trace = np.cumsum(rng.normal(0.4, 1.0, (60, 2)), axis=0)
    batch = ThinScore(LINE, 2.0).update(trace, len(trace))
    inc = ThinScore(LINE, 2.0)
    for n in range(1, 61, 7):
        m = inc.update(trace[:n], max(0, n - 5))
    m = inc.update(trace, 58)  # the frozen count never goes back (nodes never thaw)
    for k in ("coverage", "precision", "progress", "covered_end"):
        assert m[k] == batch[k]
    assert m["mean_distance"] == pytest.approx(batch["mean_distance"], rel=1e-12)


def test_cut_at_the_step_that_covers_the_end() -> None:
    trace = np.column_stack([np.linspace(0, 20, 41), np.zeros(41)])
    cut = score_trace(trace, LINE, 1.0, n_after_step=np.array([10, 21, 30, 41]))
    assert cut["precision"] == 1.0  # nothing past the end point counted
    assert score_trace(trace, LINE, 1.0)["precision"] < 1.0


# ---- the corridor score -------------------------------------------------------------------

U = np.array([[0.0, 0.0], [60.0, 0.0], [60.0, 40.0], [0.0, 40.0]])


def _along(points: np.ndarray, step: float = 1.0) -> np.ndarray:
    from cnt_env.task.targets import resample

    return resample(points, step)[0]


def test_route_laid_inside_the_corridor_scores_one() -> None:
    from cnt_env.task.scoring import RouteScore

    score = RouteScore(U, 15.0, np.zeros((0, 2, 2)), ())
    m = score.update(_along(U) + np.array([0.0, 5.0]), 0)  # 5 L_vb off the line: inside
    assert m["progress"] == 1.0 and m["completed"] and m["outside"] == 0.0
    assert float(np.sum(score.potentials(m))) == pytest.approx(1.0)


@pytest.mark.parametrize("stride", [1, 3, 7])
def test_route_incremental_equals_batch_whatever_is_frozen(stride: int) -> None:
    """The env updates the corridor score step by step, re-walking the nodes that may
    still move; pads crossed at the frozen boundary, shorts, coverage and progress must
    come out as a batch walk of the final trace gives them."""
    from cnt_env.task.routes import rectangle
    from cnt_env.task.scoring import RouteScore

    rng = np.random.default_rng(1)
    line = _along(U, 0.7)
    trace = line + rng.normal(0.0, 6.0, line.shape)  # zigzags across pads and the corridor
    pads = np.array([[[20.0, -8.0], [20.0, 8.0]], [[52.0, 20.0], [68.0, 20.0]],
                     [[30.0, 32.0], [30.0, 48.0]]])  # fmt: skip
    keep = (rectangle(35.0, 5.0, 45.0, 12.0), rectangle(62.0, 25.0, 70.0, 35.0))
    whole = RouteScore(U, 6.0, pads, keep).update(trace, len(trace))
    assert whole["pads_crossed"] == 3 and whole["shorts"] > 0 and 0 < whole["inside"] < 1
    for lag in (0, 1, 2, 5):  # nodes still moving behind the newest
        inc = RouteScore(U, 6.0, pads, keep)
        for n in [*range(1, len(trace), stride), len(trace)]:
            m = inc.update(trace[:n], max(0, n - lag))
            batch = RouteScore(U, 6.0, pads, keep).update(trace[:n], n)
            for k in batch:
                assert m[k] == pytest.approx(batch[k], rel=1e-12, abs=0.0), (k, lag, n)


def test_route_progress_cannot_skip_a_fold() -> None:
    from cnt_env.task.scoring import RouteScore

    # a trace straight from the start up to the last leg: inside the corridor at both
    # ends, but the route's middle is never followed
    trace = _along(np.array([[0.0, 0.0], [0.0, 40.0]]))
    m = RouteScore(U, 25.0, np.zeros((0, 2, 2)), ()).update(trace, len(trace))
    assert m["progress"] < 0.5 and not m["completed"]


def test_route_outside_pads_and_shorts() -> None:
    from cnt_env.task.routes import rectangle
    from cnt_env.task.scoring import RouteScore, score_route_trace

    line = np.array([[0.0, 0.0], [40.0, 0.0]])
    pads = np.array([[[20.0, -5.0], [20.0, 5.0]]])
    keep = (rectangle(10.0, 3.0, 30.0, 10.0),)
    half = _along(np.array([[0.0, 0.0], [10.0, 0.0]]))
    score = RouteScore(line, 4.0, pads, keep)
    m = score.update(half, len(half))
    terms = score.potentials(m)
    # G = 10/40 with weights (0.8, 0.2, 0.2) / 1.2, nothing outside, no pad yet
    assert m["pads_crossed"] == 0 and terms[0] == pytest.approx(0.8 * 0.25 / 1.2)
    zig = _along(np.array([[0.0, 0.0], [25.0, 0.0], [25.0, 6.0], [40.0, 6.0]]))
    m = score.update(zig, len(zig))
    assert m["pads_crossed"] == 1 and m["shorts"] > 0 and m["outside"] > 0
    t = score.potentials(m)
    a = t[:3].sum()
    o, k = m["outside"], min(1.0, 0.05 * m["short_length"])
    assert t.sum() == pytest.approx(a * (1 - o) * (1 - k))
    assert 0.0 <= t.sum() <= 1.0
    from cnt_env.task.routes import Route

    r = Route(line, 4.0, pads, keep)
    assert score_route_trace(zig, r)["score"] == pytest.approx(t.sum())


def test_the_route_score_never_rounds_below_zero() -> None:
    """Φ = A (1 - o) (1 - k) from its terms summed as the env and the tables sum them
    (np.sum): >= 0 to the last bit over random progress, pads, outside fractions and
    shorts, and exactly 0 on a full short (k = 1), where the terms summed to -1.1e-16
    before the short term was written as -(A - A o) k."""
    from cnt_env.task.scoring import RouteScore

    line = np.array([[0.0, 0.0], [40.0, 0.0]])
    pads = np.array([[[20.0, -5.0], [20.0, 5.0]]])
    score = RouteScore(line, 4.0, pads, ())
    rng = np.random.default_rng(0)
    full_short = []
    for _ in range(4000):
        m = {
            "progress": rng.uniform(),
            "pads_crossed": int(rng.integers(0, 2)),
            "n_pads": 1,
            "completed": bool(rng.integers(0, 2)),
            "outside": rng.uniform(),
            "short_length": rng.choice([0.0, rng.uniform(0.0, 20.0), 20.0, 1e3]),
        }
        phi = float(np.sum(score.potentials(m)))
        assert 0.0 <= phi <= 1.0
        if m["short_length"] >= 20.0:
            full_short.append(phi)
    assert full_short and all(phi == 0.0 for phi in full_short)


@pytest.mark.parametrize("spacing", [1.0, 0.2, 0.05])
def test_a_short_is_measured_in_length_whatever_the_node_spacing(spacing: float) -> None:
    """A straight trace through a keep-out 6 L_vb wide: the short's length is 6, and its
    penalty 0.05 per L_vb, on every mesh (the model lays nodes 0.2 L_vb apart, the
    surrogate 1). Counted per node, the 0.2 mesh paid 5x the 1's."""
    from cnt_env.task.routes import rectangle
    from cnt_env.task.scoring import RouteScore

    line = np.array([[0.0, 0.0], [40.0, 0.0]])
    keep = (rectangle(17.0, -3.0, 23.0, 3.0),)
    across = _along(np.array([[20.0, -15.0], [20.0, 15.0]]), spacing)  # crosses it along z
    score = RouteScore(line, 20.0, np.zeros((0, 2, 2)), keep)
    m = score.update(across, len(across))
    assert m["short_length"] == pytest.approx(6.0, abs=1e-9)
    assert m["shorts"] == pytest.approx(6.0 / spacing, abs=1.0)
    terms = score.potentials(m)
    a = terms[:3].sum()
    assert terms[4] == pytest.approx(-a * (1.0 - m["outside"]) * 0.05 * m["short_length"])


def test_a_short_at_the_frozen_boundary_is_counted_once() -> None:
    """The segments in a keep-out count once, also when one ends the frozen part and the
    next begins the next update's (the keep-out [9.5, 10.5] on a line of nodes 1 apart)."""
    from cnt_env.task.routes import rectangle
    from cnt_env.task.scoring import RouteScore

    line = np.array([[0.0, 0.0], [40.0, 0.0]])
    keep = (rectangle(9.5, -1.0, 10.5, 1.0),)
    trace = np.column_stack([np.arange(0.0, 21.0), np.zeros(21)])  # one node, x = 10, inside
    whole = RouteScore(line, 20.0, np.zeros((0, 2, 2)), keep).update(trace, 21)
    assert whole["shorts"] == 1 and whole["short_length"] == pytest.approx(1.0)
    for cut in (10, 11, 12):
        inc = RouteScore(line, 20.0, np.zeros((0, 2, 2)), keep)
        inc.update(trace[:cut], cut)
        assert inc.update(trace, 21)["short_length"] == pytest.approx(1.0), cut


@pytest.mark.parametrize("spacing", [1.0, 0.2])
def test_a_wire_thinner_than_the_node_spacing_is_a_short(spacing: float) -> None:
    """A neighbouring wire 0.3 L_vb wide, crossed at 45 degrees by a trace whose nodes
    step over it: the short is the chord 0.3 sqrt(2) whether or not a node lands inside."""
    from cnt_env.task.routes import rectangle
    from cnt_env.task.scoring import RouteScore

    line = np.array([[0.0, 0.0], [40.0, 0.0]])
    wire = (rectangle(20.35, -30.0, 20.65, 30.0),)
    diag = _along(np.array([[10.0, -10.0], [30.0, 10.0]]), spacing)
    m = RouteScore(line, 20.0, np.zeros((0, 2, 2)), wire).update(diag, len(diag))
    assert m["short_length"] == pytest.approx(0.3 * np.sqrt(2.0), rel=1e-9)
    if spacing == 1.0:
        assert m["shorts"] == 0  # no node inside: counted per node, no short at all


def test_success_is_a_working_circuit_not_just_a_completed_route() -> None:
    """``succeeded`` (the env's ``info["is_success"]``): completed, every pad met, no
    trace in a keep-out. Each of the three alone makes it fail, including a short only a
    segment makes (the wire thinner than the node spacing: ``shorts`` 0, length > 0)."""
    from cnt_env.task.routes import rectangle
    from cnt_env.task.scoring import RouteScore

    line = np.array([[0.0, 0.0], [40.0, 0.0]])
    pad = np.array([[[20.0, -5.0], [20.0, 5.0]]])
    clean = _along(line)

    def success(trace: np.ndarray, pads: np.ndarray, keep: tuple) -> bool:
        score = RouteScore(line, 20.0, pads, keep)
        m = score.update(trace, len(trace))
        assert m["completed"] == (trace[-1, 0] >= 40.0)
        return score.succeeded(m)

    assert success(clean, pad, ())
    assert not success(_along(np.array([[0.0, 0.0], [30.0, 0.0]])), pad, ())  # not completed
    beside = np.array([[[20.0, 8.0], [20.0, 15.0]]])  # a pad the straight trace passes by
    assert not success(clean, beside, ())
    assert success(clean, np.zeros((0, 2, 2)), (rectangle(10.0, 2.0, 30.0, 8.0),))  # clear
    assert not success(clean, pad, (rectangle(10.0, -1.0, 12.0, 8.0),))  # a short
    wire = (rectangle(19.85, -30.0, 20.15, 30.0),)  # between the nodes x = 19.80, 20.51
    diag = _along(np.array([[0.0, -20.0], [40.0, 20.0]]), 1.0)
    m = RouteScore(line, 20.0, np.zeros((0, 2, 2)), wire).update(diag, len(diag))
    assert m["completed"] and m["shorts"] == 0 and m["short_length"] > 0
    assert not RouteScore.succeeded(m)
    # the thin score: success is its termination, the end covered
    assert ThinScore.succeeded(ThinScore(LINE, 2.0).update(_along(LINE), 11))
    assert not ThinScore.succeeded(ThinScore(LINE, 2.0).update(_along(LINE * 0.5), 6))


# ---- pads as electrode strips (Route.pad_width) --------------------------------------------

PAD_ALONG_Z = np.array([[[20.0, -10.0], [20.0, 10.0]]])  # across a run along x


@pytest.mark.parametrize(
    ("offset", "pad_width", "touched"),
    [
        (1.5, 0.0, False),  # a line is met only by a crossing
        (1.5, 2.9, False),  # the strip reaches 1.45 < 1.5
        (1.5, 3.1, True),  # 1.55 >= 1.5
        (-1.5, 3.1, True),  # either side
        (0.0, 0.0, False),  # collinear with the pad: touching, not crossing
        (0.0, 1e-9, True),
    ],
)
def test_a_run_along_a_pad_touches_it_within_half_its_width(
    offset: float, pad_width: float, touched: bool
) -> None:
    """The serpentine's arm running along an electrode: a segment parallel to the pad,
    ``offset`` from its centre line, touches a strip of ``pad_width`` exactly when
    |offset| <= pad_width / 2 (the strip's edge)."""
    from cnt_env.task.scoring import RouteScore

    x = 20.0 + offset
    arm = np.array([[0.0, 0.0], [x, -30.0], [x, 30.0]])  # enters beyond the pad's end
    score = RouteScore(LINE * 4.0, 40.0, PAD_ALONG_Z, (), pad_width=pad_width)
    assert score.update(arm, len(arm))["pads_crossed"] == int(touched)


@pytest.mark.parametrize(
    ("end", "touched"),
    [
        ((20.0, 10.0), True),  # the electrode's corner line
        ((20.0, 10.01), False),  # just beyond its flat end, on its centre line
        ((21.9, 9.9), True),  # inside, beside the end
        ((22.1, 9.9), False),  # beyond the strip's edge (half-width 2)
        ((18.0, 11.0), False),  # past a corner: within 2 of the segment's end, outside
    ],
)  # fmt: skip
def test_a_strip_is_a_rectangle_with_flat_ends(end: tuple, touched: bool) -> None:
    """The strip of a pad 4 wide is the rectangle x in [18, 22], z in [-10, 10]: a trace
    ending at ``end`` (coming from beyond the pad's end, away from it) touches it exactly
    when ``end`` lies in that rectangle, boundary included."""
    from cnt_env.task.scoring import RouteScore

    tip = np.array([[0.0, 0.0], [40.0, 30.0], list(end)])
    score = RouteScore(LINE * 4.0, 40.0, PAD_ALONG_Z, (), pad_width=4.0)
    assert score.update(tip, len(tip))["pads_crossed"] == int(touched)


def test_a_crossing_meets_a_pad_of_any_width_and_width_zero_is_the_line() -> None:
    """A trace crossing the pad meets it at every width; with pad_width 0 the score is
    the crossing score bit for bit (a random zigzag with three pads)."""
    from cnt_env.task.scoring import RouteScore

    cross = np.array([[0.0, 0.0], [40.0, 0.0]])
    for w in (0.0, 0.5, 8.0):
        m = RouteScore(LINE * 4.0, 40.0, PAD_ALONG_Z, (), pad_width=w).update(cross, 2)
        assert m["pads_crossed"] == 1
    rng = np.random.default_rng(2)
    trace = _along(U, 0.7) + rng.normal(0.0, 6.0, _along(U, 0.7).shape)
    pads = np.array([[[20.0, -8.0], [20.0, 8.0]], [[52.0, 20.0], [68.0, 20.0]]])
    a = RouteScore(U, 6.0, pads, ()).update(trace, len(trace))
    b = RouteScore(U, 6.0, pads, (), pad_width=0.0).update(trace, len(trace))
    assert a == b


def test_a_wider_strip_never_loses_a_pad() -> None:
    """Monotone in the width: every pad touched at width p is touched at any p' > p."""
    from cnt_env.task.scoring import RouteScore

    rng = np.random.default_rng(3)
    pads = rng.uniform(-30.0, 90.0, (12, 2, 2))
    trace = np.cumsum(rng.normal(0.5, 3.0, (80, 2)), axis=0)
    counts = [RouteScore(U, 60.0, pads, (), pad_width=w).update(trace, len(trace))
              ["pads_crossed"] for w in (0.0, 1.0, 3.0, 10.0, 40.0)]  # fmt: skip
    assert counts == sorted(counts) and counts[0] < counts[-1] == len(pads)

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

"""benchmarks/detour_shorts.py: its command line."""

from __future__ import annotations

import numpy as np
import pytest

from benchmarks import detour_shorts  # the repo root is on pytest's pythonpath


@pytest.mark.parametrize(
    "argv",
    [
        ["--policies", "oracle"],
        ["--count", "0"],
        ["--first", "-1"],
        ["--config", "no/such/config.yml"],
        ["--agent", "no/such/agent.zip"],
    ],
)
def test_bad_arguments_exit_with_a_usage_error(argv: list[str]) -> None:
    with pytest.raises(SystemExit) as exc:
        detour_shorts.main([*argv])
    assert exc.value.code == 2


@pytest.mark.parametrize(
    ("second", "heading"),
    [((5.0, 1.0), "+x"), ((-5.0, 1.0), "-x"), ((1.0, 5.0), "+z"), ((1.0, -5.0), "-z")],
)
def test_first_heading_is_the_nearest_axis_of_the_first_leg(second, heading) -> None:
    assert (
        detour_shorts.first_heading(
            np.array([[2.0, 3.0], [2.0 + second[0], 3.0 + second[1]], [9.0, 9.0]])
        )
        == heading
    )


def test_summary_counts_shorts_and_splits_by_heading() -> None:
    row = {"policy": "agent", "shorts": 0, "first_short_step": None, "progress_at_short": None}
    rows = [
        {**row, "seed": 1, "heading": "-z", "score": 0.0, "shorts": 4, "first_short_step": 6,
         "progress_at_short": 0.183},
        {**row, "seed": 2, "heading": "-z", "score": 0.8},
        {**row, "seed": 3, "heading": "+x", "score": 0.9},
    ]  # fmt: skip
    lines = detour_shorts.summary(rows)
    assert lines[0] == "agent: mean 0.567 over 3 routes, 1 shorted [1]"
    assert lines[1] == "  first leg +x: mean 0.900 over 1; shorted (seed, step, progress): []"
    assert (
        lines[2]
        == "  first leg -z: mean 0.400 over 2; shorted (seed, step, progress): [(1, 6, 0.18)]"
    )
    assert len(lines) == 3


def test_summarize_prints_a_file_again(tmp_path, capsys) -> None:
    f = tmp_path / "rows.jsonl"
    f.write_text('{"policy": "follower", "seed": 7, "heading": "+z", "score": 0.5, "shorts": 0}\n')
    assert detour_shorts.main(["--summarize", str(f)]) == 0
    assert capsys.readouterr().out.startswith("follower: mean 0.500 over 1 routes, 0 shorted []")


def test_short_onset_is_where_the_final_run_of_shorts_began() -> None:
    onset = None
    for step, (shorts, progress) in enumerate(
        [(0, 0.1), (1, 0.2), (0, 0.3), (0, 0.4), (2, 0.5), (3, 0.6)], start=1
    ):
        onset = detour_shorts.short_onset(onset, step, {"shorts": shorts, "progress": progress})
        if step == 2:  # the first touch
            assert onset == (2, 0.2)
        if step == 3:  # the tail lifted off again: no short so far
            assert onset is None
    assert onset == (5, 0.5)


def test_a_short_is_trace_in_a_keepout_by_length_and_by_nodes_in_older_records() -> None:
    """A thin keep-out stepped over by the nodes (no node inside) is a short by length; a
    record made before short_length existed is judged by its nodes."""
    assert detour_shorts.shorted({"shorts": 0, "short_length": 0.42})
    assert not detour_shorts.shorted({"shorts": 0, "short_length": 0.0})
    assert detour_shorts.shorted({"shorts": 3})
    assert not detour_shorts.shorted({"shorts": 0})
    onset = detour_shorts.short_onset(None, 4, {"shorts": 0, "short_length": 0.3,
                                                "progress": 0.5})  # fmt: skip
    assert onset == (4, 0.5)

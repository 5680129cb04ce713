"""benchmarks/chaos.py: the perturbations it plays, and the oracle records it replays."""

from __future__ import annotations

import json
import math
from pathlib import Path

import numpy as np
import pytest

from benchmarks import chaos  # the repo root is on pytest's pythonpath
from cnt_env.task.spaces import action_from_flow, flow_from_action
from policies.opening import turned

VBAR_MAX = 0.13


def test_perturbations_alternate_in_sign_and_grow() -> None:
    turns = [chaos.perturbation(k, 1e-4) for k in range(7)]
    assert turns == pytest.approx([0.0, 1e-4, -1e-4, 2e-4, -2e-4, 3e-4, -3e-4], abs=1e-18)


@pytest.mark.parametrize("phi", [0.0, 0.3, math.pi / 4, math.pi / 2, -2.5, 3.0])
@pytest.mark.parametrize("speed", [1.0, 0.5])
def test_a_turned_action_turns_the_flow_by_the_angle_and_keeps_its_speed(phi, speed) -> None:
    """The action is float32: the flow turns by the angle to 0.1% of it (at 1e-4 rad,
    near the rim's corners too), its speed kept to 1e-8."""
    a = action_from_flow(speed * VBAR_MAX, phi, VBAR_MAX)
    v0, p0 = flow_from_action(a, VBAR_MAX)
    for eps in (1e-4, -1e-4, 3e-4):
        b = turned(a, eps, VBAR_MAX)
        assert b.dtype == np.float32
        v1, p1 = flow_from_action(b, VBAR_MAX)
        dphi = (p1 - p0 + math.pi) % (2 * math.pi) - math.pi
        assert dphi == pytest.approx(eps, rel=1e-3)
        assert v1 == pytest.approx(v0, abs=1e-8)
    assert np.array_equal(turned(a, 0.0, VBAR_MAX), a)


def _rows(tmp_path: Path, rows: list[dict]) -> Path:
    path = tmp_path / "oracle.jsonl"
    path.write_text("".join(json.dumps(r) + "\n" for r in rows))
    return path


def test_only_full_oracle_rows_with_choices_are_replayed(tmp_path: Path) -> None:
    path = _rows(tmp_path, [
        {"mode": "oracle", "target": "u_turn", "seed": 0, "choices": [0, 2], "horizon": None},
        {"mode": "oracle", "target": "u_turn", "seed": 1, "choices": [1], "horizon": 5},
        {"mode": "oracle", "target": "l_up", "seed": 0, "choices": []},
        {"mode": "follower", "target": "l_up", "seed": 1, "choices": [0]},
    ])  # fmt: skip
    assert chaos.oracle_choices([path]) == {("u_turn", 0): [0, 2]}


def test_jobs_cover_every_perturbation_and_carry_the_choices(tmp_path: Path) -> None:
    path = _rows(tmp_path, [{"mode": "oracle", "target": "u_turn", "seed": 0, "choices": [2, 0]}])
    _, jobs = chaos.parse_jobs(["--targets", "u_turn", "--modes", "follower,oracle",
                                "--perturbations", "2", "--oracle-rows", str(path)])  # fmt: skip
    assert [(j["mode"], j["k"]) for j in jobs] == [
        ("follower", 0), ("follower", 1), ("follower", 2),
        ("oracle", 0), ("oracle", 1), ("oracle", 2),
    ]  # fmt: skip
    assert all(j["choices"] == [2, 0] for j in jobs if j["mode"] == "oracle")
    assert "choices" not in jobs[0]


@pytest.mark.parametrize("argv", [
    ["--modes", "planner"],
    ["--eps", "0"],
    ["--eps", "nan"],
    ["--modes", "oracle"],  # no record of the oracle's choices
])  # fmt: skip
def test_bad_arguments_exit_with_a_usage_error(argv: list[str]) -> None:
    with pytest.raises(SystemExit) as exc:
        chaos.parse_jobs(["--targets", "u_turn", *argv])
    assert exc.value.code == 2


def test_summary_separates_the_unperturbed_episode() -> None:
    rows = [{"target": "u_turn", "seed": 0, "mode": "follower", "k": k, "score": s}
            for k, s in enumerate([0.9, 0.8, 1.0])]  # fmt: skip
    table = chaos.summary(rows)
    assert table[-1] == "| u_turn | 0 | follower | 0.900 | 0.900 ± 0.141 | 0.800 | 1.000 | 2 |"


def test_summarize_reads_the_episodes_already_written(tmp_path: Path, capsys) -> None:
    out = tmp_path / "chaos.jsonl"
    rows = [{"target": "l_up", "seed": 1, "mode": "agent", "k": k, "score": s}
            for k, s in enumerate([0.5, 0.6, 0.7])]  # fmt: skip
    out.write_text("".join(json.dumps(r) + "\n" for r in rows))
    assert chaos.main(["--summarize", "--out", str(out)]) == 0
    assert capsys.readouterr().out.splitlines() == chaos.summary(rows)
    assert chaos.main(["--summarize", "--out", str(tmp_path / "none.jsonl")]) == 2

"""benchmarks/rescore_success.py: saved episodes re-scored for the circuit's success."""

from __future__ import annotations

import csv
import json
from pathlib import Path

import numpy as np
import pytest

from benchmarks import rescore_success  # the repo root is on pytest's pythonpath
from cnt_env.task import routes
from cnt_env.task.scoring import route_score
from training.evaluate import _write_csv, aggregate

ROUTE = {"name": "beside", "waypoints": [[0.0, 0.0], [40.0, 0.0]], "width": 20.0,
         "pads": [], "keepouts": [{"rect": [10.0, 2.0, 12.0, 8.0]}]}  # fmt: skip
SHIFT = np.array([0.01, -0.02])  # the reset contact node's drift after reset


def _trace(z: float) -> np.ndarray:
    """Origin row, then a straight run past the end (x = 42) at height z."""
    x = np.arange(0.0, 43.0)
    return np.vstack([[0.0, 0.0], np.column_stack([x, np.full_like(x, z)])]) + SHIFT


def _results(path: Path, recorded_scores: dict[float, float] | None = None) -> Path:
    """A results dir as cnt-evaluate writes it: two completed episodes (the old flag
    True), one laid through the keep-out (z = 5) and one clear of it (z = 0)."""
    route = routes.resolve(ROUTE, np.random.default_rng(0))
    rows, arrays = [], {}
    for i, z in enumerate((0.0, 5.0)):
        tr = _trace(z)
        score = route_score(route)
        m = score.update(tr[1:] - SHIFT, len(tr) - 1)
        phi = float(np.sum(score.potentials(m)))
        if recorded_scores and z in recorded_scores:
            phi = recorded_scores[z]
        rows.append({"policy": "p", "target": "beside", "seed": i, "score": phi,
                     "coverage": 1.0, "precision": 1.0, "progress": 1.0,
                     "mean_distance": 0.0, "is_success": True, "failure": ""})  # fmt: skip
        arrays[f"trace_{i}"] = tr.astype(np.float32)
        arrays[f"target_{i}"] = (route.points + SHIFT).astype(np.float32)
    path.mkdir()
    (path / "summary.json").write_text(json.dumps(
        {"custom_routes": {"beside": route.to_dict()}, "env_kwargs": {}}))  # fmt: skip
    (path / "episodes.json").write_text(json.dumps(rows) + "\n")
    np.savez_compressed(path / "traces.npz", **arrays)
    _write_csv(path / "episodes.csv", rows)
    _write_csv(path / "results.csv", aggregate(rows, ["p"], ["beside"], [0, 1]))
    return path


def _column(path: Path, name: str) -> list[str]:
    with path.open(newline="") as fh:
        return [r[name] for r in csv.DictReader(fh)]


def test_a_shorted_completion_is_no_longer_a_success(tmp_path: Path, capsys) -> None:
    d = _results(tmp_path / "r")
    before = {f: (d / f).read_text() for f in ("episodes.csv", "results.csv")}
    assert _column(d / "results.csv", "success_rate") == ["1", "1"]
    assert rescore_success.main([str(d)]) == 0  # report only: nothing written
    assert "successes 2 -> 1" in capsys.readouterr().out
    assert (d / "results.csv").read_text() == before["results.csv"]
    assert rescore_success.main([str(d), "--write"]) == 0
    flags = [r["is_success"] for r in json.loads((d / "episodes.json").read_text())]
    assert flags == [True, False]
    assert _column(d / "episodes.csv", "is_success") == ["True", "False"]
    assert _column(d / "results.csv", "success_rate") == ["0.5", "0.5"]
    # only those columns changed
    for f in ("episodes.csv", "results.csv"):
        old = [line.split(",") for line in before[f].splitlines()]
        new = [line.split(",") for line in (d / f).read_text().splitlines()]
        changed = {j for a, b in zip(old, new, strict=True) for j, (x, y)
                   in enumerate(zip(a, b, strict=True)) if x != y}  # fmt: skip
        assert changed == {old[0].index("is_success" if f == "episodes.csv" else "success_rate")}
    assert rescore_success.main([str(d), "--write"]) == 0  # idempotent
    assert flags == [r["is_success"] for r in json.loads((d / "episodes.json").read_text())]


def test_a_score_the_trace_does_not_reproduce_leaves_the_files_alone(
    tmp_path: Path, capsys
) -> None:
    d = _results(tmp_path / "r", recorded_scores={5.0: 0.5})
    before = (d / "episodes.json").read_text()
    assert rescore_success.main([str(d), "--write"]) == 1
    out = capsys.readouterr().out
    assert "PROBLEM" in out and "0.500000 recorded" in out and "left alone" in out
    assert (d / "episodes.json").read_text() == before


def test_a_table_not_made_from_its_episodes_is_left_alone(tmp_path: Path, capsys) -> None:
    d = _results(tmp_path / "r")
    text = (d / "results.csv").read_text().replace(",1,", ",0.5,")
    (d / "results.csv").write_text(text, newline="")
    assert rescore_success.main([str(d), "--write"]) == 1
    assert "does not hold the rates" in capsys.readouterr().out
    assert json.loads((d / "episodes.json").read_text())[1]["is_success"] is True


def test_a_dir_without_traces_is_a_usage_error(tmp_path: Path) -> None:
    with pytest.raises(SystemExit) as exc:
        rescore_success.main([str(tmp_path)])
    assert exc.value.code == 2


def test_the_committed_tables_hold_todays_scores_and_success() -> None:
    """Every committed table with traces reproduces its scores from them and already
    holds the re-scored flags: a table made before a change of the score fails here."""
    dirs = rescore_success.result_dirs(rescore_success.DEFAULT_ROOTS)
    assert len(dirs) >= 13
    for d in dirs:
        rows, problems = rescore_success.rescore(d, 1e-3)
        assert not problems, problems
        old = json.loads((d / "episodes.json").read_text())
        assert [r["is_success"] for r in rows] == [r["is_success"] for r in old], d
        assert not rescore_success.recorded_rates_differ(d, old), d

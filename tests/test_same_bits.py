"""benchmarks/same_bits.py: two result directories compared episode by episode."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np

from benchmarks import same_bits

FIELDS = ["policy", "target", "seed", "score", "steps", "wall_s"]


def write(path: Path, rows: list[list], traces: list[np.ndarray]) -> Path:
    path.mkdir()
    rows_json = [dict(zip(FIELDS, r, strict=True)) for r in rows]
    (path / "episodes.json").write_text(json.dumps(rows_json))
    arrays = {f"trace_{i}": t for i, t in enumerate(traces)}
    arrays.update({f"target_{i}": np.zeros((2, 2)) for i in range(len(traces))})
    np.savez(path / "traces.npz", **arrays)
    return path


ROWS = [["scripted", "u_turn", 0, 0.939947, 50, 12.5], ["random", "u_turn", 0, 0.1, 9, 3.0]]
TRACES = [np.linspace(0.0, 1.0, 6).reshape(3, 2), np.ones((4, 2))]


def test_equal_directories_pass_whatever_the_wall_time_and_the_order(tmp_path) -> None:
    ref = write(tmp_path / "ref", ROWS, TRACES)
    new = write(tmp_path / "new", [[*ROWS[1][:5], 99.0], ROWS[0]], TRACES[::-1])
    assert same_bits.main([str(new), str(ref)]) == 0
    total, equal, lines = same_bits.differences(new, ref)
    assert total == equal == {"scripted": 1, "random": 1} and not lines


def test_a_column_a_last_bit_of_a_trace_or_a_missing_episode_fails(tmp_path, capsys) -> None:
    ref = write(tmp_path / "ref", ROWS, TRACES)
    last_bit = np.nextafter(ROWS[0][3], 1.0)  # lost in episodes.csv's 6 digits
    score = write(tmp_path / "score", [[*ROWS[0][:3], last_bit, 50, 12.5], ROWS[1]], TRACES)
    bit = TRACES[0].copy()
    bit[1, 1] = np.nextafter(bit[1, 1], 2.0)
    trace = write(tmp_path / "trace", ROWS, [bit, TRACES[1]])
    missing = write(tmp_path / "missing", [["ppo", "u_turn", 0, 0.9, 50, 1.0]], TRACES[:1])
    for new, what in [(score, "score"), (trace, "trace_ (traces.npz)"),
                      (missing, "not in")]:  # fmt: skip
        assert same_bits.main([str(new), str(ref)]) == 1
        out = capsys.readouterr().out
        assert what in out and "episodes differ" in out

"""benchmarks/width_or_shape.py: the routes it writes and its paired table."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np

from benchmarks import width_or_shape  # the repo root is on pytest's pythonpath

ROOT = Path(__file__).resolve().parents[1]


def test_the_hard_routes_are_those_of_the_difficulty_1_set() -> None:
    committed = json.loads((ROOT / "benchmarks/results/difficulty1_routes.json").read_text())[0]
    route = width_or_shape.drawn(1000, 1.0)
    assert route["waypoints"] == committed["waypoints"] and route["width"] == committed["width"]


def test_the_table_pairs_episodes_by_route_and_seed(tmp_path: Path) -> None:
    rows = []
    for target, follower, agent in (("a", 0.8, 0.9), ("b_detour", 0.9, 0.7)):
        for seed in (0, 1):
            rows += [{"policy": "scripted", "target": target, "seed": seed, "score": follower},
                     {"policy": "ppo_residual", "target": target, "seed": seed,
                      "score": agent + 0.01 * seed}]  # fmt: skip
    (tmp_path / "mid").mkdir()
    (tmp_path / "mid" / "episodes.json").write_text(json.dumps(rows))
    lines = width_or_shape.table(tmp_path)
    assert len(lines) == 3  # header, rule, the one set found
    assert lines[2].startswith("| mid | 2 x 2 | 0.850 | 0.805 | -0.045 ± ")
    assert lines[2].endswith("(1 / 1) | +0.105 ± 0.005 |")  # without b_detour


def test_each_detour_side_is_the_mirror_image_of_the_other() -> None:
    rows = json.loads((ROOT / "benchmarks/results/width_or_shape/detour_sides.json").read_text())
    by_name = {r["name"]: r for r in rows}
    mirrors = [n for n in by_name if n.endswith("_mz")]
    assert len(mirrors) == 3 and len(by_name) == 6
    for name in mirrors:
        a, b = by_name[name.removesuffix("_mz")], by_name[name]
        assert b["width"] == a["width"]
        for key in ("waypoints", "keepouts"):
            pa, pb = np.asarray(a[key], dtype=float), np.asarray(b[key], dtype=float)
            assert np.array_equal(pb[..., 0], pa[..., 0])
            assert np.array_equal(pb[..., 1], -pa[..., 1])

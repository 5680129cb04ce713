"""Width or shape: why the residual agent falls behind the follower on routes drawn at
difficulty 1.0 (benchmarks/RESULTS.md, issue 10, "Routes drawn at the hardest
difficulty"). Difficulty 1 makes the corridor narrower (half-width 15-20 L_vb against the
training draws' 18.5-25) and the routes longer with more turns; this separates the two.

Writes three route files, drawn by the env of ``training/configs/eval.yml`` (the model)
at reset seeds 1000-1011, the seeds of ``difficulty1_routes.json``:

- ``hard_wide.json``: the difficulty-1 routes (the same shapes) widened to the held-out routes'
  half-width, ``routes.DEFAULT_HALF_WIDTH`` (the band's own, wider, is kept);
- ``mid.json``: the routes drawn at the training difficulty, 0.5, at their own width;
- ``mid_narrow.json``: the same routes with the half-width of the difficulty-1 route of
  the same seed;
- ``detour_sides.json``: which side of the keep-out a detour goes round. The held-out
  ``detour_block`` (round its +z side) and ``mid``'s two detours (round their -z side),
  each with its mirror image in z (``_mz``: the other side).

Then, for each file::

    cnt-evaluate --route-file DIR/FILE --policies scripted,ppo_residual --seeds 0,1,2 \\
        --out DIR/FILE_STEM --jobs 2

(``python benchmarks/width_or_shape.py --out DIR --write-routes`` writes the files;
without ``--write-routes`` it prints the paired table of the runs found in ``DIR``.)
"""

from __future__ import annotations

import argparse
import json
import math
import statistics
import sys
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))
SEEDS = range(1000, 1012)
SETS = ("hard_wide", "mid", "mid_narrow", "detour_sides")
OUT = ROOT / "benchmarks/results/width_or_shape"


def drawn(seed: int, difficulty: float) -> dict:
    """The route dict the model's env draws at reset ``seed`` and ``difficulty``."""
    from training.common import EVAL_CONFIG, env_settings, load_config, make_env

    env = make_env(*env_settings(load_config(EVAL_CONFIG)), difficulty=difficulty)
    _, info = env.reset(seed=seed)
    route = env.unwrapped.target.to_dict()
    env.close()
    return {**route, "name": f"s{seed}_{info['target']}"}


def mirrored(route: dict) -> dict:
    """``route`` (a route dict) mirrored in z, named with ``_mz``: round the other side."""

    def flip(points: list) -> list:
        return (np.asarray(points, dtype=float).reshape(-1, 2) * [1.0, -1.0]).tolist()

    return {**route, "name": route["name"] + "_mz", "waypoints": flip(route["waypoints"]),
            "pads": [flip(p) for p in route["pads"]],
            "keepouts": [flip(k) for k in route["keepouts"]]}  # fmt: skip


def write_routes(out: Path) -> None:
    from cnt_env.task.routes import DEFAULT_HALF_WIDTH, held_out

    out.mkdir(parents=True, exist_ok=True)
    hard = [drawn(s, 1.0) for s in SEEDS]
    mid = [drawn(s, 0.5) for s in SEEDS]
    files = {
        "hard_wide": [{**r, "width": max(r["width"], DEFAULT_HALF_WIDTH)} for r in hard],
        "mid": mid,
        "mid_narrow": [{**m, "width": h["width"]} for m, h in zip(mid, hard, strict=True)],
    }
    block = {**held_out("detour_block").to_dict(), "name": "held_out_detour_block"}  # a new name
    detours = [block] + [r for r in mid if "detour" in r["name"]]
    files["detour_sides"] = [d for r in detours for d in (r, mirrored(r))]
    for name, rows in files.items():
        (out / f"{name}.json").write_text(json.dumps(rows, indent=1) + "\n")
        print(f"{out / name}.json: " + ", ".join(f"{r['name']} w={r['width']:.1f}" for r in rows))


def _mean_se(values: list[float]) -> str:
    """Mean ± its standard error ("-" for no value)."""
    if not values:
        return "-"
    se = statistics.stdev(values) / len(values) ** 0.5 if len(values) > 1 else math.nan
    return f"{statistics.fmean(values):+.3f} ± {se:.3f}"


def table(out: Path) -> list[str]:
    """Per set: the follower's and the agent's mean score and their paired difference, over
    every route and over the routes without a keep-out (the detours)."""
    lines = ["| set | routes x seeds | follower | residual PPO | agent - follower (per route: "
             "ahead / behind) | the same without the detours |",
             "|---|---|---|---|---|---|"]  # fmt: skip
    for name in SETS:
        path = out / name / "episodes.json"
        if not path.is_file():
            continue
        score: dict[tuple[str, str, int], float] = {}
        for r in json.loads(path.read_text()):
            score[r["policy"], r["target"], int(r["seed"])] = float(r["score"])
        keys = sorted({(t, s) for p, t, s in score if p == "scripted"})
        diffs = [score["ppo_residual", t, s] - score["scripted", t, s] for t, s in keys]
        per_route: dict[str, list[float]] = {}
        for (t, _), d in zip(keys, diffs, strict=True):
            per_route.setdefault(t, []).append(d)
        ahead = sum(statistics.fmean(v) > 0 for v in per_route.values())
        behind = sum(statistics.fmean(v) < 0 for v in per_route.values())
        open_diffs = [d for (t, _), d in zip(keys, diffs, strict=True) if "detour" not in t]
        lines.append(
            f"| {name} | {len(per_route)} x {len(keys) // len(per_route)} | "
            f"{statistics.fmean(score['scripted', t, s] for t, s in keys):.3f} | "
            f"{statistics.fmean(score['ppo_residual', t, s] for t, s in keys):.3f} | "
            f"{_mean_se(diffs)} ({ahead} / {behind}) | {_mean_se(open_diffs)} |"
        )
    return lines


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--out", type=Path, default=OUT)
    ap.add_argument("--write-routes", action="store_true", help="write the route files only")
    args = ap.parse_args(argv)
    if args.write_routes:
        write_routes(args.out)
    else:
        print("\n".join(table(args.out)))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())

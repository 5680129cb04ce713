"""Breadth: the follower and the shipped agent on circuit routes outside every set.

The held-out routes (``cnt_env.task.routes.HELD_OUT``) were fixed before any agent was
trained, and the training families draw from the same shapes. This runs the route
follower and the shipped residual agent, on the model (``training/configs/eval.yml``,
cnt-evaluate's default), on seven routes of other shapes that a circuit could ask for: a
first leg down the steps (-z), a two-turn meander, a square ring back to its start, a
diagonal against the flow, two keep-outs on alternate sides of a straight run, pads
across a run along x, and a narrow corridor along the steps. Each is designed at
w = 15 and scaled with the band like the held-out set (``routes.scale_design``). It reports each
episode's score, progress and failure, so that a route family the task or the policies
mishandle shows up.

    python benchmarks/route_breadth.py --seeds 0,1 --jobs 2 \
        --out benchmarks/results/route_breadth.json

``--write-routes FILE`` writes the seven routes as a route file (nothing is run), so that
``cnt-evaluate --route-file FILE`` scores every baseline on them, the constant-flow
oracle and random included; ``benchmarks/results/breadth_routes.json`` is that file
(a test keeps it equal to :func:`routes`).
"""

from __future__ import annotations

import argparse
import json
import multiprocessing as mp
import sys
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))
from cnt_env.cli.common import seed_list  # noqa: E402


def routes() -> dict[str, dict]:
    """The seven routes (dict format of ``reset(options={"target": ...})``)."""
    from cnt_env.task.routes import scale_design

    base = {
        "down_first": {"waypoints": [[0, 0], [0, -50], [60, -50], [60, -100]]},
        "meander2": {"waypoints": [[0, 0], [40, 0], [40, 40], [80, 40], [80, 0], [120, 0]]},
        "square_ring": {"waypoints": [[0, 0], [60, 0], [60, 60], [0, 60], [0, 15]]},
        "back_diagonal": {"waypoints": [[0, 0], [-60, -60]]},
        "slalom_keepouts": {
            "waypoints": [[0, 0], [150, 0]],
            "keepouts": [{"rect": [40, 16, 60, 40]}, {"rect": [90, -40, 110, -16]}],
        },
        "pads_across_x": {
            "waypoints": [[0, 0], [100, 0]],
            "width": 12.0,
            "pads": [[[40, -10], [40, 10]], [[80, -10], [80, 10]]],
        },
        "narrow_along_steps": {"waypoints": [[0, 0], [0, 80]], "width": 8.0},
    }
    return {name: {"name": name, **scale_design({"width": 15.0, **spec})}
            for name, spec in base.items()}  # fmt: skip


def main(argv: list[str] | None = None) -> int:
    from training.common import EVAL_CONFIG, env_settings, load_config
    from training.evaluate import run_episode

    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--seeds", type=seed_list, default="0,1", help="comma separated episode seeds")
    ap.add_argument("--jobs", type=int, default=2)
    ap.add_argument("--config", type=Path, default=EVAL_CONFIG)
    ap.add_argument("--model", type=Path, default=ROOT / "policies/pretrained/ppo_residual.zip")
    ap.add_argument("--out", type=Path, default=None, help="write the rows here (JSON)")
    ap.add_argument("--write-routes", type=Path, default=None,
                    help="write the routes as a cnt-evaluate --route-file and stop")  # fmt: skip
    args = ap.parse_args(argv)
    if args.write_routes is not None:
        lines = ",\n".join(f" {json.dumps(r)}" for r in routes().values())
        args.write_routes.write_text(f"[\n{lines}\n]\n")  # a route per line
        return 0
    env_kwargs, max_steps = env_settings(load_config(args.config))
    policies = {"scripted": {"kind": "scripted"},
                "ppo_residual": {"kind": "ppo_residual", "models": [str(args.model)]}}  # fmt: skip
    seeds = args.seeds
    jobs = [{"policy": p, "spec": spec, "target": r, "seed": s, "env_kwargs": env_kwargs,
             "max_steps": max_steps, "save_dir": None}
            for r in routes().values() for p, spec in policies.items() for s in seeds]  # fmt: skip
    t0 = time.perf_counter()
    with mp.get_context("forkserver").Pool(args.jobs) as pool:
        results = pool.map(run_episode, jobs, chunksize=1)
    rows = []
    for job, res in zip(jobs, results, strict=True):
        row = {"route": job["target"]["name"], **res["row"]}
        row.pop("target")
        rows.append(row)
        print(f"{row['route']:19s} {row['policy']:13s} seed {row['seed']}  score "
              f"{row['score']:.3f}  progress {row['progress']:.2f}  steps {row['steps']:3d}  "
              f"failure {row['failure'] or '-'}")  # fmt: skip
    wall = time.perf_counter() - t0
    print(f"{len(rows)} episodes in {wall:.0f} s")
    for p in policies:
        mine = [r["score"] for r in rows if r["policy"] == p]
        print(f"{p}: mean {sum(mine) / len(mine):.3f}")
    if args.out is not None:
        args.out.write_text(json.dumps({"command": sys.argv, "wall_s": round(wall, 1),
                                        "routes": routes(), "rows": rows}, indent=1))  # fmt: skip
    return 0


if __name__ == "__main__":
    raise SystemExit(main())

"""How much of the first swing's loss any flow schedule can avoid: an exhaustive search
over the episode's first control steps (issue 10).

``benchmarks/outside_where.py`` found that a third of the route follower's trace outside
the corridor, and half of the shipped agent's, is laid in the first 60 L_vb, the swing
under way in the warm state. Is that loss committed before any flow can act (the rod's
lag), or is there a start that avoids it? For each route and seed, every combination of
``--directions`` flow directions at v̄_max over the first ``--steps`` control steps is
played on a copy of the env (deterministic: the copies continue bit for bit), followed
by the route follower until ``--until`` L_vb of trace is laid; the trace outside the
corridor in the first ``--first`` L_vb and after it is recorded, with the follower's own
start (no forced step) as the reference. It reads the simulator through the copies, so
it is a bound on what a start can reach, not a policy.

    python benchmarks/start_search.py --targets u_turn,l_up --seeds 0,1,2 --jobs 2 \
        --out benchmarks/results/start_search.jsonl

writes one JSON line per (route, seed) and prints the table.
"""

from __future__ import annotations

import argparse
import copy
import itertools
import json
import sys
import time
from concurrent.futures import ProcessPoolExecutor
from pathlib import Path
from typing import Any

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))
from cnt_env.cli.common import name_list, seed_list  # noqa: E402
from cnt_env.jsonl import append_row  # noqa: E402


def _outside(env: Any, first: float) -> tuple[float, float, float]:
    """``(outside in the first L_vb, outside after, laid)`` of the episode's trace so far."""
    from benchmarks.outside_where import outside_lengths
    from training.evaluate import episode_frame

    xz, target = episode_frame(env.unwrapped)
    return outside_lengths(xz, target, float(env.unwrapped.target.width), first)


def _continue(env: Any, follower: Any, obs: Any, forced: tuple[np.ndarray, ...],
              until: float, first: float) -> dict[str, float]:  # fmt: skip
    """Play the ``forced`` actions, then the follower, until ``until`` L_vb are laid or
    the episode ends."""
    steps = 0
    info: dict[str, Any] = {}
    while True:
        a = follower.act(obs)  # the follower's memory advances once per step
        if steps < len(forced):
            a = forced[steps]
        obs, _, term, trunc, info = env.step(a)
        steps += 1
        early, late, laid = _outside(env, first)
        if term or trunc or laid >= until:
            break
    return {"outside_first": early, "outside_after": late, "laid": laid, "steps": steps,
            "progress": float(info.get("progress", np.nan))}  # fmt: skip


def search(job: dict[str, Any]) -> dict[str, Any]:
    from cnt_env.task.spaces import action_from_flow
    from policies import RouteFollower
    from training.common import env_settings, load_config, make_env

    env_kwargs, max_steps = env_settings(load_config(job["config"]))
    env = make_env(env_kwargs, max_steps)
    # the follower's own first flow is the reference: the start flow (start_swing) is the
    # rule this search led to, and later steps do not depend on it
    follower = RouteFollower.from_env(env, start_swing=False)
    obs, _ = env.reset(seed=job["seed"], options={"target": job["target"]})
    follower.reset(job["seed"])
    vmax = env.unwrapped.vbar_max
    t0 = time.perf_counter()
    snapshot = copy.deepcopy((env, follower))
    env.close()

    def rollout(forced: tuple[np.ndarray, ...]) -> dict[str, Any]:
        e, f = copy.deepcopy(snapshot)
        try:
            return _continue(e, f, obs, forced, job["until"], job["first"])
        finally:
            e.close()

    reference = rollout(())
    phis = 2 * np.pi * np.arange(job["directions"]) / job["directions"]
    flows = [action_from_flow(vmax, float(p), vmax) for p in phis]
    tried = []
    for combo in itertools.product(range(len(phis)), repeat=job["steps"]):
        r = rollout(tuple(flows[i] for i in combo))
        r["phi"] = [round(float(phis[i]), 3) for i in combo]
        tried.append(r)
    snapshot[0].close()
    return {
        "target": job["target"], "seed": job["seed"], "steps_searched": job["steps"],
        "directions": job["directions"], "first": job["first"], "until": job["until"],
        "follower": reference,
        "best": min(tried, key=lambda r: r["outside_first"] + r["outside_after"]),
        "best_first": min(tried, key=lambda r: r["outside_first"]),
        "combos": len(tried), "wall_s": round(time.perf_counter() - t0, 1),
        "tried": [[r["phi"], round(r["outside_first"], 2), round(r["outside_after"], 2)]
                  for r in tried],
    }  # fmt: skip


def main(argv: list[str] | None = None) -> int:
    from cnt_env.task.routes import HELD_OUT
    from training.common import EVAL_CONFIG

    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument(
        "--targets", type=name_list, default=",".join(t for t in HELD_OUT if t != "detour_block")
    )
    ap.add_argument("--seeds", type=seed_list, default="0,1,2")
    ap.add_argument("--steps", type=int, default=2, help="control steps searched")
    ap.add_argument("--directions", type=int, default=8, help="flow directions per step")
    ap.add_argument("--first", type=float, default=60.0, help="L_vb: the start's share")
    ap.add_argument("--until", type=float, default=150.0, help="L_vb laid per rollout")
    ap.add_argument("--config", type=Path, default=EVAL_CONFIG)
    ap.add_argument("--jobs", type=int, default=2)
    ap.add_argument("--out", type=Path, default=None)
    args = ap.parse_args(argv)
    common = {"steps": args.steps, "directions": args.directions, "first": args.first,
              "until": args.until, "config": str(args.config)}  # fmt: skip
    jobs = [{"target": t, "seed": s, **common} for s in args.seeds for t in args.targets]
    rows = []
    with ProcessPoolExecutor(max_workers=args.jobs) as pool:
        for row in pool.map(search, jobs):
            rows.append(row)
            if args.out:
                append_row(args.out, row, echo=True)
            else:
                print(json.dumps(row), flush=True)
    print(f"| target | seed | follower: first {args.first:g} / after | best start: first / "
          "after (flows) |\n|---|---|---|---|")  # fmt: skip
    for r in rows:
        f, b = r["follower"], r["best"]
        print(f"| {r['target']} | {r['seed']} | {f['outside_first']:.1f} / "
              f"{f['outside_after']:.1f} | {b['outside_first']:.1f} / "
              f"{b['outside_after']:.1f} ({b['phi']}) |")  # fmt: skip
    for key in ("follower", "best"):
        a = np.array([[r[key]["outside_first"], r[key]["outside_after"]] for r in rows])
        print(f"mean {key}: first {a[:, 0].mean():.2f}, after {a[:, 1].mean():.2f} L_vb")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())

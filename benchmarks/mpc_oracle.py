"""A planning oracle for the route task: what a flow schedule can score at the env's
control interval when it may try actions on copies of the simulator (issue 10).

The rollout algorithm (Bertsekas) with the route follower as the base policy. At every
control step, K candidate actions are tried, each on a deep copy of the env and of the
follower (the copies are bit-identical continuations: the env is deterministic): the
candidate for one step, then the follower to the episode's end; the candidate whose copy
ends with the highest final score is played on the real env. The candidates are the
follower's own action and its flow turned by each ``--turns`` angle and slowed to each
``--speeds`` fraction. The follower's own action wins ties, and its rollout's score is
carried from the step before (the continuation of the chosen candidate's rollout), so
the oracle's final score is never below the follower's (the rollout algorithm's
improvement property, exact here because the env is deterministic).

This is not a deployable policy (it reads the simulator's state through the copies);
it measures what flow schedules at the env's control interval reach around the
follower, so that the RL goal "follower + half its gap" can be judged against the
physics. It costs (K - 1) x the remaining steps per control step (~N^2 (K - 1) / 2 env
steps per episode of N).

    python benchmarks/mpc_oracle.py --seeds 0 --jobs 2

writes one JSON line per episode (oracle and follower on the same seed) to
``benchmarks/results/mpc_oracle.jsonl`` and prints the table.
"""

from __future__ import annotations

import argparse
import copy
import json
import sys
import time
from concurrent.futures import ProcessPoolExecutor
from pathlib import Path
from typing import Any

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))
OUT = ROOT / "benchmarks/results/mpc_oracle.jsonl"


def candidates(action: Any, vbar_max: float, turns: list[float], speeds: list[float]) -> list:
    """The follower's action first, then its flow turned by each angle (radians) and
    slowed to each fraction of its speed."""
    import numpy as np

    from cnt_env.task.spaces import action_from_flow, flow_from_action

    vbar, phi = flow_from_action(np.asarray(action, dtype=float), vbar_max)
    out = [np.asarray(action, dtype=np.float32)]
    out += [action_from_flow(vbar, phi + t, vbar_max) for t in turns]
    out += [action_from_flow(s * vbar, phi, vbar_max) for s in speeds]
    return out


def _finish(env: Any, follower: Any, obs: Any, term: bool, trunc: bool, info: dict) -> float:
    """Play the follower from here to the episode's end; the final score."""
    while not (term or trunc):
        obs, _, term, trunc, info = env.step(follower.act(obs))
    return float(info["score"])


def episode(job: dict[str, Any]) -> dict[str, Any]:
    """One episode of the oracle (``job["mode"] == "oracle"``) or of the follower alone."""
    from policies import RouteFollower
    from training.common import env_settings, load_config, make_env

    env_kwargs, max_steps = env_settings(load_config(ROOT / "training/configs/ppo.yml"))
    env = make_env(env_kwargs, max_steps)
    follower = RouteFollower.from_env(env)
    obs, info = env.reset(seed=job["seed"], options={"target": job["target"]})
    follower.reset(job["seed"])
    vbar_max = env.unwrapped.vbar_max
    t0 = time.perf_counter()
    steps = deviations = rollouts = 0
    base = None  # final score of following the follower from the current state
    while True:
        a = follower.act(obs)
        if job["mode"] == "oracle":
            cands = candidates(a, vbar_max, job["turns"], job["speeds"])
            if base is None:
                base = _finish(*copy.deepcopy((env, follower)), obs, False, False, info)
                rollouts += 1
            chosen = 0
            for k, cand in enumerate(cands[1:], start=1):
                e, f = copy.deepcopy((env, follower))
                o, _, term, trunc, inf = e.step(cand)
                score = _finish(e, f, o, term, trunc, inf)
                rollouts += 1
                e.close()
                if score > base + 1e-12:  # the follower's own action wins ties
                    base, chosen = score, k
            deviations += chosen > 0
            a = cands[chosen]
        obs, _, term, trunc, info = env.step(a)
        steps += 1
        if term or trunc:
            break
    env.close()
    return {
        "mode": job["mode"], "target": job["target"], "seed": job["seed"],
        "score": float(info["score"]), "shorts": int(info["shorts"]),
        "completed": bool(info["completed"]), "steps": steps, "deviations": deviations,
        "rollouts": rollouts, "turns": job["turns"], "speeds": job["speeds"],
        "wall_s": round(time.perf_counter() - t0, 1),
    }  # fmt: skip


def main(argv: list[str] | None = None) -> int:
    from cnt_env.task.routes import HELD_OUT

    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--targets", default=",".join(HELD_OUT))
    ap.add_argument("--seeds", default="0")
    ap.add_argument("--turns", default="-0.4,0.4", help="radians")
    ap.add_argument("--speeds", default="0.5", help="fractions of the follower's speed")
    ap.add_argument("--jobs", type=int, default=2)
    ap.add_argument("--out", type=Path, default=OUT)
    args = ap.parse_args(argv)

    def floats(text: str) -> list[float]:
        return [float(x) for x in text.split(",") if x.strip()]

    common = {"turns": floats(args.turns), "speeds": floats(args.speeds)}
    jobs = [
        {"mode": mode, "target": t, "seed": int(s), **common}
        for s in args.seeds.split(",")
        for t in args.targets.split(",")
        for mode in ("oracle", "follower")
    ]
    rows = []
    with ProcessPoolExecutor(max_workers=args.jobs) as pool:
        for row in pool.map(episode, jobs):
            rows.append(row)
            with args.out.open("a") as fh:
                fh.write(json.dumps(row) + "\n")
            print(json.dumps(row), flush=True)
    print("| target | seed | follower | oracle | deviations / steps |")
    print("|---|---|---|---|---|")
    pairs = {}
    for r in rows:
        pairs.setdefault((r["target"], r["seed"]), {})[r["mode"]] = r
    for (t, s), p in pairs.items():
        o, f = p["oracle"], p["follower"]
        print(f"| {t} | {s} | {f['score']:.3f} | {o['score']:.3f} | "
              f"{o['deviations']} / {o['steps']} |")  # fmt: skip
    mean = {m: sum(r["score"] for r in rows if r["mode"] == m) / (len(rows) / 2)
            for m in ("follower", "oracle")}  # fmt: skip
    print(f"mean: follower {mean['follower']:.3f}, oracle {mean['oracle']:.3f}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())

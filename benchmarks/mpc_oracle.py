"""A planning oracle for the route task: what a flow schedule can score at the env's
control interval when it may try actions on copies of the simulator (issue 10).

The rollout algorithm with the route follower as the base policy
(``training/oracle.py``, where it is described): at every control step the follower's
action and K - 1 variants are each tried on a copy of the env, followed by the follower to
the episode's end, and the best is played; its score is never below the follower's. It is
not a deployable policy (it reads the simulator through the copies); it measures what
flow schedules at the env's control interval reach around the follower, so that the RL
goal "follower + half its gap" can be judged against the physics.

    python benchmarks/mpc_oracle.py --seeds 0 --jobs 2

writes one JSON line per episode (oracle and follower on the same seed) to
``benchmarks/results/mpc_oracle.jsonl`` and prints the table.
"""

from __future__ import annotations

import argparse
import sys
import time
from concurrent.futures import ProcessPoolExecutor
from pathlib import Path
from typing import Any

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))
from cnt_env.cli.common import float_list, name_list, nonnegative_int, seed_list  # noqa: E402
from cnt_env.jsonl import append_row  # noqa: E402

OUT = ROOT / "benchmarks/results/mpc_oracle.jsonl"


def episode(job: dict[str, Any]) -> dict[str, Any]:
    """One episode of the oracle (``job["mode"] == "oracle"``) or of the follower alone."""
    from policies import RouteFollower
    from training.common import env_settings, load_config, make_env, shown_path
    from training.oracle import RolloutOracle

    env_kwargs, max_steps = env_settings(load_config(Path(job["config"])))
    env = make_env(env_kwargs, max_steps)
    follower = RouteFollower.from_env(env)
    obs, info = env.reset(seed=job["seed"], options={"target": job["target"]})
    follower.reset(job["seed"])
    oracle = RolloutOracle(env, follower, tuple(job["turns"]), tuple(job["speeds"]),
                           horizon=job.get("horizon"),
                           confirm=bool(job.get("confirm", False)))  # fmt: skip
    t0 = time.perf_counter()
    steps = 0
    while True:
        if job["mode"] == "oracle":
            cands, _, k = oracle.choose(obs, info)
            a = cands[k]
        else:
            a = follower.act(obs)
        obs, _, term, trunc, info = env.step(a)
        steps += 1
        if term or trunc:
            break
    env.close()
    return {
        "mode": job["mode"], "target": job["target"], "seed": job["seed"],
        "score": float(info["score"]), "shorts": int(info["shorts"]),
        "completed": bool(info["completed"]), "steps": steps,
        "deviations": sum(k > 0 for k in oracle.history), "rollouts": oracle.rollouts,
        # the candidate played at each control step (0: the follower's own action, then
        # the turns, then the speeds: training.oracle.candidates)
        "choices": list(oracle.history),
        "turns": job["turns"], "speeds": job["speeds"], "horizon": job.get("horizon"),
        "confirm": oracle.confirm,
        "config": shown_path(job["config"], ROOT),
        "wall_s": round(time.perf_counter() - t0, 1),
    }  # fmt: skip


def parse_jobs(argv: list[str] | None = None) -> tuple[argparse.Namespace, list[dict[str, Any]]]:
    """The command line and the episodes it asks for: per seed and route, the oracle's
    and the follower's."""
    from cnt_env.task.routes import HELD_OUT
    from training.common import EVAL_CONFIG

    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--targets", type=name_list, default=",".join(HELD_OUT))
    ap.add_argument("--seeds", type=seed_list, default="0")
    ap.add_argument("--turns", type=float_list, default="-0.4,0.4", help="radians")
    ap.add_argument(
        "--speeds", type=float_list, default="0.5", help="fractions of the follower's speed"
    )
    # the env the held-out scores (and so the goal's margin) are measured on. Until
    # 2026-12-02 the oracle read training/configs/ppo.yml, which pins the fast surrogate
    # since 2026-11-26: the rows of mpc_oracle.jsonl were made before that, on the env's
    # default of then (the printed law at delta_bar 1, today's surrogate).
    ap.add_argument(
        "--config", type=Path, default=EVAL_CONFIG,
        help="YAML whose env_kwargs set the env (default: the held-out evaluation's, the model)",
    )  # fmt: skip
    ap.add_argument(
        "--horizon", type=nonnegative_int, default=None,
        help="follower steps after each candidate, compared by the score reached there "
        "(default: to the episode's end, the rollout algorithm)",
    )  # fmt: skip
    ap.add_argument(
        "--confirm", action="store_true",
        help="with --horizon: play a screened departure only if its full rollout wins "
        "(training.oracle.RolloutOracle.confirm)",
    )  # fmt: skip
    ap.add_argument(
        "--modes", type=name_list, default="oracle,follower",
        help="episodes to play per route and seed: oracle, follower (the base alone)",
    )  # fmt: skip
    ap.add_argument("--jobs", type=int, default=2)
    ap.add_argument("--out", type=Path, default=OUT)
    args = ap.parse_args(argv)
    if args.confirm and args.horizon is None:
        ap.error("--confirm needs --horizon (without one every rollout is full)")
    bad = sorted(set(args.modes) - {"oracle", "follower"})
    if bad or not args.modes:
        ap.error(f"--modes takes oracle and/or follower, got {','.join(args.modes)!r}")

    common = {"turns": args.turns, "speeds": args.speeds, "config": str(args.config),
              "horizon": args.horizon, "confirm": args.confirm}  # fmt: skip
    jobs = [
        {"mode": mode, "target": t, "seed": s, **common}
        for s in args.seeds
        for t in args.targets
        for mode in args.modes
    ]
    return args, jobs


def main(argv: list[str] | None = None) -> int:
    args, jobs = parse_jobs(argv)
    rows = []
    with ProcessPoolExecutor(max_workers=args.jobs) as pool:
        for row in pool.map(episode, jobs):
            rows.append(row)
            append_row(args.out, row, echo=True)
    print("| target | seed | follower | oracle | deviations / steps |")
    print("|---|---|---|---|---|")
    pairs: dict[tuple[str, int], dict[str, dict[str, Any]]] = {}
    for r in rows:
        pairs.setdefault((r["target"], r["seed"]), {})[r["mode"]] = r
    for (t, s), p in pairs.items():
        o, f = p.get("oracle"), p.get("follower")
        fs = f"{f['score']:.3f}" if f else "-"
        os_ = f"{o['score']:.3f} | {o['deviations']} / {o['steps']}" if o else "- | -"
        print(f"| {t} | {s} | {fs} | {os_} |")
    for m in ("follower", "oracle"):
        scores = [r["score"] for r in rows if r["mode"] == m]
        if scores:
            print(f"mean {m}: {sum(scores) / len(scores):.3f} over {len(scores)} episodes")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())

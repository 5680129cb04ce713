"""The shipped residual agent and the follower on drawn detours, on the model (issue 10).

The held-out set has one route with a keep-out (``detour_block``, first leg along +z).
This plays the routes the env draws for ``--count`` reset seeds from ``--first`` (its
default families at its default difficulty, as ``training/opening.py`` drew them) and
keeps those of ``--family``: per route, the follower, the agent, and the agent with its
residual dropped (its base's action played) while the nearest keep-out point is within
``--shield`` L_vb of the contact point (a probe of a safety shield; 0: none).

    python benchmarks/detour_shorts.py --first 1000 --count 124 --shield 30
    python benchmarks/detour_shorts.py --first 1000 --count 124 --policies follower,agent \
        --config policies/pretrained/ppo_residual.yml \
        --out benchmarks/results/detour_shorts_surrogate.jsonl

writes one JSON line per episode to ``--out`` (default
``benchmarks/results/detour_shorts.jsonl``) and prints the mean score and the routes
shorted (a trace node in a keep-out) per policy. ``--config``: the env of a config's
``env_kwargs`` (default ``training/configs/eval.yml``, the model); the second command plays
the detours of the surrogate the agent was trained on.
"""

from __future__ import annotations

import argparse
import json
import math
import statistics
import sys
from concurrent.futures import ProcessPoolExecutor
from pathlib import Path
from typing import Any

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))
OUT = ROOT / "benchmarks/results/detour_shorts.jsonl"
AGENT = ROOT / "policies/pretrained/ppo_residual.zip"


def _env(config: str | None = None):
    """The env of ``config`` (a training config's path; None: configs/eval.yml, the model)."""
    from training.common import EVAL_CONFIG, env_settings, limit_threads, load_config, make_env

    limit_threads()
    return make_env(*env_settings(load_config(config or EVAL_CONFIG)))


def family_of(job: tuple[int, str | None]) -> str:
    """The family of the route the env of config ``job[1]`` draws at reset ``job[0]``."""
    seed, config = job
    env = _env(config)
    _, info = env.reset(seed=seed)
    env.close()
    return str(info["target"])


def episode(job: dict[str, Any]) -> dict[str, Any]:
    """One episode of ``job["policy"]`` (follower, agent, shield) at reset ``job["seed"]``."""
    from policies import RouteFollower, load_policy
    from policies.residual import combine

    env = _env(job.get("config"))
    obs, info = env.reset(seed=job["seed"])
    route = env.unwrapped.observation_slices["route"]
    if job["policy"] == "follower":
        policy = RouteFollower.from_env(env)
    else:
        policy = load_policy(AGENT, env=env)
    policy.reset(job["seed"])
    steps = shielded = 0
    while True:
        if job["policy"] == "shield":
            b = policy.base.act(obs)
            o = policy.vecnormalize.normalize_obs(np.asarray(obs, dtype=np.float32)[None])
            a, _ = policy.model.predict(o, deterministic=True)
            action = combine(b, np.asarray(a, dtype=np.float32).reshape(-1), policy.scale)
            kx, kz = float(obs[route][1]), float(obs[route][2])
            if math.hypot(kx, kz) < job["shield"]:
                action, shielded = np.asarray(b, dtype=np.float32), shielded + 1
        else:
            action = policy.act(obs)
        obs, _, term, trunc, info = env.step(action)
        steps += 1
        if term or trunc:
            break
    env.close()
    return {"seed": job["seed"], "route": str(info["target"]), "policy": job["policy"],
            "config": job.get("config"),
            "shield": job.get("shield"), "score": float(info["score"]),
            "shorts": int(info["shorts"]), "steps": steps, "shielded": shielded}  # fmt: skip


def main(argv: list[str] | None = None) -> int:
    from cnt_env.cli.common import name_list, positive_int, seed_int

    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--first", type=seed_int, default=1000, help="the first reset seed")
    ap.add_argument("--count", type=positive_int, default=124, help="reset seeds drawn")
    ap.add_argument("--family", default="detour")
    ap.add_argument("--policies", type=name_list, default="follower,agent,shield")
    ap.add_argument("--shield", type=float, default=30.0, help="L_vb (policy 'shield')")
    ap.add_argument("--jobs", type=int, default=2)
    ap.add_argument(
        "--config",
        help="the env of this config's env_kwargs (default: "
        "training/configs/eval.yml, the model; the agent's own, "
        "policies/pretrained/ppo_residual.yml, is the surrogate it trained on)",
    )
    ap.add_argument("--out", type=Path, default=OUT)
    args = ap.parse_args(argv)
    bad = sorted(set(args.policies) - {"follower", "agent", "shield"})
    if bad:
        ap.error(f"--policies takes follower, agent, shield; got {','.join(bad)}")
    if args.config is not None and not Path(args.config).is_file():
        ap.error(
            f"--config {args.config}: no such file (a training config, e.g. "
            "policies/pretrained/ppo_residual.yml)"
        )
    rows: list[dict[str, Any]] = []
    args.out.write_text("")  # a fresh file per run; rows are appended as episodes end
    with ProcessPoolExecutor(max_workers=args.jobs) as pool:
        drawn = list(range(args.first, args.first + args.count))
        families = list(pool.map(family_of, [(s, args.config) for s in drawn]))
        seeds = [s for s, f in zip(drawn, families, strict=True) if f == args.family]
        jobs = [{"seed": s, "policy": p, "shield": args.shield if p == "shield" else None,
                 "config": args.config} for s in seeds for p in args.policies]  # fmt: skip
        for row in pool.map(episode, jobs):
            rows.append(row)
            with args.out.open("a") as fh:
                fh.write(json.dumps(row) + "\n")
            print(json.dumps(row), flush=True)
    for p in args.policies:
        rs = [r for r in rows if r["policy"] == p]
        if rs:
            print(f"{p}: mean {statistics.fmean(r['score'] for r in rs):.3f} over {len(rs)} "
                  f"{args.family} routes, {sum(r['shorts'] > 0 for r in rs)} shorted")  # fmt: skip
    return 0


if __name__ == "__main__":
    raise SystemExit(main())

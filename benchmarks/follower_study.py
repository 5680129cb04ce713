"""The scripted route follower's options, measured on routes drawn from the training
families (never the held-out set): the evidence behind its defaults
(``policies/route_follower.py``).

    python benchmarks/follower_study.py [--families straight,l_route,...] [--seeds 0,1,2]
        [--variant NAME=JSON ...] [--config training/configs/eval.yml]
        [--jobs 2] [--out benchmarks/results/follower_study_converged.jsonl]

Each (variant, family, seed) is one episode of the config's env with
``reset(seed=seed, options={"target": family})`` (the family's route drawn from the env's
``np_random``; the family ``validation`` is the validation route ``seed`` of
``benchmarks/checkpoint_selection.py`` and of the training callbacks, a draw from every
training family with reset seed 50 000 + ``seed``), played by
``RouteFollower.from_env(env, **options)``. One JSON line per episode (score, precision,
progress, shorts, steps); then the mean score per variant and family. The default
variants: ``round3`` (no plan, the window's mean, the plain repulsion: the follower
before this study), ``plan`` (plan around keep-outs, memory 0), ``lead0`` (no predicted
centre), ``default`` (the shipped options).
"""

from __future__ import annotations

import argparse
import json
import multiprocessing as mp
import time
from collections import defaultdict
from pathlib import Path

from cnt_env.cli.common import name_list, seed_list
from cnt_env.jsonl import append_row
from training.common import EVAL_CONFIG

FAMILIES = ("straight", "l_route", "u_route", "staircase", "arc", "band", "pads", "detour")
VARIANTS = {
    "round3": {"plan": False, "observed_band": False, "memory": 0, "lead": 0.0},
    "plan": {"memory": 0, "lead": 0.0},
    "lead0": {"lead": 0.0},
    "default": {},
}
ROOT = Path(__file__).resolve().parents[1]


def _episode(job: tuple) -> dict:
    from policies import RouteFollower
    from training.common import (
        VALIDATION_SEED0,
        env_settings,
        limit_threads,
        load_config,
        make_env,
    )
    from training.evaluate import _play

    variant, options, family, seed, config = job
    limit_threads()
    env_kwargs, max_steps = env_settings(load_config(config))
    env = make_env(env_kwargs, max_steps)
    try:
        policy = RouteFollower.from_env(env, **options)
        t0 = time.perf_counter()
        if family == "validation":  # the validation routes of checkpoint_selection.py
            obs, _ = env.reset(seed=VALIDATION_SEED0 + seed)
        else:
            obs, _ = env.reset(seed=seed, options={"target": family})
        policy.reset(seed)
        steps, _, info = _play(env, policy, obs)
        return {"variant": variant, "options": options, "family": family, "seed": seed,
                **{k: float(info[k]) for k in ("score", "precision", "progress")},
                "shorts": int(info["shorts"]), "steps": steps,
                "wall_s": round(time.perf_counter() - t0, 2)}  # fmt: skip
    finally:
        env.close()


def build_parser() -> argparse.ArgumentParser:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--families", type=name_list, default=",".join(FAMILIES))
    p.add_argument("--seeds", type=seed_list, default="0,1,2")
    p.add_argument("--variant", action="append", default=[],
                   help="NAME=JSON options (default: round3, plan, default)")  # fmt: skip
    # the follower is scored on the held-out evaluation's env (the model); every study in
    # follower_study_converged.jsonl passed it as --config. Until 2026-12-02 the default
    # was the residual's training config (the surrogate).
    p.add_argument("--config", type=Path, default=EVAL_CONFIG)
    p.add_argument("--jobs", type=int, default=2)
    p.add_argument(
        "--out", type=Path, default=ROOT / "benchmarks/results/follower_study_converged.jsonl"
    )
    return p


def main(argv: list[str] | None = None) -> None:
    args = build_parser().parse_args(argv)
    variants = dict(VARIANTS)
    if args.variant:
        variants = {}
        for v in args.variant:
            name, _, text = v.partition("=")
            variants[name] = json.loads(text) if text else {}
    seeds, families = args.seeds, args.families
    jobs = [(name, opts, f, s, str(args.config))
            for name, opts in variants.items() for f in families for s in seeds]  # fmt: skip
    args.out.parent.mkdir(parents=True, exist_ok=True)
    by = defaultdict(list)
    with mp.get_context("forkserver").Pool(args.jobs) as pool:
        for row in pool.imap(_episode, jobs):
            append_row(args.out, row)
            by[row["variant"], row["family"]].append(row["score"])
    print("| variant | " + " | ".join(families) + " | mean |")
    print("|---" * (len(families) + 2) + "|")
    for name in variants:
        cells = [sum(by[name, f]) / len(by[name, f]) for f in families]
        allv = [x for f in families for x in by[name, f]]
        print(f"| {name} | " + " | ".join(f"{c:.3f}" for c in cells)
              + f" | **{sum(allv) / len(allv):.3f}** |")  # fmt: skip


if __name__ == "__main__":
    main()

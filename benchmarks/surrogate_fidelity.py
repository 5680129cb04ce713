"""How closely a training surrogate stands in for the model: the scripted route follower
on the model's validation routes, played under several physics.

    python benchmarks/surrogate_fidelity.py [--routes 12] [--jobs 2]
        [--physics NAME=JSON ...] [--out benchmarks/results/surrogate_fidelity.jsonl]

Each physics is a set of ``CNTDeposit-v0`` keywords (the default ones: the model, the
fast surrogate, the surrogate calibrated to the model's kinematics as
``training/configs/ppo_residual_calibrated.yml`` trains on, and the model's linear law on
two coarser rods). Route i is the validation route of ``training.common`` (reset seed
``VALIDATION_SEED0 + i``, drawn from the training families: never a held-out route), so
the per-route scores pair up across physics. One JSON line per physics: the follower's
score, steps and trace laid per route, the CPU time, and the correlation of its per-route
scores with the model's (the first physics).
"""

from __future__ import annotations

import argparse
import json
import multiprocessing as mp
import time
from pathlib import Path

import numpy as np

from cnt_env.jsonl import append_row

ROOT = Path(__file__).resolve().parents[1]
OUT = ROOT / "benchmarks" / "results" / "surrogate_fidelity.jsonl"
CALIBRATED_CONFIG = ROOT / "training" / "configs" / "ppo_residual_calibrated.yml"


def default_physics() -> dict[str, dict]:
    """The model, the surrogate, the calibrated surrogate (its config's env keywords) and
    the model's law on two coarser rods."""
    from cnt_env.presets import SURROGATE
    from training.common import env_settings, load_config

    calibrated, _ = env_settings(load_config(CALIBRATED_CONFIG))
    calibrated.pop("pattern_every", None)
    coarse = {f"linear_delta_{d}": {"delta_bar": d} for d in (0.33, 0.5)}
    return {"model": {}, "surrogate": dict(SURROGATE), "calibrated": calibrated, **coarse}


def _episode(job: tuple[dict, int]) -> dict:
    from cnt_env.task.env import CNTDepositEnv
    from policies import RouteFollower
    from training.common import VALIDATION_SEED0, limit_threads
    from training.evaluate import _play

    kwargs, i = job
    limit_threads()
    env = CNTDepositEnv(pattern_every=0, **kwargs)
    policy = RouteFollower.from_env(env)
    obs, _ = env.reset(seed=VALIDATION_SEED0 + i)
    policy.reset(i)
    t0 = time.process_time()
    steps, _, info = _play(env, policy, obs)
    return {"route": i, "family": env.target.name, "score": float(info["score"]),
            "steps": steps, "laid": float(info["laid_length"]),
            "cpu_s": time.process_time() - t0}  # fmt: skip


def main(argv: list[str] | None = None) -> None:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--routes", type=int, default=12)
    p.add_argument("--jobs", type=int, default=2)
    p.add_argument("--physics", action="append", default=[],
                   help="NAME=JSON env keywords (default: default_physics())")  # fmt: skip
    p.add_argument("--out", type=Path, default=OUT)
    args = p.parse_args(argv)
    physics = default_physics()
    if args.physics:
        physics = {}
        for spec in args.physics:
            name, _, text = spec.partition("=")
            physics[name] = json.loads(text) if text else {}
    reference: np.ndarray | None = None
    args.out.parent.mkdir(parents=True, exist_ok=True)
    with mp.get_context("spawn").Pool(args.jobs) as pool:
        for name, kwargs in physics.items():
            rows = pool.map(_episode, [(kwargs, i) for i in range(args.routes)])
            scores = np.array([r["score"] for r in rows])
            reference = scores if reference is None else reference
            cpu, laid = sum(r["cpu_s"] for r in rows), sum(r["laid"] for r in rows)
            record = {
                "physics": name, "kwargs": kwargs, "mean_score": float(scores.mean()),
                "corr_with_first": float(np.corrcoef(scores, reference)[0, 1]),
                "steps": sum(r["steps"] for r in rows), "laid": laid, "cpu_s": cpu,
                "laid_per_cpu_s": laid / cpu, "routes": rows,
            }  # fmt: skip
            print(f"{name:>20}: follower {record['mean_score']:.4f} (r = "
                  f"{record['corr_with_first']:+.2f} with {next(iter(physics))}), "
                  f"{record['steps']} steps, {laid:.0f} L_vb, {laid / cpu:.0f} L_vb per CPU-s",
                  flush=True)  # fmt: skip
            append_row(args.out, record)


if __name__ == "__main__":
    main()

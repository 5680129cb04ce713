"""RLlib sampling throughput against the number of env runners (optional extra ``[ray]``).

    python benchmarks/rllib_throughput.py --runners 1,2 --iterations 3

For each runner count, builds PPO from ``training/configs/ppo.yml`` (same env kwargs as
the SB3 configs) on a local Ray instance, runs ``--iterations`` training iterations after
one warm-up iteration (numba compile, warm-start cache), and reports env steps sampled per
second of wall time and per second of sampling. Writes
``benchmarks/results/rllib_throughput.json``.

How it scales on N machines: each env runner is one process with one env and needs one
core; the sampling rate is then (rate per runner) x (runners) until the single learner's
update (the PPO epochs on the train batch) dominates the iteration. The JSON gives both
parts so that the bound can be read off: iteration = max(sampling, learner) with
asynchronous sampling, their sum with RLlib's synchronous PPO.
"""

from __future__ import annotations

import argparse
import json
import sys
import time
from pathlib import Path

from cnt_env.cli.common import int_list
from training.common import CONFIG_DIR, load_config
from training.rllib import _import_ray, build_config

RESULTS = Path(__file__).resolve().parent / "results" / "rllib_throughput.json"


def measure(zoo: dict, runners: int, iterations: int) -> dict:
    algo = build_config(zoo, runners).build_algo()
    try:
        warm = algo.train()  # warm-up: compile, warm state, first rollouts
        start = int(warm["num_env_steps_sampled_lifetime"])
        t0 = time.perf_counter()
        sample_s = 0.0
        for _ in range(iterations):
            r = algo.train()
            timers = r.get("timers", {})
            sample_s += float(timers.get("env_runner_sampling_timer", 0.0))
        wall = time.perf_counter() - t0
        steps = int(r["num_env_steps_sampled_lifetime"]) - start
    finally:
        algo.stop()
    return {
        "env_runners": runners,
        "iterations": iterations,
        "env_steps_per_iteration": steps / iterations,
        "wall_s": round(wall, 2),
        "env_steps_per_s": round(steps / wall, 2),
        # None when this RLlib version does not report the sampling timer
        "sampling_s_per_iteration": round(sample_s / iterations, 2) if sample_s else None,
        "iteration_s": round(wall / iterations, 2),
    }


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument(
        "--runners", type=int_list, default="1,2", help="comma-separated env-runner counts"
    )
    ap.add_argument("--iterations", type=int, default=3)
    ap.add_argument("--config", type=Path, default=CONFIG_DIR / "ppo.yml")
    ap.add_argument("--n-steps", type=int, default=256, help="rollout steps per runner")
    ap.add_argument("--out", type=Path, default=RESULTS)
    args = ap.parse_args(argv)
    ray = _import_ray()
    zoo = load_config(args.config)
    zoo["n_steps"] = args.n_steps
    zoo["n_epochs"] = 1
    rows = []
    counts = args.runners
    ray.init(num_cpus=max(counts) + 1, include_dashboard=False, log_to_driver=False)
    try:
        for n in counts:
            rows.append(measure(zoo, n, args.iterations))
            print(json.dumps(rows[-1]), flush=True)
    finally:
        ray.shutdown()
    base = rows[0]["env_steps_per_s"] / rows[0]["env_runners"] if rows[0]["env_runners"] else 0
    for r in rows:
        r["speedup_vs_first"] = round(r["env_steps_per_s"] / rows[0]["env_steps_per_s"], 2)
    result = {
        "command": "python benchmarks/rllib_throughput.py "
        + " ".join(sys.argv[1:] if argv is None else argv),
        "cores": __import__("os").cpu_count(),
        "rows": rows,
        "per_runner_env_steps_per_s": round(base, 1),
    }
    args.out.parent.mkdir(parents=True, exist_ok=True)
    args.out.write_text(json.dumps(result, indent=2) + "\n")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())

"""Throughput of CNTDeposit-v0: L_vb of trace per CPU-second, control steps per second on
one core, and reset times.

For each preset (``--presets``: the serpentine default and the coil preset, route task
by default) it measures, in one process with one thread:

* ``reset_cold_s``: the first reset with an empty warm-state cache (it simulates the
  warm-up; numba compilation is excluded, it happens before the timing);
* ``reset_warm_disk_s``: the first reset of a new env when the state is on disk;
* ``reset_warm_memory_s``: the median reset of an env that has its warm state;
* ``lvb_per_cpu_s`` (the figure of merit, goal 300): trace laid per CPU-second of
  ``env.step`` (``time.process_time``, so a busy machine moves it little), and
  ``steps_per_s`` (wall): over ``--steps`` steps with seeded random actions (episodes
  restart through reset, whose time is not counted), with the share of the time spent
  inside the simulator and the solver counts per control step.

``--previous`` adds the same measurement of each preset with the env's settings before
round 3 (a uniform suspended rod and the Newton tolerance 1e-8: ``sim_options=
{"coarse_delta": None, "newton": NewtonOptions()}``, against the graded rod and 1e-5 of
``presets.MESH`` and ``presets.NEWTON``; on the coil preset also the validated step,
``dt_factor`` 0.05, against the flat env's 0.1 of ``presets.ENV_SIM_DEFAULTS``) and the
ratio of the two figures of merit. ``--surrogate`` adds the same for the fast surrogate
the agents are trained on (``presets.SURROGATE``: the printed drag law at delta_bar 1,
against the model's linear law at 0.2) and the ratio of the surrogate's figure to the
default's. ``--baseline N``
also runs N control steps of the paper's constant flow (v̄ = 0.037 along +x) and
measures the serpentine it lays, which sets the episode length (max_episode_steps).
Prints one JSON object.

    python benchmarks/env_throughput.py [--steps 200] [--presets serpentine,coil]
                                        [--previous] [--surrogate] [--small]
                                        [--baseline 600]
                                        [--score corridor|thin] [--out FILE]
"""

from __future__ import annotations

import os

for _var in ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS", "NUMBA_NUM_THREADS"):
    os.environ.setdefault(_var, "1")  # one core: the figure is per core

import argparse  # noqa: E402
import json  # noqa: E402
import platform  # noqa: E402
import statistics  # noqa: E402
import sys  # noqa: E402
import tempfile  # noqa: E402
import time  # noqa: E402
from pathlib import Path  # noqa: E402

import numpy as np  # noqa: E402

from cnt_env.cli.common import name_list  # noqa: E402
from cnt_env.patterns import MeasureOptions  # noqa: E402
from cnt_env.patterns import measure as measure_pattern  # noqa: E402
from cnt_env.presets import SURROGATE  # noqa: E402
from cnt_env.sim import warmstart  # noqa: E402
from cnt_env.sim.deposition import DepositionConfig, DepositionSim  # noqa: E402
from cnt_env.sim.stepper import NewtonOptions  # noqa: E402
from cnt_env.task.env import CNTDepositEnv  # noqa: E402

#: Issue 11's goal: L_vb of trace per CPU-second of env.step.
GOAL_LVB_PER_CPU_S = 300.0


def _compile(env: CNTDepositEnv) -> None:
    """Load or compile the numba kernels outside every timing."""
    sim = DepositionSim(env.config, seed=0)
    sim.step()


def measure(kwargs: dict, steps: int, seed: int = 0) -> dict:
    with tempfile.TemporaryDirectory() as cache:
        kwargs = dict(kwargs, cache_dir=cache)
        env = CNTDepositEnv(**kwargs)
        _compile(env)
        warmstart.clear_memory_cache()
        t0 = time.perf_counter()
        env.reset(seed=seed)
        reset_cold = time.perf_counter() - t0

        warmstart.clear_memory_cache()
        env2 = CNTDepositEnv(**kwargs)
        t0 = time.perf_counter()
        env2.reset(seed=seed)
        reset_disk = time.perf_counter() - t0
        memory = []
        for k in range(5):
            t0 = time.perf_counter()
            env2.reset(seed=seed + 1 + k)
            memory.append(time.perf_counter() - t0)

        sim = env._sim
        inner = sim.advance
        in_sim = [0.0]

        def timed_advance(duration: float) -> None:
            t = time.perf_counter()
            try:
                inner(duration)
            finally:
                in_sim[0] += time.perf_counter() - t

        sim.advance = timed_advance
        rng = np.random.default_rng(seed)
        wall, cpu, laid, prev, phys, newton, failures, episodes = 0.0, 0.0, 0.0, 0.0, 0, 0, 0, 1
        sim_in_steps = 0.0
        for _ in range(steps):
            action = rng.uniform(-1.0, 1.0, 2).astype(np.float32)
            t0, c0, s0 = time.perf_counter(), time.process_time(), in_sim[0]
            _, _, terminated, truncated, info = env.step(action)
            wall += time.perf_counter() - t0
            cpu += time.process_time() - c0
            sim_in_steps += in_sim[0] - s0  # not the resets' advance
            laid += info["laid_length"] - prev
            prev = info["laid_length"]
            phys += info["physics_steps"]
            newton += info["newton_iterations"]
            if terminated or truncated:
                failures += "failure" in info
                env.reset()
                prev = 0.0
                episodes += 1
    return {
        "params": {k: v for k, v in env.params.as_dict().items() if v is not None},
        "substrate": env.substrate,
        "coarse_delta": env.config.coarse_delta,
        "dt": env.dt,
        "control_interval": env.control_interval,
        "n_substeps": env.n_substeps,
        "warmup_length": env.warmup_length,
        "reset_cold_s": round(reset_cold, 3),
        "reset_warm_disk_s": round(reset_disk, 4),
        "reset_warm_memory_s": round(statistics.median(memory), 4),
        "steps": steps,
        "episodes": episodes,
        "failures": failures,
        "lvb_per_cpu_s": round(laid / cpu, 1),
        "cpu_s": round(cpu, 2),
        "steps_per_s": round(steps / wall, 2),
        "ms_per_step": round(1e3 * wall / steps, 3),
        "sim_share": round(sim_in_steps / wall, 4),
        "env_overhead_ms_per_step": round(1e3 * (wall - sim_in_steps) / steps, 3),
        "laid_per_step": round(laid / steps, 3),
        "physics_steps_per_control_step": round(phys / steps, 2),
        "newton_iterations_per_physics_step": round(newton / max(phys, 1), 3),
        "us_per_newton_iteration": round(1e6 * sim_in_steps / max(newton, 1), 1),
        "n_nodes": int(sim.rod.n_nodes),
    }


def baseline(kwargs: dict, steps: int) -> dict:
    """The pattern laid by the preset's own constant flow over ``steps`` control steps."""
    env = CNTDepositEnv(**dict(kwargs, reset_advance=0.0))
    env.reset(seed=0, options={"target": "long_diagonal"})
    p = env.params
    u = p.vbar / env.vbar_max  # an action on an axis maps to that fraction of vbar_max
    action = np.array([u * np.cos(p.phi), u * np.sin(p.phi)], dtype=np.float32)
    t0 = time.perf_counter()
    for _ in range(steps):
        *_, info = env.step(action)
    wall = time.perf_counter() - t0
    trace = env._sim.trace()[env._n0 - 1 :]
    m = measure_pattern(trace, MeasureOptions(transient_length=0.0), substrate=env.substrate)
    periods = max(m["n_uturns"] - 1, 1) / 2.0
    return {
        "steps": steps,
        "wall_s": round(wall, 2),
        "laid_length": round(info["laid_length"], 2),
        "laid_per_step": round(info["laid_length"] / steps, 3),
        "pattern": m["pattern"],
        "amplitude": round(m["amplitude"], 2),
        "peak_to_peak": round(m.get("peak_to_peak", float("nan")), 2),
        "wavelength": round(m["wavelength"], 2),
        "n_uturns": m["n_uturns"],
        "trace_per_period": round(m["measured_length"] / periods, 1),
    }


def main(argv: list[str] | None = None) -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--steps", type=int, default=200)
    parser.add_argument(
        "--presets", type=name_list, default="serpentine,coil", help="comma separated"
    )
    parser.add_argument("--out", default=None, help="also write the JSON here")
    parser.add_argument(
        "--previous",
        action="store_true",
        help="also measure each preset with the settings before round 3 (uniform rod, 1e-8)",
    )
    parser.add_argument(
        "--surrogate",
        action="store_true",
        help="also measure each preset on the fast surrogate (presets.SURROGATE)",
    )
    parser.add_argument(
        "--small",
        action="store_true",
        help="the test-suite configuration (Hbar = 30) instead of the default",
    )
    parser.add_argument(
        "--baseline",
        type=int,
        default=0,
        help="also lay this many control steps at the preset's constant flow",
    )
    parser.add_argument(
        "--score",
        choices=("thin", "corridor"),
        default="corridor",
        help="task: corridor (the route task, 30 H-bar control steps) or thin (the "
        "first round's task)",
    )
    args = parser.parse_args(argv)
    base: dict = {"score": args.score}
    if args.small:
        base = dict(base, Hbar=30.0, Ibar=200.0, initial_radius=4.0, warmup_length=3.0)
    result = {
        "benchmark": "env_throughput",
        "machine": {"processor": platform.processor() or platform.machine(),
                    "cpu_count": os.cpu_count(), "threads": 1},
        "goal_lvb_per_cpu_s": GOAL_LVB_PER_CPU_S,
        "argv": sys.argv[1:] if argv is None else list(argv),
    }  # fmt: skip
    for preset in args.presets:
        result[preset] = measure(dict(base, preset=preset), args.steps)
        result[preset]["meets_goal"] = result[preset]["lvb_per_cpu_s"] >= GOAL_LVB_PER_CPU_S
        if args.previous:
            before = {"coarse_delta": None, "newton": NewtonOptions()}
            if preset == "coil":  # the flat env ran the validated step until round 3's end
                before["dt_factor"] = DepositionConfig.dt_factor
            prev = measure(dict(base, preset=preset, sim_options=before), args.steps)
            result[preset]["previous"] = prev
            result[preset]["ratio_to_previous"] = round(
                result[preset]["lvb_per_cpu_s"] / prev["lvb_per_cpu_s"], 3
            )
        if args.surrogate:
            fast = measure(dict(base, preset=preset, **SURROGATE), args.steps)
            result[preset]["surrogate"] = fast
            result[preset]["surrogate_speedup"] = round(
                fast["lvb_per_cpu_s"] / result[preset]["lvb_per_cpu_s"], 3
            )
    if args.baseline > 0:
        with tempfile.TemporaryDirectory() as cache:
            result["baseline_pattern"] = baseline(dict(base, cache_dir=cache), args.baseline)
    text = json.dumps(result, indent=2)
    print(text)
    if args.out:
        Path(args.out).write_text(text + "\n")


if __name__ == "__main__":
    main()

"""A/B driver for the speed work of issue 11: one deposition run or one env run with
optional Newton options, timed in CPU seconds of this process (the machine is shared).

    python benchmarks/speed_ab.py --preset serpentine --deposit 200
    python benchmarks/speed_ab.py --preset coil --deposit 1000 --measure
    python benchmarks/speed_ab.py --env --preset coil --steps 100
    python benchmarks/speed_ab.py --preset serpentine --deposit 200 --newton residual_check=False

``--newton name=value`` (repeatable) sets a NewtonOptions field over the model's
(``presets.NEWTON``; on a checkout from before it, over the stepper's defaults); values
are Python literals. Without any, the code's defaults run, so the same command works on
a checkout from before issue 11 (the baseline of an A/B pair). ``--measure`` adds the pattern
figures of the run (coil radius, amplitude, wavelength; transient 150 L_vb). Prints one
JSON line.
"""

from __future__ import annotations

import os

for _var in ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS", "NUMBA_NUM_THREADS"):
    os.environ.setdefault(_var, "1")

import argparse  # noqa: E402
import ast  # noqa: E402
import json  # noqa: E402
import tempfile  # noqa: E402
import time  # noqa: E402

import numpy as np  # noqa: E402

from cnt_env.sim.deposition import DepositionSim, default_config  # noqa: E402
from cnt_env.sim.stepper import NewtonOptions  # noqa: E402


def main(argv: list[str] | None = None) -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--preset", choices=("coil", "serpentine"), default="serpentine")
    ap.add_argument("--deposit", type=float, default=200.0)
    ap.add_argument("--env", action="store_true")
    ap.add_argument("--steps", type=int, default=150)
    ap.add_argument("--measure", action="store_true")
    ap.add_argument("--transient", type=float, default=150.0)
    ap.add_argument("--seed", type=int, default=0, help="start-up perturbation seed (runs)")
    ap.add_argument(
        "--set",
        action="append",
        default=[],
        metavar="NAME=VALUE",
        help="a DimensionlessParams group of the run (e.g. Ibar=1000)",
    )
    ap.add_argument("--newton", action="append", default=[], metavar="NAME=VALUE")
    args = ap.parse_args(argv)
    if args.env and (args.set or args.seed):
        ap.error("--set and --seed apply to runs, not to --env (the env's seed 0 and groups)")
    opts = {}
    for item in args.newton:
        name, value = item.split("=", 1)
        opts[name] = ast.literal_eval(value)
    try:  # the model's Newton options, which --newton changes field by field
        from cnt_env.presets import NEWTON as model_newton
    except ImportError:  # a checkout from before presets.NEWTON: the stepper's defaults
        model_newton = {}
    extra = {"newton": NewtonOptions(**{**model_newton, **opts})} if opts else {}
    out: dict = {"preset": args.preset, "newton": opts}
    if args.env:
        import gymnasium as gym

        import cnt_env  # noqa: F401  (registers CNTDeposit-v0)

        with tempfile.TemporaryDirectory() as cache:
            env = gym.make("CNTDeposit-v0", preset=args.preset, cache_dir=cache,
                           sim_options=extra or None)  # fmt: skip
            env.reset(seed=0)
            rng = np.random.default_rng(0)
            laid, prev, phys = 0.0, 0.0, 0
            t0 = time.process_time()
            for _ in range(args.steps):
                _, _, term, trunc, info = env.step(rng.uniform(-1, 1, 2).astype(np.float32))
                laid += info["laid_length"] - prev
                prev = info["laid_length"]
                phys += info["physics_steps"]
                if term or trunc:
                    env.reset()
                    prev = 0.0
            cpu = time.process_time() - t0
        out.update(mode="env", steps=args.steps, cpu_s=round(cpu, 3), laid=round(laid, 2),
                   laid_per_cpu_s=round(laid / cpu, 2), physics_steps=phys,
                   control_steps_per_cpu_s=round(args.steps / cpu, 2))  # fmt: skip
    else:
        groups = {k: float(v) for k, v in (item.split("=", 1) for item in args.set)}
        cfg = default_config(args.preset, **extra, **groups)
        DepositionSim(cfg, seed=0).step()  # compile / load the numba cache outside the timing
        sim = DepositionSim(cfg, seed=args.seed)
        t0 = time.process_time()
        sim.run(args.deposit)
        cpu = time.process_time() - t0
        st = sim.stats()
        out.update(mode="baseline", seed=args.seed, groups=groups, deposit=args.deposit,
                   cpu_s=round(cpu, 3),
                   laid_per_cpu_s=round(st["deposited_length"] / cpu, 2), steps=st["steps"],
                   newton_per_step=round(st["newton_iterations"] / st["steps"], 4),
                   halvings=st["halvings"], events=st["events"])  # fmt: skip
        if args.measure:
            from cnt_env.patterns import MeasureOptions, measure

            substrate = "stepped" if cfg.params.kappa_c_bar is not None else "flat"
            m = measure(sim.trace(), MeasureOptions(transient_length=args.transient), substrate)
            out.update({k: float(m[k]) for k in ("coil_radius", "amplitude", "wavelength")})
            out["pattern"] = m["pattern"]
    print(json.dumps(out))


if __name__ == "__main__":
    main()

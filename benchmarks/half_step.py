"""One serpentine point at a chosen step and Newton options, with the solver's counts
(issue 12, "Δt on the shipped solver" in benchmarks/RESULTS.md): the pattern's figures
and CVs, Newton step halvings and failed touchdown searches. Prints one JSON object.

    python benchmarks/half_step.py [--vbar 0.037] [--dt-factor 0.025] [--deposit 4000]
        [--projection 0.02] [--predictor-retry] [--max-rotation DEG]
        [--snap jump|constraint|penalty] [--save-trace PATH]
"""

from __future__ import annotations

import argparse
import dataclasses
import json
import math
import time


def main(argv: list[str] | None = None) -> dict:
    from cnt_env.patterns import MeasureOptions, measure
    from cnt_env.presets import RUN_TRANSIENT
    from cnt_env.sim import deposition

    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--vbar", type=float, default=0.037)
    p.add_argument("--dt-factor", type=float, default=0.025)
    p.add_argument("--deposit", type=float, default=4000.0)
    p.add_argument("--seed", type=int, default=0)
    p.add_argument("--projection", type=float, default=None, help="default: presets.NEWTON")
    p.add_argument("--predictor-retry", action="store_true")
    p.add_argument(
        "--max-rotation",
        type=float,
        default=None,
        help="NewtonOptions.max_edge_rotation in degrees (default: presets.NEWTON)",
    )
    p.add_argument("--save-trace", default=None, help="write the trace (.npy) here")
    p.add_argument("--snap", default=None, help="default: presets.MODEL (Stepped.snap)")
    args = p.parse_args(argv)
    cfg = deposition.default_config("serpentine")
    newton = dataclasses.replace(cfg.newton, predictor_retry=args.predictor_retry)
    if args.max_rotation is not None:
        newton = dataclasses.replace(newton, max_edge_rotation=math.radians(args.max_rotation))
    if args.projection is not None:
        newton = dataclasses.replace(newton, length_projection=args.projection)
    cfg = dataclasses.replace(cfg, params=dataclasses.replace(cfg.params, vbar=args.vbar),
                              dt_factor=args.dt_factor, newton=newton)  # fmt: skip
    if args.snap is not None:
        cfg = dataclasses.replace(cfg, snap=args.snap)
    sim = deposition.DepositionSim(cfg, seed=args.seed)
    t0 = time.process_time()
    sim.run(args.deposit)
    cpu = time.process_time() - t0
    if args.save_trace:
        import numpy as np

        np.save(args.save_trace, sim.trace())
    m = measure(sim.trace(), MeasureOptions(transient_length=RUN_TRANSIENT["serpentine"]),
                "stepped")  # fmt: skip
    out = {
        "vbar": args.vbar, "dt_factor": args.dt_factor, "deposit": args.deposit,
        "seed": args.seed, "length_projection": newton.length_projection,
        "predictor_retry": newton.predictor_retry,
        "max_edge_rotation_deg": round(math.degrees(newton.max_edge_rotation), 3),
        "snap": cfg.snap, "pattern": m["pattern"],
        "amplitude": m["amplitude"], "wavelength": m["wavelength"],
        "amplitude_cv": m["amplitude_cv"], "wavelength_cv": m["wavelength_cv"],
        "n_loops": m["n_loops"], "n_self_crossings": m["n_self_crossings"],
        **{k: v for k, v in sim.stats().items() if isinstance(v, (int, float))},
        "cpu_s": round(cpu, 1),
    }  # fmt: skip
    print(json.dumps(out))
    return out


if __name__ == "__main__":
    main()

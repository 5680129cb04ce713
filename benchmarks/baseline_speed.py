"""Speed of the paper's baselines with their validated default configuration: the coil
preset (Hbar = 253, Ibar = 2200, flat sticky substrate, no flow; issue 11's goal 1000
L_vb in 30 s) or the serpentine preset (Hbar = 155, Ibar = 300, stepped, vbar = 0.037;
goal 500 L_vb in 8 s).

Prints JSON: wall time (numba compilation excluded), steps, mean Newton iterations per
step, deposited length per wall-second, and the measured pattern figures.

    python benchmarks/baseline_speed.py [--preset coil|serpentine] [--deposit L]
                                        [--delta D] [--coarse-delta C]

Without options it runs the preset's validated mesh (presets.MESH: uniform delta = 1 on
both); ``--coarse-delta 4`` grades the suspended rod as the env does
(presets.ENV_SIM_DEFAULTS).
"""

from __future__ import annotations

import argparse
import json
import time

from cnt_env.patterns import MeasureOptions, measure
from cnt_env.sim.deposition import DepositionSim, default_config


def main(argv: list[str] | None = None) -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--preset", choices=("coil", "serpentine"), default="coil")
    parser.add_argument("--deposit", type=float, default=None, help="coil 1000, serp. 500")
    parser.add_argument("--delta", type=float, default=None, help="fine delta_bar")
    parser.add_argument("--coarse-delta", type=float, default=None)
    parser.add_argument("--transient", type=float, default=150.0)
    args = parser.parse_args(argv)
    overrides = {} if args.delta is None else {"delta_bar": args.delta}
    if args.coarse_delta is not None:
        overrides["coarse_delta"] = args.coarse_delta
    config = default_config(args.preset, **overrides)  # the validated mesh unless overridden
    deposit = args.deposit or {"coil": 1000.0, "serpentine": 500.0}[args.preset]
    substrate = "stepped" if config.params.kappa_c_bar is not None else "flat"
    warm = DepositionSim(config, seed=0)
    warm.step()  # numba compilation / cache load outside the timing
    sim = DepositionSim(config, seed=0)
    t0 = time.perf_counter()
    sim.run(deposit)
    wall = time.perf_counter() - t0
    st = sim.stats()
    m = measure(sim.trace(), MeasureOptions(transient_length=args.transient), substrate)
    print(json.dumps({
        "benchmark": f"{args.preset}_baseline_speed",
        "delta_bar": config.params.delta_bar,
        "coarse_delta": config.coarse_delta,
        "dt": sim.dt,
        "deposited_length": round(st["deposited_length"], 3),
        "wall_time_s": round(wall, 2),
        "steps": st["steps"],
        "newton_iterations_per_step": round(st["newton_iterations"] / st["steps"], 3),
        "deposited_per_wall_second": round(st["deposited_length"] / wall, 2),
        "n_nodes": st["n_nodes"],
        "coil_radius": round(m["coil_radius"], 4),
        "amplitude": round(m["amplitude"], 3),
        "wavelength": round(m["wavelength"], 3),
        "pattern": m["pattern"],
    }, indent=2))  # fmt: skip


if __name__ == "__main__":
    main()

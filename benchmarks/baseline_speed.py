"""Speed of the paper's baselines with their validated default configuration: the coil
preset (Hbar = 253, Ibar = 2200, flat sticky substrate, no flow; issue 11's goal 1000
L_vb in 30 s) or the serpentine preset (Hbar = 155, Ibar = 300, stepped, vbar = 0.037;
goal 500 L_vb in 8 s).

Prints JSON: wall time (numba compilation excluded), steps, mean Newton iterations per
step, deposited length per wall-second, and the measured pattern figures.

    python benchmarks/baseline_speed.py [--preset coil|serpentine] [--deposit L]
                                        [--delta D] [--coarse-delta C] [--surrogate]
                                        [--previous]
                                        [--out FILE.json]

Without options it runs the preset's validated configuration (presets.MODEL on
presets.MESH: delta = 0.2, graded above 20 L_vb from the contact; presets.NEWTON:
residual 1e-5 e_v); ``--surrogate`` the fast surrogate (the printed law at delta = 1);
``--coarse-delta 0`` is a uniform rod. ``--previous`` also runs the defaults before
round 3 (uniform rod, residual 1e-8) in the same process, after the current ones, and
prints the ratio of their wall times; ``--out`` writes the JSON to a file as well.
"""

from __future__ import annotations

import argparse
import json
import time
from pathlib import Path

from cnt_env.patterns import MeasureOptions, measure
from cnt_env.presets import SURROGATE
from cnt_env.sim.deposition import DepositionSim, default_config
from cnt_env.sim.stepper import NewtonOptions


def timed_run(preset: str, deposit: float, transient: float, **overrides) -> dict:
    """One baseline run (the numba compile and cache load outside the timing)."""
    config = default_config(preset, **overrides)
    substrate = "stepped" if config.params.kappa_c_bar is not None else "flat"
    warm = DepositionSim(config, seed=0)
    warm.step()
    sim = DepositionSim(config, seed=0)
    t0 = time.perf_counter()
    sim.run(deposit)
    wall = time.perf_counter() - t0
    st = sim.stats()
    m = measure(sim.trace(), MeasureOptions(transient_length=transient), substrate)
    return {
        "benchmark": f"{preset}_baseline_speed",
        "delta_bar": config.params.delta_bar,
        "coarse_delta": config.coarse_delta,
        "residual_tol": config.newton.residual_tol,
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
    }  # fmt: skip


def main(argv: list[str] | None = None) -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--preset", choices=("coil", "serpentine"), default="coil")
    parser.add_argument("--deposit", type=float, default=None, help="coil 1000, serp. 500")
    parser.add_argument("--delta", type=float, default=None, help="fine delta_bar")
    parser.add_argument("--coarse-delta", type=float, default=None, help="0: uniform")
    parser.add_argument("--surrogate", action="store_true",
                        help="the fast surrogate (presets.SURROGATE)")  # fmt: skip
    parser.add_argument("--transient", type=float, default=150.0)
    parser.add_argument("--previous", action="store_true",
                        help="also run the pre-round-3 defaults (uniform, 1e-8)")  # fmt: skip
    parser.add_argument("--out", default=None, help="also write the JSON here")
    args = parser.parse_args(argv)
    overrides = dict(SURROGATE) if args.surrogate else {}
    if args.delta is not None:
        overrides["delta_bar"] = args.delta
    if args.coarse_delta is not None:
        overrides["coarse_delta"] = args.coarse_delta or None
    deposit = args.deposit or {"coil": 1000.0, "serpentine": 500.0}[args.preset]
    out = timed_run(args.preset, deposit, args.transient, **overrides)
    if args.previous:
        prev = timed_run(args.preset, deposit, args.transient,
                         **{**overrides, "coarse_delta": None,
                            "newton": NewtonOptions(residual_tol=1e-8)})  # fmt: skip
        out = {**out, "previous": prev,
               "speedup": round(prev["wall_time_s"] / out["wall_time_s"], 3)}  # fmt: skip
    text = json.dumps(out, indent=2)
    print(text)
    if args.out:
        Path(args.out).write_text(text + "\n")


if __name__ == "__main__":
    main()

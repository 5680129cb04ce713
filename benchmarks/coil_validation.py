"""Coil baseline validation (physics.md §6, issue 3): R0 against the paper's 7.64 L_vb,
its convergence in delta and dt, independence of the start-up radius R_i, the drag-law
option, and the physical sanity figures (deposition speed V Hbar, vdW work per length).

Each case runs the paper's coil preset (Hbar = 253, Ibar = 2200) to ``--deposit`` L_vb and
measures the coil radius after ``--transient`` L_vb. Results are cached per case in
``benchmarks/results/coil_validation.json`` (re-running skips finished cases), and a
markdown table is printed.

    python benchmarks/coil_validation.py [--jobs 2] [--cases default,delta_half,...]
"""

from __future__ import annotations

import argparse
import json
import time
from concurrent.futures import ProcessPoolExecutor
from pathlib import Path

RESULTS = Path(__file__).resolve().parent / "results" / "coil_validation.json"

DEFAULT = {"delta_bar": 0.125, "coarse_delta": 1.0, "dt_factor": 0.05, "initial_radius": 6.4,
           "drag_law": "linear"}  # fmt: skip

# name -> overrides of DEFAULT
CASES: dict[str, dict] = {
    "default": {},
    "delta_1": {"delta_bar": 1.0, "coarse_delta": None},
    "delta_0.5": {"delta_bar": 0.5},
    "delta_0.25": {"delta_bar": 0.25},
    "delta_half": {"delta_bar": 0.0625},
    "dt_half": {"dt_factor": 0.025},
    "Ri_4.8": {"initial_radius": 4.8},
    "Ri_9.6": {"initial_radius": 9.6},
    "printed_drag": {"drag_law": "printed"},
    "printed_drag_delta_1": {"drag_law": "printed", "delta_bar": 1.0, "coarse_delta": None},
    "uniform_0.25": {"delta_bar": 0.25, "coarse_delta": None},
}


def run_case(name: str, deposit: float, transient: float) -> dict:
    from cnt_env.deposition import DepositionConfig, DepositionSim
    from cnt_env.patterns import MeasureOptions, measure
    from cnt_env.units import paper_groups

    c = {**DEFAULT, **CASES[name]}
    config = DepositionConfig(
        params=paper_groups("coil", delta_bar=c["delta_bar"]), dt_factor=c["dt_factor"],
        initial_radius=c["initial_radius"], drag_law=c["drag_law"],
        coarse_delta=c["coarse_delta"],
    )  # fmt: skip
    sim = DepositionSim(config, seed=0)
    t0 = time.perf_counter()
    sim.run(transient)
    mid = sim.stats()
    sim.run(deposit)
    wall = time.perf_counter() - t0
    st = sim.stats()
    laid = st["deposited_length"] - mid["deposited_length"]
    m = measure(sim.trace(), MeasureOptions(transient_length=transient))
    return {
        "case": name, **c, "deposit": deposit, "transient": transient,
        "coil_radius": m["coil_radius"], "coil_radius_spread": m["coil_radius_spread"],
        "coil_coverage": m["coil_coverage"], "pattern": m["pattern"],
        # after the transient: deposition speed in units of e_v/(sigma mu H), vdW work per
        # laid length in e_v, kinetic energy discarded by sticking per laid length
        "V_Hbar": laid / (st["time"] - mid["time"]) * config.params.Hbar,
        "vdw_work_per_length": (st["vdw_work"] - mid["vdw_work"]) / laid,
        "sticking_loss_per_length": (st["sticking_loss"] - mid["sticking_loss"]) / laid,
        "steps": st["steps"], "newton_per_step": st["newton_iterations"] / st["steps"],
        "halvings": st["halvings"], "n_nodes": st["n_nodes"], "wall_time_s": wall,
    }  # fmt: skip


def main(argv: list[str] | None = None) -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--cases", default=",".join(CASES))
    parser.add_argument("--jobs", type=int, default=2)
    parser.add_argument("--deposit", type=float, default=700.0)
    parser.add_argument("--transient", type=float, default=300.0)
    parser.add_argument("--force", action="store_true", help="re-run finished cases")
    args = parser.parse_args(argv)
    done = json.loads(RESULTS.read_text()) if RESULTS.exists() else {}
    todo = [c for c in args.cases.split(",") if args.force or c not in done]
    with ProcessPoolExecutor(max_workers=args.jobs) as pool:
        futures = {c: pool.submit(run_case, c, args.deposit, args.transient) for c in todo}
        for name, fut in futures.items():
            done[name] = fut.result()
            RESULTS.parent.mkdir(parents=True, exist_ok=True)
            RESULTS.write_text(json.dumps(done, indent=1, sort_keys=True))
            print(f"finished {name}: R0 = {done[name]['coil_radius']:.3f}", flush=True)
    ref = done.get("default", {}).get("coil_radius")
    print("| case | delta | dt_factor | R_i | drag | R0 | vs 7.64 | vs default | V Hbar |"
          " vdW work / length | Newton/step | wall s |")  # fmt: skip
    print("|---|---|---|---|---|---|---|---|---|---|---|---|")
    for name in CASES:
        r = done.get(name)
        if r is None:
            continue
        rel = f"{100 * (r['coil_radius'] / ref - 1):+.1f}%" if ref else "-"
        print(
            f"| {name} | {r['delta_bar']}{'' if r['coarse_delta'] is None else ' (graded)'} "
            f"| {r['dt_factor']} | {r['initial_radius']} | {r['drag_law']} "
            f"| {r['coil_radius']:.3f} | {100 * (r['coil_radius'] / 7.64 - 1):+.1f}% | {rel} "
            f"| {r['V_Hbar']:.3f} | {r['vdw_work_per_length']:.3f} "
            f"| {r['newton_per_step']:.2f} | {r['wall_time_s']:.0f} |"
        )


if __name__ == "__main__":
    main()

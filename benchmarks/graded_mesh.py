"""Graded mesh on the suspended rod (issue 11, "fewer unknowns"): what a coarser mesh
far from the contact saves, and what it moves.

Each case runs one deposition, on the serpentine preset at the env's simulator settings
(``presets.ENV_SIM_DEFAULTS``) or at the model's validated ones (``--validated``), or on
the coil preset (``--preset coil``, validated settings), with ``--dt-factor`` and
``coarse_delta`` (the injected edge length, split to ``delta_bar`` within ``fine_length``
of the contact; ``none``: a uniform rod) varied, Newton at the residual 1e-8 e_v the
study ran with (RESULTS.md, issue 11) or, with ``--newton model``, the shipped solver
(``presets.NEWTON``), and
prints one JSON line: CPU seconds, L_vb per CPU-second, mean solved nodes, Newton
iterations per step, and the pattern figures (amplitude, wavelength along x, class).

    python benchmarks/graded_mesh.py --coarse none,2,4 --fine 20,40 --vbar 0.037,0.12 \
        --deposit 600 --jobs 2 --out benchmarks/results/graded_mesh.jsonl
"""

from __future__ import annotations

import os

for _var in ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS", "NUMBA_NUM_THREADS"):
    os.environ.setdefault(_var, "1")

import argparse  # noqa: E402
import itertools  # noqa: E402
import json  # noqa: E402
import sys  # noqa: E402
import time  # noqa: E402
from concurrent.futures import ProcessPoolExecutor  # noqa: E402
from pathlib import Path  # noqa: E402

from cnt_env.cli.common import seed_list  # noqa: E402
from cnt_env.jsonl import append_row  # noqa: E402


def run_case(case: dict) -> dict:
    from cnt_env.patterns import MeasureOptions, measure
    from cnt_env.presets import ENV_SIM_DEFAULTS
    from cnt_env.sim.deposition import DepositionSim, default_config
    from cnt_env.sim.stepper import NewtonOptions

    stepped = case["preset"] == "serpentine"
    changes = {} if case["validated"] or not stepped else dict(ENV_SIM_DEFAULTS["stepped"])
    # the study ran at residual 1e-8 e_v (the model's default when it ran); --newton model
    # runs the shipped solver (presets.NEWTON), as the env does
    if case["newton"] == "strict":
        changes["newton"] = NewtonOptions(residual_tol=1e-8)
    # the mesh is what this benchmark varies: "none" is the uniform rod
    changes.update(coarse_delta=case["coarse"], fine_length=case["fine"] or 20.0)
    if case["dt_factor"] is not None:
        changes.update(dt_factor=case["dt_factor"])
    cfg = default_config(case["preset"], **changes)
    cfg = cfg.with_params(vbar=case["vbar"], phi=case["phi"])
    DepositionSim(cfg, seed=case["seed"]).step()  # numba cache outside the timing
    sim = DepositionSim(cfg, seed=case["seed"])
    nodes, n_chunks = 0.0, 0
    t0 = time.process_time()
    while sim.deposited_length < case["deposit"]:
        sim.run(min(case["deposit"], sim.deposited_length + 10.0))
        nodes += sim.rod.n_nodes
        n_chunks += 1
    cpu = time.process_time() - t0
    st = sim.stats()
    m = measure(
        sim.trace(),
        MeasureOptions(transient_length=case["transient"]),
        "stepped" if stepped else "flat",
    )
    return {
        **case,
        "cpu_s": round(cpu, 2),
        "laid_per_cpu_s": round(st["deposited_length"] / cpu, 2),
        "mean_nodes": round(nodes / max(n_chunks, 1), 1),
        "steps": st["steps"],
        "newton_per_step": round(st["newton_iterations"] / st["steps"], 3),
        "coil_radius": round(float(m["coil_radius"]), 4),
        "amplitude": round(float(m["amplitude"]), 3),
        "wavelength": round(float(m["wavelength"]), 3),
        "pattern": m["pattern"],
    }


def _floats(text: str) -> list[float | None]:
    return [None if v == "none" else float(v) for v in text.split(",")]


def main(argv: list[str] | None = None) -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--preset", choices=("serpentine", "coil"), default="serpentine")
    ap.add_argument("--coarse", default="none,2,4", help="coarse_delta values ('none': uniform)")
    ap.add_argument("--dt-factor", default="none", help="dt_factor values ('none': default)")
    ap.add_argument("--fine", default="20", help="fine_length values (L_vb)")
    ap.add_argument("--vbar", default="0.037")
    ap.add_argument("--phi", default="0")
    ap.add_argument("--seeds", type=seed_list, default="0", help="start-up perturbation seeds")
    ap.add_argument("--deposit", type=float, default=600.0)
    ap.add_argument("--transient", type=float, default=150.0)
    ap.add_argument("--validated", action="store_true", help="serpentine: the model's dt and tail")
    ap.add_argument(
        "--newton",
        choices=("strict", "model"),
        default="strict",
        help="strict: residual 1e-8 e_v (the study's); model: presets.NEWTON",
    )
    ap.add_argument("--jobs", type=int, default=1)
    ap.add_argument("--out", type=Path, default=None, help="append JSON lines here")
    args = ap.parse_args(argv)
    cases = []
    for seed, coarse, fine, vbar, phi, dtf in itertools.product(
        args.seeds,
        _floats(args.coarse),
        _floats(args.fine),
        _floats(args.vbar),
        _floats(args.phi),
        _floats(args.dt_factor),
    ):
        if coarse is None and fine != _floats(args.fine)[0]:
            continue  # fine_length means nothing on a uniform mesh
        cases.append({"preset": args.preset, "coarse": coarse, "fine": fine, "vbar": vbar,
                      "phi": phi, "dt_factor": dtf, "seed": seed,
                      "deposit": args.deposit, "transient": args.transient,
                      "validated": args.validated, "newton": args.newton})  # fmt: skip
    command = "python benchmarks/graded_mesh.py " + " ".join(sys.argv[1:] if argv is None else argv)
    with ProcessPoolExecutor(max_workers=args.jobs) as pool:
        for row in pool.map(run_case, cases):
            row["command"] = command
            if args.out is not None:
                args.out.parent.mkdir(parents=True, exist_ok=True)
                append_row(args.out, row, echo=True)
            else:
                print(json.dumps(row), flush=True)


if __name__ == "__main__":
    main()

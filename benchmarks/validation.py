"""Physics validation of the paper's baselines (docs/model.md §6), one suite each:

* ``coil`` (issue 3): R0 against the paper's 7.64 L_vb, its convergence in delta and dt,
  independence of the start-up radius R_i, the drag-law option, and the physical sanity
  figures (deposition speed V Hbar, vdW work per length, kinetic energy lost to sticking).
* ``serpentine`` (issue 4): amplitude and wavelength against Abar ~ 30 (26-33) and
  lambdabar ~ 6-8, their convergence in delta and dt, the sliding option (B vs C),
  kappa_c insensitivity, and the flow direction phi = 0.87.

Each case runs the preset to ``--deposit`` L_vb and measures after ``--transient`` L_vb.
Results are cached per case in ``benchmarks/results/<suite>_validation.json``
(re-running skips a finished case only if it ran with the same settings: a case cached
under an older model default is run again), and a markdown table is printed.

    python benchmarks/validation.py coil [--jobs 2] [--cases default,delta_half,...]
    python benchmarks/validation.py serpentine --deposit 1500 --transient 150
"""

from __future__ import annotations

import argparse
import json
import time
from concurrent.futures import ProcessPoolExecutor
from pathlib import Path
from typing import TYPE_CHECKING

from cnt_env.cli.common import name_list
from cnt_env.presets import ENV_MESH, ENV_SIM_DEFAULTS, NEWTON, SURROGATE

if TYPE_CHECKING:
    from cnt_env.sim.deposition import DepositionConfig

RESULTS_DIR = Path(__file__).resolve().parent / "results"
#: the env's speed settings on the stepped substrate (step, solved tail, graded rod)
ENV_STEPPED = {**ENV_SIM_DEFAULTS["stepped"], **ENV_MESH}


def _suite_defaults() -> dict[str, dict]:
    """Each suite's validated configuration: the preset's mesh and start-up arc
    (cnt_env.presets), the simulator's own defaults (DepositionConfig), and for the
    serpentine the paper's kappa_c; no value is copied here."""
    import dataclasses

    from cnt_env.presets import DEFAULT_KAPPA_C, MESH
    from cnt_env.sim.deposition import DepositionConfig

    sim = {f.name: f.default for f in dataclasses.fields(DepositionConfig)}
    # every Newton option of the model (length projection, edge-rotation check, lagged
    # Jacobian, ...), so a case cached before one of them was on is run again
    base = {"dt_factor": sim["dt_factor"], "drag_law": sim["drag_law"], **NEWTON}
    out = {}
    for suite in ("coil", "serpentine"):
        mesh = MESH[suite]
        out[suite] = {"delta_bar": mesh["delta_bar"], "coarse_delta": mesh["coarse_delta"],
                      "fine_length": mesh["fine_length"], **base,
                      "initial_radius": mesh["initial_radius"]}  # fmt: skip
    out["serpentine"].update(sliding=sim["sliding"], phi=0.0, kappa_c_bar=DEFAULT_KAPPA_C,
                             tail_length=sim["tail_length"], vbar=None)  # fmt: skip
    return out


#: the mesh sequence of the delta study (RESULTS.md, issue 12, "The delta study")
DELTA_STUDY = (1.0, 0.5, 0.25, 0.2, 0.125, 0.1)
#: the off-baseline points of the issue-12 configuration study
TREND_POINTS = (("vbar", 0.019), ("vbar", 0.07), ("vbar", 0.12), ("phi", 0.87), ("phi", 1.2),
                ("kappa_c_bar", 0.1))  # fmt: skip

SERPENTINE_CASES: dict[str, dict] = {
    "default": {},
    "sliding_C": {"sliding": "C"},
    # the printed law (the default until round 4's end, now the surrogate) at delta 0.5
    "delta_half": {"drag_law": "printed", "delta_bar": 0.5},
    "dt_half": {"dt_factor": 0.025},
    # dt convergence at the ends of the flow range, where the contact moves fastest
    "vbar_0.019": {"vbar": 0.019},
    "vbar_0.019_dt_half": {"vbar": 0.019, "dt_factor": 0.025},
    "vbar_0.12": {"vbar": 0.12},
    "vbar_0.12_dt_half": {"vbar": 0.12, "dt_factor": 0.025},
    "kappa_c_0.1": {"kappa_c_bar": 0.1},
    "kappa_c_0.4": {"kappa_c_bar": 0.4},
    "phi_0.87": {"phi": 0.87},
    "dt_0.1": {"dt_factor": 0.1},
    "dt_0.2": {"dt_factor": 0.2},
    # the env's faster configuration: 4x the step, 60 L_vb of deposited tail in the solve
    "env_fast": {"dt_factor": 0.2, "tail_length": 60.0},
    # the solved deposited tail (default 195 L_vb = 25 um) shorter and longer, at the ends
    # of the flow range: is 195 converged, and what does a shorter (faster) tail cost?
    **{f"tail_{t:g}": {"tail_length": t} for t in (100.0, 300.0)},
    **{
        f"vbar_{v:g}_tail_{t:g}": {"vbar": v, "tail_length": t}
        for v in (0.019, 0.12)
        for t in (100.0, 300.0)
    },
    # the delta study of the linear law (sliding C), whose coil converges to the paper's
    # R0 as delta falls (COIL_CASES): can one fine delta serve both substrates?
    **{f"linear_delta_{d:g}": {"drag_law": "linear", "delta_bar": d} for d in DELTA_STUDY},
    # ... and the printed law on the same sequence (delta_half is its 0.5)
    **{f"delta_{d:g}": {"drag_law": "printed", "delta_bar": d} for d in (0.25, 0.2)},
    # the trend points of the issue-12 study for the linear law at delta 1 and 0.2
    **{
        f"linear_delta_{d:g}_{k}_{v:g}": {"drag_law": "linear", "delta_bar": d, k: v}
        for d in (1.0, 0.2)
        for k, v in TREND_POINTS
    },
    # the env's speed settings on the surrogate (the printed law at delta 1, what the
    # agents train on) and on the model (the linear law at delta 0.2, the env's default),
    # at the baseline and v = 0.12: what the speed settings cost each model
    **{
        f"{name}env{suffix}": {**model, **ENV_STEPPED, **point}
        for name, model in (
            ("surrogate_", dict(SURROGATE)),
            ("linear_delta_0.2_", {"drag_law": "linear", "delta_bar": 0.2}),
        )
        for suffix, point in (("", {}), ("_vbar_0.12", {"vbar": 0.12}))
    },
}

# name -> overrides of the coil suite's defaults (_suite_defaults)
COIL_CASES: dict[str, dict] = {
    "default": {},
    "delta_1": {"delta_bar": 1.0, "coarse_delta": None},
    # the printed law (the surrogate's) on the delta sequence
    "delta_0.5": {"drag_law": "printed", "delta_bar": 0.5},
    "delta_0.25": {"drag_law": "printed", "delta_bar": 0.25},
    "delta_half": {"delta_bar": 0.0625},
    "dt_half": {"dt_factor": 0.025},
    "Ri_4.8": {"initial_radius": 4.8},
    "Ri_9.6": {"initial_radius": 9.6},
    "printed_drag": {"drag_law": "printed"},
    "printed_drag_delta_1": {"drag_law": "printed", "delta_bar": 1.0, "coarse_delta": None},
    "uniform_0.25": {"delta_bar": 0.25, "coarse_delta": None},
    # the linear law on the serpentine's mesh sequence (SERPENTINE_CASES linear_delta_*),
    # and the printed law at its finest point
    **{f"linear_delta_{d:g}": {"drag_law": "linear", "delta_bar": d} for d in DELTA_STUDY},
    "delta_0.2": {"drag_law": "printed", "delta_bar": 0.2},
}


def case_settings(suite: str, name: str) -> dict:
    """The settings of case ``name``: the suite's defaults with the case's overrides (what
    run_case records and the cache is compared on)."""
    return {**_suite_defaults()[suite], **CASES[suite][name]}


def case_config(suite: str, c: dict) -> DepositionConfig:
    """The DepositionConfig of a case's settings ``c`` (:func:`case_settings`)."""
    from cnt_env.sim.deposition import DepositionConfig
    from cnt_env.sim.stepper import NewtonOptions
    from cnt_env.units import paper_groups

    groups = {"delta_bar": c["delta_bar"]}
    extra = {}
    if suite == "serpentine":
        groups.update(phi=c["phi"], kappa_c_bar=c["kappa_c_bar"])
        if c["vbar"] is not None:  # None: the preset's
            groups["vbar"] = c["vbar"]
        extra["sliding"] = c["sliding"]
        extra["tail_length"] = c["tail_length"]
    return DepositionConfig(
        params=paper_groups(suite, **groups), dt_factor=c["dt_factor"],
        initial_radius=c["initial_radius"], drag_law=c["drag_law"],
        coarse_delta=c["coarse_delta"], fine_length=c["fine_length"],
        newton=NewtonOptions(**{k: c[k] for k in NEWTON}), **extra,
    )  # fmt: skip


def run_case(suite: str, name: str, deposit: float, transient: float) -> dict:
    from cnt_env.patterns import MeasureOptions, measure
    from cnt_env.sim.deposition import DepositionSim

    c = case_settings(suite, name)
    config = case_config(suite, c)
    sim = DepositionSim(config, seed=0)
    t0 = time.perf_counter()
    sim.run(transient)
    mid = sim.stats()
    sim.run(deposit)
    wall = time.perf_counter() - t0
    st = sim.stats()
    laid = st["deposited_length"] - mid["deposited_length"]
    substrate = "stepped" if suite == "serpentine" else "flat"
    # the wavelength along x, the paper's frame (as reproduce.py); until round 4 this
    # measured it along the flow, which differs at phi != 0
    m = measure(sim.trace(), MeasureOptions(transient_length=transient), substrate,
                flow_direction=(1.0, 0.0))  # fmt: skip
    keep = ("pattern", "coil_radius", "coil_radius_spread", "coil_coverage", "amplitude",
            "amplitude_spread", "amplitude_cv", "peak_to_peak", "wavelength",
            "wavelength_spread", "wavelength_cv", "n_uturns", "n_cycles", "n_loops",
            "n_self_crossings")  # fmt: skip
    return {
        "case": name, **c, "deposit": deposit, "transient": transient,
        **{k: m[k] for k in keep},
        # after the transient: deposition speed in units of e_v/(sigma mu H), vdW work per
        # laid length in e_v, kinetic energy discarded by sticking per laid length
        "V_Hbar": laid / (st["time"] - mid["time"]) * config.params.Hbar,
        "vdw_work_per_length": (st["vdw_work"] - mid["vdw_work"]) / laid,
        "sticking_loss_per_length": (st["sticking_loss"] - mid["sticking_loss"]) / laid,
        "steps": st["steps"], "newton_per_step": st["newton_iterations"] / st["steps"],
        "halvings": st["halvings"], "n_nodes": st["n_nodes"], "wall_time_s": wall,
    }  # fmt: skip


def _row(suite: str, name: str, r: dict, ref: dict | None) -> str:
    mesh = f"{r['delta_bar']}{'' if r['coarse_delta'] is None else ' (graded)'}"
    common = f"| {name} | {mesh} | {r['dt_factor']} "
    tail = (f"| {r['V_Hbar']:.3f} | {r['vdw_work_per_length']:.3f} "
            f"| {r['newton_per_step']:.2f} | {r['wall_time_s']:.0f} |")  # fmt: skip
    if suite == "coil":
        rel = f"{100 * (r['coil_radius'] / ref['coil_radius'] - 1):+.1f}%" if ref else "-"
        return (common + f"| {r['initial_radius']} | {r['drag_law']} | {r['coil_radius']:.3f} "
                f"| {100 * (r['coil_radius'] / 7.64 - 1):+.1f}% | {rel} " + tail)  # fmt: skip
    rel_a = f"{100 * (r['amplitude'] / ref['amplitude'] - 1):+.1f}%" if ref else "-"
    rel_w = f"{100 * (r['wavelength'] / ref['wavelength'] - 1):+.1f}%" if ref else "-"
    vbar = r.get("vbar") or "preset"
    return (common + f"| {r['sliding']} | {r['kappa_c_bar']} | {vbar} | {r['phi']} "
            f"| {r['pattern']} "
            f"| {r['amplitude']:.2f} ({rel_a}) | {r['wavelength']:.2f} ({rel_w}) "
            f"| {r['n_cycles']} | {r['n_loops']} | {_drift_ratio(r)} " + tail)  # fmt: skip


def _drift_ratio(r: dict) -> str:
    """lambda V / (4 A vbar) of a serpentine across the steps (phi = 0): one cycle lays
    ~4 A of trace in 4 A / V while the pattern drifts with the flow, so lambda ~ 4 A vbar
    / V and the ratio is ~1 (RESULTS.md, issue 12, "The delta study"); "-" otherwise."""
    from cnt_env.units import paper_groups

    if r["phi"] != 0.0 or not r["amplitude"] > 0:
        return "-"
    vbar = r.get("vbar") or paper_groups("serpentine").vbar
    return f"{r['wavelength'] * r['V_Hbar'] / (4.0 * r['amplitude'] * vbar):.2f}"


CASES = {"coil": COIL_CASES, "serpentine": SERPENTINE_CASES}
HEADERS = {
    "coil": "| case | delta | dt_factor | R_i | drag | R0 | vs 7.64 | vs default |",
    "serpentine": "| case | delta | dt_factor | sliding | kappa_c | vbar | phi | pattern "
    "| amplitude | wavelength | cycles | loops | lambda V / (4 A vbar) |",
}


def _same_settings(args: argparse.Namespace, name: str, cached: dict | None,
                   quiet: bool = False) -> bool:  # fmt: skip
    """Whether ``cached`` ran case ``name`` as it would run now: the suite's current
    defaults with the case's overrides, the same deposit and transient."""
    if cached is None:
        return False
    now = {**case_settings(args.suite, name), "deposit": args.deposit,
           "transient": args.transient}  # fmt: skip
    stale = {k for k, v in now.items() if cached.get(k, None if v is None else "?") != v}
    if stale and not quiet:
        print(f"{name}: cached with other settings ({', '.join(sorted(stale))}), run again")
    return not stale


def main(argv: list[str] | None = None) -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("suite", choices=sorted(CASES))
    parser.add_argument(
        "--cases", type=name_list, default=None, help="comma-separated (default: all)"
    )
    parser.add_argument("--jobs", type=int, default=2)
    parser.add_argument("--deposit", type=float, default=700.0)
    parser.add_argument("--transient", type=float, default=300.0)
    parser.add_argument("--force", action="store_true", help="re-run finished cases")
    parser.add_argument("--results", default=None, help="JSON file (default: per suite)")
    args = parser.parse_args(argv)
    results = Path(args.results or RESULTS_DIR / f"{args.suite}_validation.json")
    done = json.loads(results.read_text()) if results.exists() else {}
    names = args.cases or list(CASES[args.suite])
    todo = [c for c in names if args.force or not _same_settings(args, c, done.get(c))]
    with ProcessPoolExecutor(max_workers=args.jobs) as pool:
        futures = {
            c: pool.submit(run_case, args.suite, c, args.deposit, args.transient) for c in todo
        }
        for name, fut in futures.items():
            done[name] = fut.result()
            results.parent.mkdir(parents=True, exist_ok=True)
            results.write_text(json.dumps(done, indent=1, sort_keys=True))
            print(f"finished {name}", flush=True)
    ref = done.get("default")
    header = HEADERS[args.suite] + " V Hbar | vdW work / length | Newton/step | wall s |"
    print(header)
    print("|" + "---|" * (header.count("|") - 1))
    stale = []
    for name in CASES[args.suite]:
        if name in done and _same_settings(args, name, done[name], quiet=True):
            print(_row(args.suite, name, done[name], ref))
        elif name in done:
            stale.append(name)
    if stale:
        print(f"not shown, cached with other settings (run them to refresh): {', '.join(stale)}")


if __name__ == "__main__":
    main()

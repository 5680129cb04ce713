"""The model's (κ̄_c, v̄) phase diagram past the table's κ̄_c 0.1-0.2 (issue 12).

`benchmarks/reproduce.py` runs the phase diagram at κ̄_c 0.1, 0.15 and 0.2 (where the
paper finds its classes and the collapse). This assembles the wider diagram from those
records and the probe's runs at κ̄_c 0.05, 0.075, 0.3 and 0.4 (the model's defaults,
3000 L_vb per point, 150 dropped, seed 0 unless named), every trace measured again with
today's classifier, and writes a table and a class map:

    cnt-sim sweep --preset serpentine --param kappa-c --values 0.3,0.4,0.2 \
        --param2 vbar --values2 0.019,0.12,0.037 --deposit 3000 --transient 150 --jobs 2 \
        --out benchmarks/results/kappa_phase/sweep.csv \
        --traces benchmarks/results/kappa_phase/traces --plots benchmarks/results/kappa_phase
    cnt-sim sweep --preset serpentine --param kappa-c --values 0.05 \
        --param2 vbar --values2 0.019,0.12,0.037,0.07 --deposit 3000 --transient 150 \
        --jobs 2 --out benchmarks/results/kappa_phase/sweep_low.csv \
        --traces benchmarks/results/kappa_phase/traces_low \
        --plots benchmarks/results/kappa_phase/low
    sh benchmarks/results/kappa_phase/points/run.sh   # single points, a seed, half steps
    python benchmarks/kappa_phase.py                 # this: table.md, phase_map.png
"""

from __future__ import annotations

import argparse
import json
import re
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from benchmarks.reproduce import load_done  # noqa: E402

PROBE = ROOT / "benchmarks" / "results" / "kappa_phase"
REPRODUCE = ROOT / "benchmarks" / "results" / "reproduce" / "results.jsonl"
TRANSIENT = 150.0
SHORT = {"serpentine-coil": "SC", "periodic-serpentine": "P", "irregular-serpentine": "I",
         "too_short": "short", "coil": "coil"}  # fmt: skip
COLOURS = {"SC": "tab:purple", "P": "tab:green", "I": "tab:orange"}


def _name_fields(name: str) -> dict[str, float | int | str]:
    """κ̄_c, v̄, seed and step from a probe file name (the sweep's or run.sh's)."""
    k = re.search(r"(?:kappa_c_bar=|k)([0-9.]+?)_", name)
    v = re.search(r"(?:vbar=|v)([0-9.]+?)(?:_|\.npz)", name)
    seed = re.search(r"seed(\d+)", name)
    return {"kappa_c_bar": float(k.group(1)), "vbar": float(v.group(1)),
            "seed": int(seed.group(1)) if seed else 0,
            "step": "half" if "dt_half" in name else "default"}  # fmt: skip


def probe_records() -> list[dict]:
    """Every probe trace, measured again (the classes of today's classifier)."""
    from cnt_env import runs
    from cnt_env.io import load_trace

    out = []
    paths = sorted(PROBE.glob("traces*/*.npz")) + sorted(PROBE.glob("points/*.npz"))
    for path in paths:
        m = runs.measure(load_trace(path)["trace"], runs.measure_options_for(TRANSIENT),
                         "stepped")  # fmt: skip
        out.append({**_name_fields(path.name), "source": str(path.relative_to(ROOT)),
                    **{k: m.get(k) for k in ("pattern", "amplitude", "wavelength",
                                             "settled_amplitude_cv", "settled_wavelength_cv",
                                             "settled_loop_events", "n_cycles")}})  # fmt: skip
    return out


def reproduce_records() -> list[dict]:
    """The table's κ̄_c rows (0.1, 0.15; 0.2 from the v̄ row): seed 0, default step."""
    out = []
    for r in load_done(REPRODUCE).values():
        if r["row"] in ("phase", "vbar") and r["seed"] == 0 and r["dt_factor"] == 0.05:
            out.append({"kappa_c_bar": r["kappa_c_bar"], "vbar": r["vbar"], "seed": 0,
                        "step": "default", "source": "reproduce/results.jsonl",
                        "pattern": r["pattern"], "amplitude": r["amplitude"],
                        "wavelength": r["wavelength_x"],
                        "settled_amplitude_cv": r.get("settled_amplitude_cv"),
                        "settled_wavelength_cv": r.get("settled_wavelength_cv"),
                        "settled_loop_events": None, "n_cycles": r["n_cycles"]})  # fmt: skip
    return out


def _cell(r: dict | None) -> str:
    if r is None:
        return ""
    return f"{SHORT.get(r['pattern'], r['pattern'])} {r['amplitude']:.1f} / {r['wavelength']:.1f}"


def main(argv: list[str] | None = None) -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--out", type=Path, default=PROBE)
    args = ap.parse_args(argv)
    records = probe_records()
    seen = {(r["kappa_c_bar"], r["vbar"]) for r in records if r["step"] == "default"}
    records += [r for r in reproduce_records() if (r["kappa_c_bar"], r["vbar"]) not in seen]
    main_grid = {(r["kappa_c_bar"], r["vbar"]): r for r in records
                 if r["step"] == "default" and r["seed"] == 0}  # fmt: skip
    kappas = sorted({k for k, _ in main_grid})
    vbars = sorted({v for _, v in main_grid if v >= 0.019})
    lines = ["| κ̄_c \\ v̄ | " + " | ".join(f"{v:g}" for v in vbars) + " |",
             "|---" * (len(vbars) + 1) + "|"]  # fmt: skip
    for k in kappas:
        lines.append(f"| {k:g} | " + " | ".join(_cell(main_grid.get((k, v))) for v in vbars) + " |")
    lines += ["", "Class Ā / λ̄_x, seed 0, default step. Other runs:", ""]
    for r in records:
        if r["step"] != "default" or r["seed"] != 0:
            lines.append(f"- κ̄_c {r['kappa_c_bar']:g}, v̄ {r['vbar']:g}, seed {r['seed']}, "
                         f"{r['step']} step: {_cell(r)}")  # fmt: skip
    table = "\n".join(lines) + "\n"
    args.out.mkdir(parents=True, exist_ok=True)
    (args.out / "table.md").write_text(table)
    (args.out / "records.json").write_text(json.dumps(records, indent=1) + "\n")
    print(table)

    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, ax = plt.subplots(figsize=(7, 4.5))
    for (k, v), r in main_grid.items():
        if v < 0.019:
            continue
        c = SHORT.get(r["pattern"], "?")
        ax.scatter(kappas.index(k), vbars.index(v), s=900, marker="s",
                   color=COLOURS.get(c, "lightgrey"))  # fmt: skip
        ax.annotate(f"{c}\n{r['amplitude']:.0f}", (kappas.index(k), vbars.index(v)),
                    ha="center", va="center", fontsize=8)  # fmt: skip
    ax.set_xticks(range(len(kappas)), [f"{k:g}" for k in kappas])
    ax.set_yticks(range(len(vbars)), [f"{v:g}" for v in vbars])
    title = "the model's classes (SC serpentine-coil, P periodic, I irregular) and Ā"
    ax.set(xlabel="κ̄_c", ylabel="v̄", xlim=(-0.6, len(kappas) - 0.4),
           ylim=(-0.6, len(vbars) - 0.4), title=title)  # fmt: skip
    fig.tight_layout()
    fig.savefig(args.out / "phase_map.png", dpi=110)
    print(f"wrote {args.out / 'table.md'}, {args.out / 'phase_map.png'}")


if __name__ == "__main__":
    main()

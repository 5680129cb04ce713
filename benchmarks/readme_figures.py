"""The README's serpentine figure, from traces committed with the reproduction runs.

    python benchmarks/readme_figures.py        # writes docs/serpentines.png

No simulation: it plots ``benchmarks/results/reproduce/traces`` (the default
configuration, dt_factor 0.05, 3000 L_vb per point), the last ``--window``
L_vb of each, with the amplitude and wavelength that ``cnt_env.patterns`` measures on
the whole trace (the numbers of ``benchmarks/RESULTS.md``, issue 12).
"""

from __future__ import annotations

import argparse
from pathlib import Path

import numpy as np

from cnt_env.patterns import MeasureOptions, arc_length, measure
from cnt_env.plotting.topview import lvb_in_um

ROOT = Path(__file__).resolve().parents[1]
RESULTS = ROOT / "benchmarks" / "results"
# the table's serpentine run (reproduce.SERPENTINE_RUN, 150 dropped), the model's mesh,
# tolerance, length projection, edge-rotation check and lagged Jacobian (presets)
_MESH = (
    "run=3000-150__coarse=4_fine=20_tol=1e-05_proj=0.02_rot=30_lag__drag_law=linear__delta_bar=0.2"
)
PANELS = (
    (f"reproduce/traces/default__serpentine__vbar=0.005__{_MESH}.npy", "v̄ = 0.005, φ = 0"),
    (
        f"reproduce/traces/default__serpentine__vbar=0.037__{_MESH}.npy",
        "v̄ = 0.037, φ = 0 (baseline)",
    ),
    (f"reproduce/traces/default__serpentine__vbar=0.12__{_MESH}.npy", "v̄ = 0.12, φ = 0"),
    (f"reproduce/traces/default__serpentine__phi=0.87__{_MESH}.npy", "v̄ = 0.037, φ = 0.87"),
)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--window", type=float, default=1000.0, help="L_vb of trace shown")
    ap.add_argument("--out", type=Path, default=ROOT / "docs" / "serpentines.png")
    args = ap.parse_args()

    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    shown, labels = [], []
    for rel, title in PANELS:
        trace = np.load(RESULTS / rel)
        m = measure(trace, MeasureOptions(transient_length=150.0), substrate="stepped")
        arc = arc_length(trace)
        shown.append(trace[arc >= arc[-1] - args.window])
        labels.append(
            f"{title}\n{m['pattern']}\nA = {m['amplitude']:.1f}, λ_x = {m['wavelength']:.1f}"
        )
    # equal aspect in every panel: widths in proportion to each trace's x/z extent
    spans = [np.ptp(t, axis=0) + 4.0 for t in shown]
    ratios = [max(float(s[0] / s[1]), 0.7) for s in spans]
    fig, axes = plt.subplots(
        1, len(PANELS), figsize=(3.2 * sum(ratios) + 2.0 * len(PANELS), 4.6),
        gridspec_kw={"width_ratios": ratios},
    )  # fmt: skip
    for ax, trace, label in zip(axes, shown, labels, strict=True):
        ax.plot(trace[:, 0], trace[:, 1], lw=0.7, color="#1f4e79")
        ax.plot(*trace[-1], "o", color="#c0392b", ms=4)
        ax.set_aspect("equal", adjustable="datalim")
        ax.set_xlabel("x / L_vb")
        ax.set_title(label, fontsize=9)
    axes[0].set_ylabel("z / L_vb (along the steps)")
    um = lvb_in_um("stepped")
    fig.suptitle(
        f"Deposited traces, last {args.window:g} L_vb; flow along +x at φ = 0; "
        f"1 L_vb = {um:.3f} µm; red: the contact point"
    )
    fig.tight_layout()
    args.out.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(args.out, dpi=110)
    print(args.out)


if __name__ == "__main__":
    main()

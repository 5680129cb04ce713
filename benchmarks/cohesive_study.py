"""The cohesive adhesion's convergence: the coil's R0 against its range h and the mesh.

The cohesive pull (docs/model.md §4, ``ContactOptions.adhesion="cohesive"``) has one
length of its own, the range h of the vdW attraction. This runs the coil point of the
reproduction table (``reproduce.py``, 1500 L_vb with 900 dropped) with the candidate
``C_cohesive`` at each ``h:delta`` given, and ``eq1:delta`` for eq. 1 (candidate
``C_fine`` at that delta), one JSON line per point:

    python benchmarks/cohesive_study.py 0.2:0.2 0.1:0.2 0.05:0.2 0.05:0.1 0.025:0.1 \
        0.05:0.05 --out benchmarks/results/cohesive_study.jsonl

and at H = 100, where the cohesive contact lays no coil:

    python benchmarks/cohesive_study.py 0.1:0.2 0.05:0.1 eq1:0.2 --Hbar 100 \
        --out benchmarks/results/cohesive_study.jsonl

and with the paper's printed drag law (rows with "drag_law": "printed"; rows without
the key ran before it existed, with the linear law):

    python benchmarks/cohesive_study.py 0.05:0.2 0.05:0.1 --drag-law printed \
        --out benchmarks/results/cohesive_study.jsonl

(A range below delta^2 is refused by DepositionConfig: the mesh cannot resolve it.)
"""

from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from benchmarks import reproduce  # noqa: E402
from cnt_env.jsonl import append_row  # noqa: E402


def coil_point(
    h: float | None, delta: float, hbar: float | None = None, drag_law: str = "linear"
) -> dict:
    """R0 of the coil point with the cohesive range ``h`` (None: eq. 1) at ``delta``: the
    baseline, or the ``coil_groups`` point at ``hbar``; ``drag_law`` as in the model."""
    base = "C_fine" if h is None else "C_cohesive"
    name = f"{base}_h{h}_d{delta}_{drag_law}"
    reproduce.CANDIDATES[name] = dict(
        reproduce.CANDIDATES[base], delta_bar=delta, drag_law=drag_law
    )
    if h is not None:
        reproduce.CANDIDATES[name]["cohesive_range"] = h
    rows = reproduce.rows()
    point = (
        rows["coil"][0]
        if hbar is None
        else next(p for p in rows["coil_groups"] if p["groups"] == {"Hbar": hbar})
    )
    rec = reproduce.run_point(point, name, None, None, 0)["record"]
    return {"adhesion": "eq1" if h is None else "cohesive", "cohesive_range": h,
            "drag_law": drag_law, "delta_bar": delta, "Hbar": rec["Hbar"],
            "pattern": rec["pattern"], "R0": rec["coil_radius"],
            "wall_s": rec["wall_s"], "error": rec["error"]}  # fmt: skip


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("points", nargs="+", help="h:delta (h = eq1 for eq. 1)")
    ap.add_argument(
        "--Hbar",
        type=float,
        default=None,
        help="the coil_groups point at this Hbar (100-400) instead of the baseline",
    )
    ap.add_argument("--drag-law", choices=("linear", "printed"), default="linear",
                    help="the drag law (linear: the model's, C_fine / C_cohesive)")  # fmt: skip
    ap.add_argument("--out", type=Path, default=None, help="append JSON lines here")
    args = ap.parse_args(argv)
    for spec in args.points:
        h, delta = spec.split(":")
        row = coil_point(None if h == "eq1" else float(h), float(delta), args.Hbar, args.drag_law)
        if args.out is not None:
            append_row(args.out, row, echo=True)
        else:
            print(json.dumps(row), flush=True)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())

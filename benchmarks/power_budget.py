"""Where the adhesion energy goes: the power budget of the deposition, per unit length laid.

The deposition speed V sets the serpentine's wavelength (lambda = 4 A vbar / V,
benchmarks/RESULTS.md, issue 12, "The delta study"), and V falls as the contact is refined
(linear law: V Hbar 0.66 at delta 1, 0.49 at 0.2). This splits the vdW work of paper eq. 1
(e_v per unit length laid, by construction) into where it is dissipated, after each
implicit step of a run past its start-up:

- the drag on the suspended rod (its edges from the contact edge up), split into its
  axial part sigma mu |t . v_r|^2 and its normal part C_sigma mu |v_r - (t . v_r) t|^2
  per unit length, and into the part within ``--near`` L_vb of arc from the contact and
  the rest;
- the drag on the deposited edges that still move (stepped substrate: the sliding tail);
- the power the flow puts in: sum of v_flow . F over the edges (F the drag on the edge,
  v_r = v_flow - edge velocity, implicit-Euler velocities as in the solve), so that
  power into the rod = flow power - dissipation;
- the rest, vdW work + power into the rod - change of elastic and kinetic energy, split
  into the energy jumps of the discrete events between the solves (each measured around
  its call: the snap of deposited edges to the steps, the deposit of a touched-down node,
  the injection at the top, the split of long edges near the contact, the deletion of
  the far tail) and the implicit solves' own dissipation (rest = solve dissipation -
  jumps), which is also binned by the steps since the last touchdown.

Linear drag law only (the model's). Every figure is per unit length laid, in e_v.

    python benchmarks/power_budget.py --preset serpentine --delta 1,0.5,0.2 \
        --out benchmarks/results/power_budget.jsonl
"""

from __future__ import annotations

import argparse
import itertools
import json
import sys
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from cnt_env.cli.common import float_list  # noqa: E402
from cnt_env.jsonl import append_row  # noqa: E402
from cnt_env.sim.deposition import ContactOptions  # noqa: E402


def edge_drag_powers(sim, near: float) -> dict[str, float]:
    """The drag powers of the current step (module doc), summed over the edges with drag."""
    rod = sim.rod
    n = rod.n_nodes
    x = rod.nodes
    u = rod.node_velocities
    e = x[1:] - x[:-1]
    ln = np.linalg.norm(e, axis=1)
    t = e / ln[:, None]
    vr = rod.flow[None, :] - 0.5 * (u[1:] + u[:-1])
    tv = np.einsum("ij,ij->i", t, vr)
    normal = vr - tv[:, None] * t
    d = rod.drag
    coef = rod.rest_lengths[: n - 1] * d.mu
    on = rod.drag_on[: n - 1].astype(bool)
    force = coef[:, None] * (d.c_sigma * vr + (d.sigma - d.c_sigma) * tv[:, None] * t)
    axial = coef * d.sigma * tv**2
    norm_ = coef * d.c_sigma * np.einsum("ij,ij->i", normal, normal)
    flow_in = force @ rod.flow
    c = sim.contact_node
    j = np.arange(n - 1)
    suspended = (j >= c - 1) & on
    deposited = (j < c - 1) & on
    arc = np.concatenate([[0.0], np.cumsum(ln)])
    near_mask = suspended & (arc[1:] - arc[c] <= near)
    out = {
        "susp_axial": float(axial[suspended].sum()),
        "susp_normal": float(norm_[suspended].sum()),
        "susp_near": float((axial + norm_)[near_mask].sum()),
        "deposited": float((axial + norm_)[deposited].sum()),
        "flow_in": float(flow_in[on].sum()),
    }
    # power the drag puts into the rod: the flow's power less the dissipation
    out["into_rod"] = out["flow_in"] - out["susp_axial"] - out["susp_normal"] - out["deposited"]
    return out


def budget(preset: str, delta: float, transient: float, window: float, near: float,
           seed: int = 0, **changes) -> dict:  # fmt: skip
    """Run ``preset`` at ``delta`` past ``transient`` L_vb, then integrate the budget
    over ``window`` L_vb laid."""
    from cnt_env.sim.deposition import DepositionSim, default_config

    config = default_config(preset, delta_bar=delta, **changes)
    if config.drag_law != "linear":
        raise ValueError("the power budget is written for the linear drag law")
    sim = DepositionSim(config, seed=seed)
    t0 = time.perf_counter()
    sim.run(transient)
    rod = sim.rod

    def mechanical() -> float:
        return rod.elastic_energy() + rod.kinetic_energy()

    l0, w0, time0 = sim.deposited_length, sim.vdw_work, sim.time
    e0 = mechanical()
    sums = dict.fromkeys(("susp_axial", "susp_normal", "susp_near", "deposited", "flow_in",
                          "into_rod"), 0.0)  # fmt: skip
    sticking0 = sim.sticking_loss
    # the events' energy jumps (module doc), each measured around the call that makes it
    jumps = dict.fromkeys(("snap", "deposit", "inject", "refine", "delete"), 0.0)

    def measured(name: str, call):
        def wrapper(*args):
            before = mechanical()
            out = call(*args)
            jumps[name] += mechanical() - before
            return out

        return wrapper

    # (the substrate is a frozen dataclass: set the wrapper on this instance only)
    object.__setattr__(sim.substrate, "after_step", measured("snap", sim.substrate.after_step))
    for name in ("deposit", "inject", "refine", "delete"):
        attr = "_settle_contact" if name == "deposit" else f"_{name}"
        setattr(sim, attr, measured(name, getattr(sim, attr)))
    # the solves' dissipation step by step, by the steps since the last touchdown (0: the
    # step that deposits a node; 1: the next, the first under the pull on the new
    # contact node)
    by_since = dict.fromkeys(("0", "1", "2-3", "4+"), 0.0)
    since, e_prev = 4, e0
    while sim.deposited_length < l0 + window:
        w_prev, j_prev, laid_prev = sim.vdw_work, sum(jumps.values()), sim.deposited_length
        taken = sim.step()
        powers = edge_drag_powers(sim, near)
        for k, v in powers.items():
            sums[k] += v * taken
        e_now = mechanical()
        solve = (sim.vdw_work - w_prev + powers["into_rod"] * taken
                 - (e_now - e_prev - (sum(jumps.values()) - j_prev)))  # fmt: skip
        e_prev = e_now
        since = 0 if sim.deposited_length > laid_prev else since + 1
        key = "0" if since == 0 else "1" if since == 1 else "2-3" if since <= 3 else "4+"
        by_since[key] += solve
    laid = sim.deposited_length - l0
    e1 = mechanical()
    vdw = sim.vdw_work - w0
    rest = vdw + sums["into_rod"] - (e1 - e0)
    per = {k: v / laid for k, v in sums.items()}
    p = config.params
    return {
        "preset": preset,
        "delta_bar": delta,
        "vbar": p.vbar,
        "phi": p.phi,
        "seed": seed,
        "dt_factor": config.dt_factor,
        "adhesion": config.contact.adhesion,
        "cohesive_range": config.contact.cohesive_range if sim.cohesive else None,
        "transient": transient,
        "laid": laid,
        "near": near,
        "V_Hbar": laid / (sim.time - time0) * p.Hbar,
        "vdw_work": vdw / laid,
        "drag_suspended_axial": per["susp_axial"],
        "drag_suspended_normal": per["susp_normal"],
        "drag_suspended_near_contact": per["susp_near"],
        "drag_deposited": per["deposited"],
        "flow_power_in": per["flow_in"],
        "into_rod_by_drag": per["into_rod"],
        "mechanical_energy_change": (e1 - e0) / laid,
        "sticking_loss": (sim.sticking_loss - sticking0) / laid,
        "rest": rest / laid,
        **{f"jump_{k}": v / laid for k, v in jumps.items()},
        # the implicit solves' own dissipation: rest = solve dissipation - event jumps
        "solve_dissipation": (rest + sum(jumps.values())) / laid,
        **{f"solve_dissipation_since_touchdown_{k}": v / laid for k, v in by_since.items()},
        "wall_s": round(time.perf_counter() - t0, 1),
    }


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--preset", default="serpentine", choices=("serpentine", "coil"))
    ap.add_argument(
        "--delta", type=float_list, default="1,0.5,0.2", help="comma separated delta_bar values"
    )
    ap.add_argument(
        "--vbar", type=float_list, default=None, help="comma separated vbar values (serpentine)"
    )
    ap.add_argument(
        "--transient",
        type=float,
        default=None,
        help="L_vb laid before the budget (default: 150 serpentine, 300 coil)",
    )
    ap.add_argument("--window", type=float, default=300.0, help="L_vb laid in the budget")
    ap.add_argument(
        "--near", type=float, default=5.0, help="arc (L_vb) from the contact counted as near it"
    )
    ap.add_argument(
        "--dt-factor",
        type=float,
        default=None,
        help="time step factor (default: the preset's, 0.05)",
    )
    ap.add_argument(
        "--adhesion",
        default="eq1",
        choices=("eq1", "cohesive"),
        help="the adhesion model (deposition.ContactOptions.adhesion)",
    )
    ap.add_argument(
        "--cohesive-range",
        type=float_list,
        default="0.05",
        help="comma separated ranges h of the cohesive adhesion, L_vb",
    )
    ap.add_argument("--out", type=Path, default=None, help="append JSON lines here")
    args = ap.parse_args(argv)
    transient = args.transient
    if transient is None:
        transient = 150.0 if args.preset == "serpentine" else 300.0
    vbars = [None] if args.vbar is None else args.vbar
    ranges = [None] if args.adhesion == "eq1" else args.cohesive_range
    for delta, vbar, h in itertools.product(args.delta, vbars, ranges):
        changes: dict = {} if vbar is None else {"vbar": vbar}
        if args.dt_factor is not None:
            changes["dt_factor"] = args.dt_factor
        if h is not None:
            changes["contact"] = ContactOptions(adhesion="cohesive", cohesive_range=h)
        row = budget(args.preset, delta, transient, args.window, args.near, **changes)
        if args.out is not None:
            append_row(args.out, row, echo=True)
        else:
            print(json.dumps(row), flush=True)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())

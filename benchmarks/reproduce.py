"""Reproduce the paper's sweeps (issue 12): coils, the (kappa_c, vbar) phase diagram with
Abar(vbar) and lambda(vbar), Abar/lambda against Hbar, Ibar and phi, and the model
configuration study.

    python benchmarks/reproduce.py [--jobs 2] [--backend local|ray] [--quick] [--only ROW]
                                   [--candidate NAME] [--out DIR] [--dt-factor F]
                                   [--max-wall S] [--point K=V[,K=V]] [--seeds 0,1,2]

Resumable: every finished point is one JSON line in ``DIR/results.jsonl``; points already
there (same key: the point, its mesh and Newton tolerance) are skipped. Parallel over a
ProcessPoolExecutor (spawn context), or Ray tasks with ``--backend ray`` (a local
instance of ``--jobs`` CPUs, ``cnt_env.sweep.ray_session``; ``--max-wall`` applies to the
local backend only). The whole default table: 28 points in ~13 min with ``--jobs 2``. At the
end it writes ``DIR/summary.md`` (model against paper wherever the paper gives a number)
and figures ``DIR/*.png``. ``--candidate`` runs the rows with one of the named model
configurations of CANDIDATES (the configuration study); the default is the configuration
``default_config`` carries (presets.py). ``--point`` picks single points by their
groups; ``--seeds`` runs each point once per seed of the start-up perturbation, and the
summary then gives the seeds' spread and judges a change of the step against it (a
pattern that scatters with its start-up is converged in dt when its mean moves less than
the seeds' standard error says it may). Uses the library directly (no CLI).
"""

from __future__ import annotations

import argparse
import json
import math
import multiprocessing
import os
import re
import sys
import time
from collections.abc import Sequence
from concurrent.futures import ProcessPoolExecutor, as_completed
from pathlib import Path
from typing import Any

ROOT = Path(__file__).resolve().parents[1]
if str(ROOT) not in sys.path:
    sys.path.insert(0, str(ROOT))

from cnt_env.cli.common import seed_list  # noqa: E402
from cnt_env.jsonl import JsonlError, append_row, read_rows  # noqa: E402

#: Named model configurations of the study (DepositionConfig fields). "default" is
#: whatever presets.py / DepositionConfig carry; the others name what they change.
CANDIDATES: dict[str, dict[str, Any]] = {
    "default": {},
    # issue 12's starting point: linear drag, x fixed (B), jump snap, z clamped tail
    "today": {
        "drag_law": "linear",
        "sliding": "B",
        "snap": "jump",
        "friction": 0.0,
        "tail_clamp": "xyz",
    },
    # the paper as printed: eq. 2 drag, delta ~ L_vb, deposited on penetrating y = 0
    "printed": {
        "drag_law": "printed",
        "sliding": "B",
        "snap": "jump",
        "friction": 0.0,
        "tail_clamp": "xyz",
        "contact_mode": "project",
    },
    "C": {
        "drag_law": "linear",
        "sliding": "C",
        "snap": "jump",
        "friction": 0.0,
        "tail_clamp": "xyz",
    },
    "C_penalty": {
        "drag_law": "linear",
        "sliding": "C",
        "snap": "penalty",
        "friction": 0.0,
        "tail_clamp": "xyz",
    },
    "C_tail60": {
        "drag_law": "linear",
        "sliding": "C",
        "snap": "jump",
        "friction": 0.0,
        "tail_clamp": "xyz",
        "tail_length": 60.0,
    },
    # C on a fine mesh, both substrates (the delta study: its amplitude and the coil's R0
    # converge in delta; RESULTS.md issue 12, "The delta study")
    "C_fine": {
        "drag_law": "linear",
        "sliding": "C",
        "snap": "jump",
        "friction": 0.0,
        "tail_clamp": "xyz",
        "delta_bar": 0.2,
    },
    # C_fine with the cohesive adhesion (docs/model.md §4): the vdW pull of finite range
    # on every free node near the substrate instead of eq. 1's jump from node to node
    "C_cohesive": {
        "drag_law": "linear",
        "sliding": "C",
        "snap": "jump",
        "friction": 0.0,
        "tail_clamp": "xyz",
        "delta_bar": 0.2,
        "adhesion": "cohesive",
        "cohesive_range": 0.05,
    },
    "printed_C": {
        "drag_law": "printed",
        "sliding": "C",
        "snap": "jump",
        "friction": 0.0,
        "tail_clamp": "xyz",
    },
    # sliding along z without a z clamp: the trace may translate along the steps
    "B_free": {
        "drag_law": "linear",
        "sliding": "B",
        "snap": "jump",
        "friction": 0.0,
        "tail_clamp": "xy",
    },
    "B_free_printed": {
        "drag_law": "printed",
        "sliding": "B",
        "snap": "jump",
        "friction": 0.0,
        "tail_clamp": "xy",
    },
    "C_free": {
        "drag_law": "linear",
        "sliding": "C",
        "snap": "jump",
        "friction": 0.0,
        "tail_clamp": "xy",
    },
    "B_penalty": {
        "drag_law": "linear",
        "sliding": "B",
        "snap": "penalty",
        "friction": 0.0,
        "tail_clamp": "xyz",
    },
    "B_constraint": {
        "drag_law": "linear",
        "sliding": "B",
        "snap": "constraint",
        "friction": 0.0,
        "tail_clamp": "xyz",
    },
    "B_friction10": {
        "drag_law": "linear",
        "sliding": "B",
        "snap": "jump",
        "friction": 10.0,
        "tail_clamp": "xy",
    },
    "B_friction1": {
        "drag_law": "linear",
        "sliding": "B",
        "snap": "jump",
        "friction": 1.0,
        "tail_clamp": "xy",
    },
    "none": {
        "drag_law": "linear",
        "sliding": "none",
        "snap": "jump",
        "friction": 0.0,
        "tail_clamp": "xyz",
    },
}
# C_cohesive with the paper's printed drag: eq. 2 as printed on a converged mesh with a
# contact that loses no energy (R0 converges in delta with it, 8.27 / 8.29 at delta 0.2 /
# 0.1, where eq. 1 drifts 7.9 -> 9.2 from delta 1 to 0.2)
CANDIDATES["printed_cohesive"] = dict(CANDIDATES["C_cohesive"], drag_law="printed")
# C_fine with sliding B (x fixed, z free): the sliding the paper's main text describes
# ("may slide" along the steps) at the converged delta; the coil, on the flat sticky
# substrate, is C_fine's (RESULTS.md, issue 12, "Sliding B on the converged mesh")
CANDIDATES["B_fine"] = dict(CANDIDATES["C_fine"], sliding="B")
# C_cohesive with sliding B: the contact that loses no energy (its wavelength in the
# paper's band) with the sliding that lowers the amplitude on the steps (RESULTS.md,
# issue 12, "Sliding B with the cohesive contact")
CANDIDATES["B_cohesive"] = dict(CANDIDATES["C_cohesive"], sliding="B")
# B_fine and C_fine with a viscous friction on the deposited nodes' sliding (eta in units
# of mu per unit length; -eta l u on each sliding DOF, docs/model.md §4): a substrate
# between the frictionless steps (eta 0) and the flat sticky one (eta -> inf); the flat
# substrate, and so the coil, is unchanged (RESULTS.md, issue 12, "Friction on the steps")
CANDIDATES["B_fine_friction10"] = dict(CANDIDATES["B_fine"], friction=10.0)
for _eta in (10.0, 100.0):
    CANDIDATES[f"C_fine_friction{_eta:g}"] = dict(CANDIDATES["C_fine"], friction=_eta)
# C_fine with deposited nodes held in x and z (no sliding): the limit of C as eta -> inf
CANDIDATES["none_fine"] = dict(CANDIDATES["C_fine"], sliding="none")
# C_fine with the critical-curvature rule's length fixed at the paper's delta ~ L_vb
# instead of the edge's (substrate.Stepped.snap_length): the rule's window for a straight
# edge, kappa_c l, is then the paper's on the model's finer mesh (RESULTS.md, issue 12,
# "The snap rule's length")
CANDIDATES["C_fine_snap1"] = dict(CANDIDATES["C_fine"], snap_length=1.0)
# C_fine in a linear boundary layer, the flow vbar y / Hbar (DepositionConfig.flow_profile;
# vbar at the rod's top) instead of the paper's uniform flow (RESULTS.md, issue 12, "A
# boundary layer: the pattern follows the flow at the rod's top")
CANDIDATES["C_fine_shear"] = dict(CANDIDATES["C_fine"], flow_profile="linear")

SERP = "serpentine"
COIL = "coil"


def _point(row: str, preset: str, run: tuple[float, float] | None = None,
           **groups: Any) -> dict[str, Any]:  # fmt: skip
    """A point: ``groups`` changed from the preset; ``run`` = (deposit, transient) L_vb
    when the point needs a longer run than the preset's (``--deposit`` overrides it)."""
    point: dict[str, Any] = {"row": row, "preset": preset, "groups": groups}
    if run is not None:
        point["run"] = run
    return point


#: L_vb each serpentine point deposits (the preset's ``RUN_DEPOSIT``): the pattern classes
#: need >= 10 cycles to call a serpentine periodic
#: (patterns.MeasureOptions.periodic_min_cycles), and at 1500 L_vb the model's baseline
#: lays 9 (a cycle is ~4A + lambda of trace: ~150 L_vb at A = 34) and v̄ = 0.019 only 6,
#: so most points came out "too_short". The surrogate's table
#: (benchmarks/results/reproduce_surrogate) ran at 4000; ``--serpentine-run 1500`` is the
#: earlier length (the Δt and seed studies of benchmarks/results/reproduce_1500 and
#: C_fine's table, benchmarks/results/reproduce_C_fine, ran at it).
SERPENTINE_RUN = 3000.0
#: (deposit, transient) of the serpentine preset's run when the 1500 L_vb table
#: (benchmarks/results/reproduce_1500) ran: its point keys name no run, and a point at this
#: run still gets those keys.
LEGACY_SERPENTINE_RUN = (1500.0, 150.0)


def rows(quick: bool = False, serpentine_run: float = SERPENTINE_RUN
         ) -> dict[str, list[dict[str, Any]]]:  # fmt: skip
    """The points of each row (dimensionless groups changed from the preset); serpentine
    points deposit ``serpentine_run`` L_vb (the preset's transient dropped)."""
    from cnt_env.presets import RUN_DEPOSIT, RUN_TRANSIENT

    if quick:
        return {
            "coil": [_point("coil", COIL)],
            "vbar": [_point("vbar", SERP, vbar=v) for v in (0.037, 0.12)],
            "phi": [_point("phi", SERP, phi=1.2)],
        }
    serp_run = (serpentine_run, RUN_TRANSIENT[SERP])

    def _pt(row: str, preset: str, run: tuple[float, float] | None = None,
            **groups: Any) -> dict[str, Any]:  # fmt: skip
        return _point(row, preset, serp_run if preset == SERP else run, **groups)

    # in priority order: a run cut short by --max-wall has the paper's headline rows
    out: dict[str, list[dict[str, Any]]] = {}
    # the coil's run named in its key, so a change of the preset's run runs it again
    out["coil"] = [_pt("coil", COIL, (RUN_DEPOSIT[COIL], RUN_TRANSIENT[COIL]))]
    out["vbar"] = [_pt("vbar", SERP, vbar=v) for v in (0.037, 0.019, 0.07, 0.12, 0.005, 0.05, 0.1)]
    out["phi"] = [_pt("phi", SERP, phi=f) for f in (1.2, 0.87, 1.45, 0.44)]
    out["phase"] = [
        _pt("phase", SERP, kappa_c_bar=k, vbar=v)
        for k in (0.1, 0.15)
        for v in (0.037, 0.019, 0.07, 0.12)
    ]
    # (the later values of each row were added in round 3's last session, for the curves)
    out["Hbar"] = [_pt("Hbar", SERP, Hbar=h) for h in (100.0, 250.0, 200.0, 400.0)]
    out["Ibar"] = [_pt("Ibar", SERP, Ibar=i) for i in (100.0, 1000.0, 30.0, 3000.0)]
    # off the baseline the start-up lasts longer (~1000 L_vb at Hbar = 150): 2500 L_vb,
    # the first 1200 dropped
    long = (2500.0, 1200.0)
    out["coil_groups"] = [
        _pt("coil_groups", COIL, long, Hbar=h) for h in (150.0, 400.0, 100.0, 200.0, 300.0)
    ] + [_pt("coil_groups", COIL, long, Ibar=i) for i in (700.0, 7000.0, 300.0, 1500.0, 4000.0)]
    # coils against L_vb (issue 12: "coils against L_vb, H and I"): the substrate's
    # adhesion e_v changed at the paper's tube, height and gas (lvb_groups)
    out["coil_Lvb"] = [_pt("coil_Lvb", COIL, long, **lvb_groups(r)) for r in LVB_RATIOS]
    return out


#: L_vb / L_vb of the paper's flat graphite on the coil_Lvb row: e_v = 4.39e-10 J/m / r^2,
#: 1.78x down to 0.25x the graphite's adhesion (the stepped quartz's 1.64e-10 is r = 1.64)
LVB_RATIOS = (0.75, 1.25, 1.5, 2.0)


def lvb_groups(ratio: float) -> dict[str, float]:
    """The coil preset's groups with the vdW-bending length L_vb = sqrt(k_b / e_v) times
    ``ratio``, by a change of the adhesion e_v alone (k_b, H, rho, mu, k_s, r0 the
    paper's): e_v -> e_v / ratio^2, so H/L_vb and r0/L_vb scale as 1/ratio, Ibar =
    rho e_v^2 / (k_b mu^2) as 1/ratio^4 and k_s/e_v as ratio^2 (docs/model.md §2). In
    SI, a coil of radius R0_bar is R0_bar * ratio * L_vb(graphite) micrometres."""
    from cnt_env import units

    g = units.paper_groups(COIL)
    return {
        "Hbar": g.Hbar / ratio,
        "Ibar": g.Ibar / ratio**4,
        "ks_over_ev": g.ks_over_ev * ratio**2,
        "r0_bar": g.r0_bar / ratio,
    }


def lvb_ratio(rec: dict[str, Any]) -> float:
    """L_vb of a record over the coil preset's: the coil_Lvb row changes it (H fixed, so
    it is Hbar_preset / Hbar), every other row keeps its substrate's."""
    from cnt_env import units

    if rec.get("row") != "coil_Lvb":
        return 1.0
    return units.paper_groups(COIL).Hbar / rec["Hbar"]


def lvb_um(rec: dict[str, Any]) -> float:
    """L_vb of a record in micrometres: its substrate's for the paper's tube
    (units.preset), times lvb_ratio."""
    from cnt_env import units

    return units.preset(rec["preset"]).L_vb * 1e6 * lvb_ratio(rec)


def lvb_points(recs: list[dict[str, Any]]) -> list[dict[str, Any]]:
    """The coils against L_vb: the baseline coil and the coil_Lvb row, by L_vb."""
    return sorted((r for r in recs if r["row"] in ("coil", "coil_Lvb")), key=lvb_ratio)


#: the study's screening rows (issue 12: v row, phi row, kappa_c row), most telling first
STUDY_POINTS = (
    [_point("vbar", SERP, vbar=v) for v in (0.019, 0.12)]
    + [_point("phi", SERP, phi=1.2), _point("vbar", SERP, vbar=0.037)]
    + [_point("vbar", SERP, vbar=0.07)]
    + [_point("phi", SERP, phi=f) for f in (0.87, 0.44)]
    + [_point("phase", SERP, kappa_c_bar=k, vbar=0.037) for k in (0.1, 0.15)]
)
#: the discretisation finding: the baseline at finer delta (uniform 0.5; graded 0.125 near
#: the contact as on the coil preset, 1 above)
DELTA_POINTS = [
    _point("delta", SERP, delta_bar=0.5),
    _point("delta", SERP, delta_bar=0.125, coarse_delta=1.0),
]

#: What the paper gives (docs/model.md §6): (row, key) -> (quantity, value, note)
PAPER: list[tuple[str, dict[str, float], str, float, str]] = [
    ("coil", {}, "coil_radius", 7.64, "R0 = 7.64 (+-0.01)"),
    ("vbar", {"vbar": 0.037}, "amplitude", 30.0, "baseline A ~ 30 (26-33)"),
    ("vbar", {"vbar": 0.037}, "wavelength_x", 7.0, "baseline lambda ~ 6-8"),
    ("vbar", {"vbar": 0.005}, "amplitude", 100.0, "A ~ 100 as vbar -> 0 (Fig. 4b)"),
    ("vbar", {"vbar": 0.005}, "wavelength_x", 4.0, "lambda ~ 4 as vbar -> 0 (Fig. 4c)"),
    ("vbar", {"vbar": 0.07}, "amplitude", 25.0, "A ~ 25 at vbar ~ 0.07 (Fig. 4b)"),
    ("vbar", {"vbar": 0.12}, "wavelength_x", 25.0, "lambda ~ 25 at vbar ~ 0.13 (Fig. 4c)"),
    ("phi", {"phi": 0.0}, "amplitude", 32.0, "phi = 0: A = 32 (Fig. 6b)"),
    ("phi", {"phi": 0.0}, "wavelength_x", 6.0, "phi = 0: lambda = 6.0 (Fig. 6b)"),
    ("phi", {"phi": 1.45}, "amplitude", 90.0, "phi -> pi/2: A -> 90 (Fig. 6b, at pi/2)"),
    ("phi", {"phi": 1.45}, "wavelength_x", 3.9, "phi -> pi/2: lambda -> 3.9 (at pi/2)"),
]
PAPER_CLASS = [
    ({"vbar": 0.019}, "serpentine-coil"),
    ({"vbar": 0.037}, "periodic-serpentine"),
    ({"vbar": 0.12}, "irregular-serpentine"),
]


def point_config(point: dict[str, Any], candidate: str, dt_factor: float | None) -> Any:
    """The DepositionConfig of a point: the preset's (mesh included) with the candidate's
    options, the point's groups and ``dt_factor``."""
    from cnt_env.sim.deposition import ContactOptions, default_config

    changes = dict(CANDIDATES[candidate])
    if point["preset"] == COIL:  # stepped-substrate options but the drag law, contact, delta
        keep = ("drag_law", "contact_mode", "delta_bar", "adhesion", "cohesive_range")
        changes = {k: v for k, v in changes.items() if k in keep}
    contact = {k: changes.pop(f)
               for k, f in (("mode", "contact_mode"), ("adhesion", "adhesion"),
                            ("cohesive_range", "cohesive_range")) if f in changes}  # fmt: skip
    if contact:
        changes["contact"] = ContactOptions(**contact)
    if dt_factor is not None:
        changes["dt_factor"] = dt_factor
    changes.update(point["groups"])
    return default_config(point["preset"], **changes)


#: The model of the "default" candidate from issue 12's study until the default became
#: the mesh-converged model (round 4's last session): the printed drag law at delta_bar 1
#: (candidate printed_C). Records of "default" made then name no model fields in their
#: keys; a default that differs from it names the fields that differ.
LEGACY_DEFAULT_MODEL: dict[str, Any] = {
    "drag_law": "printed", "delta_bar": 1.0, "sliding": "C", "snap": "jump",
    "friction": 0.0, "tail_clamp": "xyz", "tail_length": 195.0,
}  # fmt: skip


def _default_model_fields(cfg: Any) -> str:
    """``|k=v`` for each field of LEGACY_DEFAULT_MODEL on which ``cfg`` differs."""
    now = {k: getattr(cfg, k) for k in LEGACY_DEFAULT_MODEL if k != "delta_bar"}
    now["delta_bar"] = cfg.params.delta_bar
    return "".join(
        f"|{k}={v:g}" if isinstance(v, float) else f"|{k}={v}"
        for k, v in now.items()
        if v != LEGACY_DEFAULT_MODEL[k]
    )


def point_key(point: dict[str, Any], candidate: str, dt_factor: float | None,
              seed: int = 0) -> str:  # fmt: skip
    """The point's name in results.jsonl; it names the mesh, Newton tolerance, length
    projection, edge-rotation check and lagged Jacobian it ran with, so a change of any
    of these defaults runs the point again, and a seed other than 0 (the seeded start-up
    perturbation). The named candidates fix their model; "default" follows presets.py, so
    its key also names the model fields that differ from LEGACY_DEFAULT_MODEL."""
    g = ",".join(f"{k}={v:g}" for k, v in sorted(point["groups"].items()))
    if "run" in point and not (
        point["preset"] == SERP and tuple(point["run"]) == LEGACY_SERPENTINE_RUN
    ):
        g += "|run={:g}-{:g}".format(*point["run"])
    dt = "" if dt_factor is None else f"|dt={dt_factor:g}"
    cfg = point_config(point, candidate, dt_factor)
    if _capped(cfg.params.Hbar, cfg.step_hbar_cap):  # named when it sets the step
        dt += f"|dtcap={cfg.step_hbar_cap:g}"
    mesh = f"coarse={cfg.coarse_delta or 0:g},fine={cfg.fine_length:g}"
    sd = f"|seed={seed}" if seed else ""
    proj = cfg.newton.length_projection  # named when on (records before it ran without)
    pj = f",proj={proj:g}" if proj else ""
    rot = cfg.newton.max_edge_rotation  # named when on (records before it ran without)
    pj += f",rot={math.degrees(rot):g}" if rot else ""
    pj += ",lag" if cfg.newton.lagged_jacobian else ""  # named when on, as above
    model = _default_model_fields(cfg) if candidate == "default" else ""
    return (
        f"{candidate}|{point['preset']}|{g}{dt}{sd}|{mesh},tol={cfg.newton.residual_tol:g}"
        f"{pj}{model}"
    )


def run_point(
    point: dict[str, Any],
    candidate: str,
    dt_factor: float | None,
    deposit: float | None,
    seed: int = 0,
) -> dict[str, Any]:
    """Run one point and measure it (in a worker process)."""
    import numpy as np

    from cnt_env.patterns import MeasureOptions, measure
    from cnt_env.presets import RUN_DEPOSIT, RUN_TRANSIENT
    from cnt_env.sim.deposition import DepositionSim

    preset = point["preset"]
    cfg = point_config(point, candidate, dt_factor)
    if deposit is None and "run" in point:
        length, transient = point["run"]
    else:
        length = deposit if deposit is not None else RUN_DEPOSIT[preset]
        transient = min(RUN_TRANSIENT[preset], 0.3 * length)
    sim = DepositionSim(cfg, seed=seed)
    t0 = time.time()
    error = None
    try:
        sim.run(length)
    except Exception as exc:
        error = f"{type(exc).__name__}: {exc}"[:300]
    wall = time.time() - t0
    trace = sim.trace()
    phi = cfg.params.phi
    opts = MeasureOptions(transient_length=transient)
    substrate = "flat" if cfg.params.kappa_c_bar is None else "stepped"
    m = measure(trace, opts, substrate, flow_direction=(1.0, 0.0))
    p = cfg.params
    rec = {
        "key": point_key(point, candidate, dt_factor, seed),
        "row": point["row"],
        "seed": seed,
        "preset": preset,
        "candidate": candidate,
        "groups": point["groups"],
        "vbar": p.vbar,
        "phi": phi,
        "kappa_c_bar": p.kappa_c_bar,
        "Hbar": p.Hbar,
        "Ibar": p.Ibar,
        "delta_bar": p.delta_bar,
        "dt_factor": cfg.dt_factor,
        "dt_hbar_cap": cfg.step_hbar_cap,
        "dt": cfg.time_step,
        "drag_law": cfg.drag_law,
        "sliding": cfg.sliding,
        "snap": cfg.snap,
        "friction": cfg.friction,
        "flow_profile": cfg.flow_profile,
        "tail_clamp": cfg.tail_clamp,
        "tail_length": cfg.tail_length,
        "coarse_delta": cfg.coarse_delta,
        "fine_length": cfg.fine_length,
        "residual_tol": cfg.newton.residual_tol,
        "length_projection": cfg.newton.length_projection,
        "max_edge_rotation": cfg.newton.max_edge_rotation,
        "lagged_jacobian": cfg.newton.lagged_jacobian,
        "contact_mode": cfg.contact.mode,
        "adhesion": cfg.contact.adhesion,
        "cohesive_range": cfg.contact.cohesive_range if cfg.contact.adhesion != "eq1" else None,
        "deposit": length,
        "transient": transient,
        "error": error,
        **_measured(m),
        "wall_s": round(wall, 1),
        "steps": sim.stats()["steps"],
        # V: the trace laid over the simulated time, times Hbar (units e_v / (sigma mu H)),
        # start-up included; the wavelength's kinematics, lambda = 4 A vbar / V
        "deposition_speed": sim.deposited_length / sim.time * p.Hbar if sim.time > 0 else None,
    }
    return {"record": rec, "trace": np.asarray(trace[:, [0, 2]], dtype=np.float32)}


def _measured(m: dict[str, Any]) -> dict[str, Any]:
    """A point record's fields from ``patterns.measure`` (wavelength along x; NaN as
    None): one home for what a run and a re-measure write."""

    def f(x: Any) -> Any:
        return None if isinstance(x, float) and not math.isfinite(x) else x

    return {
        "pattern": m["pattern"],
        "coil_radius": f(m["coil_radius"]),
        "amplitude": f(m["amplitude"]),
        "amplitude_cv": f(m["amplitude_cv"]),
        "wavelength_x": f(m["wavelength"]),
        "wavelength_cv": f(m["wavelength_cv"]),
        "settled_amplitude_cv": f(m["settled_amplitude_cv"]),
        "settled_wavelength_cv": f(m["settled_wavelength_cv"]),
        "wavelength_prog": f(m["wavelength_progression"]),
        "n_cycles": m["n_cycles"],
        "n_loops": m["n_loops"],
        "n_self_crossings": m["n_self_crossings"],
        "loop_density": f(m["loop_density"]),
    }


def remeasure(out: Path) -> int:
    """Re-measure every point whose trace is stored (after a change to patterns.py),
    rewriting results.jsonl in place. Returns the number of points re-measured."""
    import numpy as np

    from cnt_env.patterns import MeasureOptions, measure

    path = out / "results.jsonl"
    recs = list(load_done(path).values())
    n = 0
    for rec in recs:
        name = rec["key"].replace("|", "__").replace(",", "_")
        f = out / "traces" / f"{name}.npy"
        if not f.exists():
            continue
        trace = np.load(f).astype(np.float64)
        opts = MeasureOptions(transient_length=rec["transient"])
        sub = "flat" if rec["preset"] == COIL else "stepped"
        rec.update(_measured(measure(trace, opts, sub, flow_direction=(1.0, 0.0))))
        n += 1
    path.write_text("".join(json.dumps(r) + "\n" for r in recs))
    return n


def load_done(path: Path) -> dict[str, dict[str, Any]]:
    return {rec["key"]: rec for rec in read_rows(path)}


def _fmt(x: Any, nd: int = 1) -> str:
    return "-" if x is None else (f"{x:.{nd}f}" if isinstance(x, float) else str(x))


def _match(rec: dict[str, Any], row: str, groups: dict[str, float]) -> bool:
    if row in ("vbar", "phi") and rec["row"] in ("vbar", "phi") and rec["preset"] == SERP:
        base = {"vbar": 0.037, "phi": 0.0}
        g = {**base, **rec["groups"]}
        want = {**base, **groups}
        return all(abs(g.get(k, 0) - v) < 1e-9 for k, v in want.items()) and all(
            k in ("vbar", "phi") for k in rec["groups"]
        )
    return rec["row"] == row and rec["groups"] == groups


def log_invocation(out: Path, points: int, wall: float, jobs: int, dt_factor: float | None,
                   argv: Sequence[str] | None) -> None:  # fmt: skip
    """Append an invocation that ran points to ``out/invocations.jsonl`` (the summary lists
    them: a resumed invocation that finds everything done records nothing)."""
    rec = {
        "finished": time.strftime("%Y-%m-%d %H:%M", time.gmtime()), "points": points,
        "wall_s": round(wall), "jobs": jobs, "dt_factor": dt_factor,
        "argv": list(sys.argv[1:] if argv is None else argv),
    }  # fmt: skip
    append_row(out / "invocations.jsonl", rec)


def invocations_text(out: Path) -> str:
    """The table of the invocations that ran this folder's points (wall time, jobs)."""
    path = out / "invocations.jsonl"
    if not path.is_file():
        return ""
    lines = ["", "## Invocations that ran points", "",
             "| finished (UTC) | points | dt_factor | jobs | wall s | arguments |",
             "|---|---|---|---|---|---|"]  # fmt: skip
    for r in read_rows(path):
        dt = "default" if r["dt_factor"] is None else r["dt_factor"]
        lines.append(f"| {r['finished']} | {r['points']} | {dt} | {r['jobs']} "
                     f"| {r['wall_s']} | `{' '.join(r['argv'])}` |")  # fmt: skip
    return "\n".join(lines) + "\n"


def _capped(hbar: float, cap: float | None) -> bool:
    """The step cap (DepositionConfig.dt_hbar_cap) sets the step at this Hbar."""
    return cap is not None and hbar > cap


def _before_cap(rec: dict[str, Any]) -> bool:
    """The record ran before the step was capped in absolute time at a point where the
    cap now sets it (RESULTS.md, issue 12): kept in results.jsonl, out of the tables."""
    from cnt_env.presets import STEP_HBAR_CAP

    cap = STEP_HBAR_CAP["flat" if rec["kappa_c_bar"] is None else "stepped"]
    return _capped(rec["Hbar"], cap) and "|dtcap=" not in rec["key"]


def _other_step(rec: dict[str, Any]) -> bool:
    """The record ran at a --dt-factor other than the default (its key says so)."""
    return "|dt=" in rec["key"]


def _other_seed(rec: dict[str, Any]) -> bool:
    """The record ran at a seed other than 0 (its key says so)."""
    return "|seed=" in rec["key"]


def _solver(key: str) -> str:
    """The mesh and Newton settings a point ran with (the last field of its key)."""
    return key.rsplit("|", 1)[1]


def _at_todays_solver(recs: list[dict[str, Any]]) -> list[dict[str, Any]]:
    """The records run at today's default mesh, tolerance and projection, if any."""
    today = {_solver(point_key(_point("coil", p), "default", None)) for p in (COIL, SERP)}
    return [r for r in recs if _solver(r["key"]) in today] or recs


def headline(every: list[dict[str, Any]]) -> list[dict[str, Any]]:
    """The default step and seed 0 (the other steps and seeds have their own sections),
    at the solver settings of today's defaults when any record ran with them, and of a
    point run more than once (e.g. with a longer run) its latest record: a record from
    before a change of those settings stays in results.jsonl, out of the tables."""
    current = _at_todays_solver([r for r in every if not _other_step(r) and not _other_seed(r)])

    def point(r: dict[str, Any]) -> tuple:
        return r["row"], r["preset"], tuple(sorted(r["groups"].items()))

    latest = {point(r): r for r in current}
    return [r for r in current if latest[point(r)] is r]


#: The paper's ranges in SI units (docs/model.md §6): over 0 <= vbar <= 0.13 its
#: serpentine amplitudes lie within 3-13 um and its wavelengths within 0.5-3 um;
#: experiments report coil radii of 0.5-5 um. (row, measure, low, high, what) in um.
PAPER_SI: list[tuple[tuple[str, ...], str, float, float, str]] = [
    (("vbar",), "amplitude", 3.0, 13.0, "serpentine amplitude A, vbar row"),
    (("vbar",), "wavelength_x", 0.5, 3.0, "serpentine wavelength lambda_x, vbar row"),
    (("coil", "coil_groups", "coil_Lvb"), "coil_radius", 0.5, 5.0,
     "coil radius R0, coil rows (experiments)"),
]  # fmt: skip


def si_section(recs: list[dict[str, Any]]) -> list[str]:
    """The model's ranges in micrometres, with L_vb of the paper's tube on each substrate
    (units.preset; the H and I rows change H and rho, not L_vb; the coil_Lvb row has its
    own, lvb_ratio), against PAPER_SI. The amplitude is half the peak-to-peak distance
    (docs/model.md §7), as in the paper's range (its A ~ 100 and ~ 25 are 12.8 and 3.2
    um, the range's ends); peak to peak is given too."""
    from cnt_env import units

    l_um = {p: units.preset(p).L_vb * 1e6 for p in units.PRESETS}
    lines = ["", "## In SI units, against the paper's ranges", "",
             f"L_vb = {l_um[SERP]:.4f} um (stepped), {l_um[COIL]:.4f} um (flat).", "",
             "| quantity | paper (um) | model (um) | points | inside |",
             "|---|---|---|---|---|"]  # fmt: skip
    for row_names, qty, low, high, what in PAPER_SI:
        hits = [r for r in recs if r["row"] in row_names and r.get(qty)]
        if not hits:
            lines.append(f"| {what} | {low:g}-{high:g} | not run | 0 | |")
            continue
        um = [r[qty] * lvb_um(r) for r in hits]
        inside = sum(low <= v <= high for v in um)
        got = f"{min(um):.2f}-{max(um):.2f}"
        if qty == "amplitude":
            got += f" (peak to peak {2 * min(um):.2f}-{2 * max(um):.2f})"
        lines.append(f"| {what} | {low:g}-{high:g} | {got} | {len(um)} | {inside} of {len(um)} |")
    return lines


def lvb_section(recs: list[dict[str, Any]]) -> list[str]:
    """The coils against L_vb (the coil_Lvb row and the baseline coil) in micrometres, with
    R0 / (7.64 L_vb): 1 where the coil scales with L_vb as the paper's baseline R0_bar."""
    from cnt_env import units

    pts = lvb_points(recs)
    if len(pts) < 2:
        return []
    lines = ["", "## Coils against L_vb (the adhesion e_v changed; tube, H and gas the "
             "paper's)", "", "| e_v (J/m) | L_vb (um) | Hbar | Ibar | R0_bar | R0 (um) | "
             "R0 / (7.64 L_vb) |", "|---|---|---|---|---|---|---|"]  # fmt: skip
    for r in pts:
        ratio, lvb = lvb_ratio(r), lvb_um(r)
        r0 = r.get("coil_radius")
        got = (f"{r0:.2f} | {r0 * lvb:.3f} | {r0 / 7.64:.3f}" if r0 else
               f"no coil ({r['pattern']}) | - | -")  # fmt: skip
        lines.append(f"| {units.PAPER_E_V_FLAT / ratio**2:.3g} | {lvb:.4f} | {r['Hbar']:.1f} | "
                     f"{r['Ibar']:.4g} | {got} |")  # fmt: skip
    return lines


def summary(records: list[dict[str, Any]], candidate: str) -> str:
    every = [r for r in records if r["candidate"] == candidate]
    recs = headline(every)
    lines = [f"# Reproduction: candidate `{candidate}`", ""]
    lines += [
        "## Model against paper",
        "",
        "| quantity | paper | model | diff |",
        "|---|---|---|---|",
    ]
    for row, groups, qty, value, note in PAPER:
        hits = [r for r in recs if _match(r, row, groups) and r.get(qty) is not None]
        if not hits:
            lines.append(f"| {note} | {value:g} | not run | |")
            continue
        v = hits[0][qty]
        lines.append(f"| {note} | {value:g} | {v:.2f} | {100 * (v / value - 1):+.1f}% |")
    for groups, cls in PAPER_CLASS:
        hits = [r for r in recs if _match(r, "vbar", groups)]
        got = hits[0]["pattern"] if hits else "not run"
        lines.append(f"| class at vbar = {groups['vbar']} | {cls} | {got} | |")
    lines += si_section(recs)
    lines += lvb_section(recs)
    lines += ["", "## All points", "",
              "| row | groups | class | A | lambda_x | lambda_prog | CV A | CV lambda "
              "| settled CV A / lambda | cycles | loops | crossings | R0 | wall s | error |",
              "|---|---|---|---|---|---|---|---|---|---|---|---|---|---|---|"]  # fmt: skip
    for r in sorted(recs, key=lambda r: (r["row"], sorted(r["groups"].items()))):
        g = ", ".join(f"{k}={v:g}" for k, v in r["groups"].items()) or "baseline"
        lines.append(
            f"| {r['row']} | {g} | {r['pattern']} | {_fmt(r['amplitude'])} | "
            f"{_fmt(r['wavelength_x'])} | {_fmt(r['wavelength_prog'])} | "
            f"{_fmt(r['amplitude_cv'], 2)} | {_fmt(r['wavelength_cv'], 2)} | "
            f"{_fmt(r.get('settled_amplitude_cv'), 2)} / "
            f"{_fmt(r.get('settled_wavelength_cv'), 2)} | {r['n_cycles']} | "
            f"{r['n_loops']} | {r['n_self_crossings']} | {_fmt(r['coil_radius'], 2)} | "
            f"{r['wall_s']} | {r['error'] or ''} |"
        )
    other = _at_todays_solver([r for r in every if _other_step(r) and not _other_seed(r)])
    if other:
        lines += ["", "## Other time steps (same points, dt_factor changed)", "",
                  "| row | point | dt_factor | class | A | lambda_x | R0 | A change | "
                  "lambda_x change | R0 change |",
                  "|---|---|---|---|---|---|---|---|---|---|"]  # fmt: skip
        worst: dict[float, tuple[float, str]] = {}
        for r in sorted(
            other, key=lambda r: (r["dt_factor"], r["row"], sorted(r["groups"].items()))
        ):
            same = re.sub(r"\|dt=[^|]*", "", r["key"])  # the point at the default step
            b = next((b for b in recs if b["key"] == same), {})
            g = ", ".join(f"{k}={v:g}" for k, v in r["groups"].items()) or "baseline"
            # the measures of the point's kind: R0 for a coil, A and lambda_x otherwise
            keys = ("coil_radius",) if r["preset"] == "coil" else ("amplitude", "wavelength_x")
            changes = []
            for k in ("amplitude", "wavelength_x", "coil_radius"):
                new, old = r.get(k), b.get(k)
                if k not in keys or new is None or old is None or not old:
                    changes.append("")
                    continue
                rel = new / old - 1.0
                if abs(rel) > worst.get(r["dt_factor"], (0.0, ""))[0]:
                    worst[r["dt_factor"]] = (abs(rel), f"{r['row']} {g}, {k}")
                changes.append(f"{100 * rel:+.1f}%")
            lines.append(
                f"| {r['row']} | {r['preset']} {g} | {r['dt_factor']:g} | {r['pattern']} "
                f"(default: {b.get('pattern', '-')}) | {_fmt(r['amplitude'])} | "
                f"{_fmt(r['wavelength_x'])} | {_fmt(r['coil_radius'], 2)} | "
                + " | ".join(changes)
                + " |"
            )
        lines.append("")
        for dt, (w, where) in sorted(worst.items()):
            lines.append(f"Largest change at dt_factor {dt:g} (A and lambda_x of serpentines, "
                         f"R0 of coils): {100 * w:.1f}% ({where}).")  # fmt: skip
    lines += seeds_section(every)
    total = sum(r["wall_s"] for r in recs)
    lines += ["", f"Sum of per-point wall times: {total:.0f} s ({len(recs)} points)."]
    return "\n".join(lines) + "\n"


def _spread(values: list[Any]) -> tuple[float, float, int]:
    """(mean, sample sd, n) of the finite values (nan, nan, 0 when there are none)."""
    v = [x for x in values if x is not None and math.isfinite(x)]
    if not v:
        return math.nan, math.nan, 0
    mean = sum(v) / len(v)
    sd = math.sqrt(sum((x - mean) ** 2 for x in v) / (len(v) - 1)) if len(v) > 1 else 0.0
    return mean, sd, len(v)


def seeds_section(every: list[dict[str, Any]]) -> list[str]:
    """Points run with several seeds: the seeds' spread at each step, and the change of
    the mean against the default step, judged against two standard errors of the
    difference of the means (a pattern whose measures scatter with the start-up
    perturbation is converged in the step when its mean moves less than that)."""
    groups: dict[str, dict[float, list[dict[str, Any]]]] = {}
    for r in every:
        point = re.sub(r"\|(dt|seed)=[^|]*", "", r["key"])
        groups.setdefault(point, {}).setdefault(r["dt_factor"], []).append(r)
    multi = {k: v for k, v in groups.items() if any(len(rs) > 1 for rs in v.values())}
    if not multi:
        return []
    lines = ["", "## Seeds: the start-up perturbation's spread, and the step against it", "",
             "Measures of the point's kind (A and lambda_x of a serpentine, R0 of a coil): "
             "mean +- sample sd over the seeds (n: seeds with a value). The change of the "
             "mean against the default step is 'within' when it is below two standard "
             "errors of the difference.", "",
             "| row | point | dt_factor | seeds | classes | A | lambda_x | R0 | change of the "
             "mean | within 2 SE? |", "|---|---|---|---|---|---|---|---|---|---|"]  # fmt: skip
    for _, by_dt in sorted(multi.items()):
        first = next(iter(by_dt.values()))[0]
        kind = ("coil_radius",) if first["preset"] == COIL else ("amplitude", "wavelength_x")
        g = ", ".join(f"{k}={v:g}" for k, v in first["groups"].items()) or "baseline"
        default_dt = min(by_dt, key=lambda dt: (_other_step(by_dt[dt][0]), dt))
        base = {k: _spread([r.get(k) for r in by_dt[default_dt]]) for k in kind}
        for dt, rs in sorted(by_dt.items()):
            classes: dict[str, int] = {}
            for r in rs:
                classes[r["pattern"]] = classes.get(r["pattern"], 0) + 1
            cells, changes, verdicts = [], [], []
            for k in ("amplitude", "wavelength_x", "coil_radius"):
                m, sd, n = _spread([r.get(k) for r in rs])
                cells.append(f"{m:.2f} +- {sd:.2f} ({n})" if n and k in kind else "")
                if k not in kind or dt == default_dt:
                    continue
                m0, sd0, n0 = base[k]
                if not (n and n0):
                    changes.append(f"{k}: n/a")
                    continue
                se = math.sqrt(sd * sd / n + sd0 * sd0 / n0)
                changes.append(f"{k} {100 * (m / m0 - 1):+.1f}%")
                verdicts.append("yes" if abs(m - m0) <= 2 * se else "no")
            cls = ", ".join(f"{c} {k}" for c, k in sorted(classes.items()))
            lines.append(f"| {first['row']} | {first['preset']} {g} | {dt:g} | "
                         f"{len(rs)} | {cls} | " + " | ".join(cells)
                         + f" | {'; '.join(changes)} | {', '.join(verdicts)} |")  # fmt: skip
    return lines


def _get(recs: list[dict[str, Any]], **want: float) -> dict[str, Any] | None:
    base = {"vbar": 0.037, "phi": 0.0, "kappa_c_bar": 0.2, "Hbar": 155.0, "Ibar": 300.0}
    want = {**base, **want}
    for r in recs:
        # the delta finding's points are not the study's (a candidate's own delta is)
        if r["preset"] != SERP or r["row"] == "delta":
            continue
        if all(abs((r[k] or 0) - v) < 1e-9 for k, v in want.items()):
            return r
    return None


_SHORT = {"serpentine-coil": "SC", "periodic-serpentine": "P", "too_short": "TS",
          "irregular-serpentine": "I"}  # fmt: skip


def study_table(records: list[dict[str, Any]]) -> str:
    """Candidate x row: A / lambda_x / class at each study point, and the checks."""
    cands = sorted({r["candidate"] for r in records}, key=list(CANDIDATES).index)
    cols = [("vbar", 0.019), ("vbar", 0.037), ("vbar", 0.07), ("vbar", 0.12),
            ("phi", 0.44), ("phi", 0.87), ("phi", 1.2),
            ("kappa_c_bar", 0.1), ("kappa_c_bar", 0.15)]  # fmt: skip
    head = " | ".join(f"{k.split('_')[0]}={v:g}" for k, v in cols)
    lines = [f"| candidate | {head} | checks passed |", "|---" * (len(cols) + 2) + "|"]
    for c in cands:
        recs = [r for r in records if r["candidate"] == c]
        cells = []
        for k, v in cols:
            r = _get(recs, **{k: v})
            if r is None:
                cells.append("")
                continue
            cls = _SHORT.get(r["pattern"], r["pattern"])
            cells.append(f"{_fmt(r['amplitude'])} / {_fmt(r['wavelength_x'])} {cls}")
        ok, total = _checks(recs)
        lines.append(f"| {c} | " + " | ".join(cells) + f" | {ok}/{total} |")
    lines += ["", "Cells: A / lambda along x, class (SC serpentine-coil, P periodic, I irregular,",
              "TS too short to judge).", "", "Checks:"]  # fmt: skip
    lines += [f"- {name}" for name, _ in CHECKS]
    return "\n".join(lines) + "\n"


def _val(r: dict[str, Any] | None, key: str) -> float:
    v = None if r is None else r.get(key)
    return math.nan if v is None else float(v)


def _within(x: float, target: float, rel: float = 0.25) -> bool:
    return abs(x / target - 1.0) <= rel


CHECKS: list[tuple[str, Any]] = [
    ("baseline A in 26-33", lambda g: 26 <= _val(g(), "amplitude") <= 33),
    ("baseline lambda in 6.3-8.3", lambda g: 6.3 <= _val(g(), "wavelength_x") <= 8.3),
    ("A falls 0.019 -> 0.037 -> 0.07",
     lambda g: _val(g(vbar=0.019), "amplitude") > _val(g(), "amplitude")
     > _val(g(vbar=0.07), "amplitude")),
    ("lambda rises 0.019 -> 0.037 -> 0.12",
     lambda g: _val(g(vbar=0.019), "wavelength_x") < _val(g(), "wavelength_x")
     < _val(g(vbar=0.12), "wavelength_x")),
    ("A(0.07) within 25% of 25", lambda g: _within(_val(g(vbar=0.07), "amplitude"), 25.0)),
    ("lambda(0.12) within 25% of 25",
     lambda g: _within(_val(g(vbar=0.12), "wavelength_x"), 25.0)),
    ("A rises with phi (0 -> 0.87 -> 1.2)",
     lambda g: _val(g(), "amplitude") < _val(g(phi=0.87), "amplitude")
     < _val(g(phi=1.2), "amplitude")),
    ("lambda_x falls with phi (0 -> 0.87 -> 1.2)",
     lambda g: _val(g(), "wavelength_x") > _val(g(phi=0.87), "wavelength_x")
     > _val(g(phi=1.2), "wavelength_x")),
    ("A, lambda at kappa_c 0.1 and 0.15 within 25% of kappa_c 0.2 (collapse)",
     lambda g: all(_within(_val(g(kappa_c_bar=k), q), _val(g(), q))
                   for k in (0.1, 0.15) for q in ("amplitude", "wavelength_x"))),
    ("classes: serpentine-coil at 0.019, periodic at 0.037, irregular at 0.12",
     lambda g: (g(vbar=0.019) or {}).get("pattern") == "serpentine-coil"
     and (g() or {}).get("pattern") == "periodic-serpentine"
     and (g(vbar=0.12) or {}).get("pattern") == "irregular-serpentine"),
]  # fmt: skip


def _checks(recs: list[dict[str, Any]]) -> tuple[int, int]:
    def g(**kw: float) -> dict[str, Any] | None:
        return _get(recs, **kw)

    return sum(bool(fn(g)) for _, fn in CHECKS), len(CHECKS)


def figures(records: list[dict[str, Any]], candidate: str, out: Path) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    shown = headline([r for r in records if r["candidate"] == candidate])
    recs = [r for r in shown if r["preset"] == SERP]
    coils = [r for r in shown if r["preset"] == COIL]
    fig, axes = plt.subplots(3, 4, figsize=(17, 10.5))
    # A and lambda vs vbar, one curve per kappa_c (phi = 0, baseline H, I)
    by_k: dict[float, list[dict[str, Any]]] = {}
    for r in recs:
        if r["phi"] == 0 and r["Hbar"] == 155 and r["Ibar"] == 300:
            by_k.setdefault(r["kappa_c_bar"], []).append(r)
    for k, rs in sorted(by_k.items()):
        rs = sorted(rs, key=lambda r: r["vbar"])
        v = [r["vbar"] for r in rs]
        axes[0, 0].plot(v, [r["amplitude"] or math.nan for r in rs], "o-", label=f"kc={k:g}")
        axes[1, 0].plot(v, [r["wavelength_x"] or math.nan for r in rs], "o-", label=f"kc={k:g}")
    axes[0, 0].plot([0.0, 0.037, 0.07], [100, 30, 25], "k--", label="paper (approx.)")
    axes[1, 0].plot([0.0, 0.037, 0.13], [4, 7, 25], "k--", label="paper (approx.)")
    axes[0, 0].set(xlabel="vbar", ylabel="A")
    axes[1, 0].set(xlabel="vbar", ylabel="lambda (along x)")
    axes[0, 0].legend(fontsize=7)
    rs = sorted([r for r in recs if r["vbar"] == 0.037 and r["kappa_c_bar"] == 0.2
                 and r["Hbar"] == 155 and r["Ibar"] == 300], key=lambda r: r["phi"])  # fmt: skip
    f = [r["phi"] for r in rs]
    axes[0, 1].plot(f, [r["amplitude"] or math.nan for r in rs], "o-", label="model")
    axes[0, 1].plot([0, math.pi / 2], [32, 90], "k--", label="paper ends")
    axes[1, 1].plot(f, [r["wavelength_x"] or math.nan for r in rs], "o-", label="along x")
    axes[1, 1].plot(f, [r["wavelength_prog"] or math.nan for r in rs], "s-",
                    label="along progression")  # fmt: skip
    axes[1, 1].plot([0, math.pi / 2], [6.0, 3.9], "k--", label="paper ends")
    axes[0, 1].set(xlabel="phi", ylabel="A")
    axes[1, 1].set(xlabel="phi", ylabel="lambda")
    axes[1, 1].legend(fontsize=7)
    rs = sorted([r for r in recs if r["vbar"] == 0.037 and r["phi"] == 0 and r["Hbar"] == 155
                 and r["Ibar"] == 300], key=lambda r: r["kappa_c_bar"])  # fmt: skip
    kc = [r["kappa_c_bar"] for r in rs]
    axes[0, 2].plot(kc, [r["amplitude"] or math.nan for r in rs], "o-", label="A")
    axes[0, 2].plot(kc, [r["wavelength_x"] or math.nan for r in rs], "s-", label="lambda")
    axes[0, 2].set(xlabel="kappa_c", title="vbar = 0.037")
    axes[0, 2].legend(fontsize=7)
    colours = {"serpentine-coil": "C3", "periodic-serpentine": "C2",
               "irregular-serpentine": "C0"}  # fmt: skip
    for r in recs:
        if r["phi"] == 0 and r["Hbar"] == 155 and r["Ibar"] == 300:
            axes[1, 2].scatter(r["kappa_c_bar"], r["vbar"], c=colours.get(r["pattern"], "0.5"))
    for name, c in [*colours.items(), ("other", "0.5")]:
        axes[1, 2].scatter([], [], c=c, label=name)
    axes[1, 2].set(xlabel="kappa_c", ylabel="vbar", title="phases")
    axes[1, 2].legend(fontsize=7)
    # the H and I rows: coil radius (flat) and serpentine A, lambda (stepped, vbar 0.037)
    for ax, key, fixed, base in ((axes[2, 0], "Hbar", "Ibar", 2200.0),
                                 (axes[2, 1], "Ibar", "Hbar", 253.0)):  # fmt: skip
        rs = sorted([r for r in coils if r[fixed] == base], key=lambda r: r[key])
        ax.plot([r[key] for r in rs], [r["coil_radius"] or math.nan for r in rs], "o-",
                label="model (no point: no coil)")  # fmt: skip
        ax.axhline(7.64, color="k", ls="--", lw=0.8, label="paper R0 at the baseline")
        ax.set(xlabel=key, ylabel="coil R0", title=f"coils ({fixed} = {base:g})")
        ax.legend(fontsize=7)
    ax = axes[2, 2]
    for key, fixed, base, mark in (("Hbar", "Ibar", 300.0, "o-"), ("Ibar", "Hbar", 155.0, "s-")):
        rs = [r for r in recs if r["vbar"] == 0.037 and r["phi"] == 0
              and r["kappa_c_bar"] == 0.2 and r[fixed] == base]  # fmt: skip
        rs.sort(key=lambda r: r[key])
        ax.plot([r[key] for r in rs], [r["amplitude"] or math.nan for r in rs], mark,
                label=f"A vs {key}")  # fmt: skip
        ax.plot([r[key] for r in rs], [r["wavelength_x"] or math.nan for r in rs], mark,
                mfc="none", label=f"lambda_x vs {key}")  # fmt: skip
    ax.set(xscale="log", xlabel="Hbar or Ibar", title="serpentines, vbar = 0.037")
    ax.legend(fontsize=7)
    # coils against L_vb, in micrometres (the adhesion e_v changed: lvb_groups)
    rs = lvb_points(coils)
    lv = [lvb_um(r) for r in rs]
    ax = axes[0, 3]
    r0_um = [(r["coil_radius"] or math.nan) * x for r, x in zip(rs, lv, strict=True)]
    ax.plot(lv, r0_um, "o-", label="model (no point: no coil)")
    if lv:
        ax.plot([0, max(lv)], [0, 7.64 * max(lv)], "k--", lw=0.8, label="R0 = 7.64 L_vb")
    ax.set(xlabel="L_vb (um)", ylabel="coil R0 (um)", title="coils against L_vb (e_v)")
    ax.legend(fontsize=7)
    for ax in (axes[1, 3], axes[2, 3]):
        ax.axis("off")
    fig.suptitle(f"candidate {candidate}")
    fig.tight_layout()
    fig.savefig(out / f"trends_{candidate}.png", dpi=110)
    plt.close(fig)


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--jobs", type=int, default=2)
    ap.add_argument("--backend", choices=("local", "ray"), default="local",
                    help="local processes, or Ray tasks on a local instance of --jobs CPUs "
                         "(the [ray] extra)")  # fmt: skip
    ap.add_argument("--quick", action="store_true", help="a handful of short points (CI)")
    ap.add_argument("--only", action="append", help="run only this row (repeatable)")
    ap.add_argument("--point", action="append", metavar="K=V[,K=V]",
                    help="run only the points whose changed groups are exactly these, e.g. "
                         "Hbar=250 or kappa_c_bar=0.1,vbar=0.037 (repeatable)")  # fmt: skip
    ap.add_argument("--serpentine-run", type=float, default=SERPENTINE_RUN,
                    help=f"L_vb per serpentine point of the table (default {SERPENTINE_RUN:g}; "
                         "1500, the preset's run, gives the keys of reproduce_1500)")  # fmt: skip
    ap.add_argument(
        "--seeds",
        type=seed_list,
        default="0",
        help="comma-separated seeds of the start-up perturbation; every point "
        "runs once per seed (default 0; the summary gives the seeds' spread)",
    )
    ap.add_argument("--study", action="store_true", help="the configuration-study points")
    ap.add_argument("--delta", action="store_true", help="the delta finding points")
    ap.add_argument(
        "--study-points",
        type=int,
        default=None,
        help="with --study: only the first N (most telling) points",
    )
    ap.add_argument("--candidate", action="append", help=f"one of {sorted(CANDIDATES)}")
    ap.add_argument("--dt-factor", type=float, default=None)
    ap.add_argument("--deposit", type=float, default=None, help="L_vb per point")
    ap.add_argument("--out", type=Path, default=ROOT / "benchmarks/results/reproduce")
    ap.add_argument("--max-wall", type=float, default=None, help="stop submitting after S s")
    ap.add_argument("--no-traces", action="store_true")
    ap.add_argument(
        "--remeasure", action="store_true",
        help="re-measure the stored traces, rewrite the summary and figures, run nothing",
    )  # fmt: skip
    args = ap.parse_args(argv)
    candidates = args.candidate or ["default"]
    for c in candidates:
        if c not in CANDIDATES:
            ap.error(f"unknown candidate {c!r}; choose from {sorted(CANDIDATES)}")
    if args.jobs < 1:
        ap.error("--jobs must be >= 1")
    deposit = args.deposit if args.deposit is not None else (300.0 if args.quick else None)
    if args.delta:
        table = {"delta": list(DELTA_POINTS)}
    elif args.study:
        table = {"study": list(STUDY_POINTS)[: args.study_points]}
    else:
        table = rows(args.quick, args.serpentine_run)
    if args.only:
        unknown = set(args.only) - set(table)
        if unknown:
            ap.error(f"unknown row(s) {sorted(unknown)}; choose from {sorted(table)}")
        table = {k: v for k, v in table.items() if k in args.only}
    if args.point:
        try:
            wanted = [{k: float(v) for k, v in (kv.split("=") for kv in spec.split(","))}
                      for spec in args.point]  # fmt: skip
        except ValueError:
            ap.error(f"--point takes K=V[,K=V], got {args.point}")
        full = table
        table = {k: [p for p in v if p["groups"] in wanted] for k, v in table.items()}
        if not any(table.values()):
            keys = {k for w in wanted for k in w}
            points = [p["groups"] for v in full.values() for p in v]
            near = sorted({",".join(f"{k}={v:g}" for k, v in g.items())
                           for g in points if keys & set(g)})  # fmt: skip
            ap.error(f"no point of the table has the groups {args.point}; the table's points "
                     f"with {sorted(keys)}: {' '.join(near) or 'none'}. A point off the table "
                     "is a `cnt-sim run` (e.g. --preset serpentine --vbar 0.02)")  # fmt: skip
    seeds: list[int] = args.seeds
    out: Path = args.out
    out.mkdir(parents=True, exist_ok=True)
    (out / "traces").mkdir(exist_ok=True)
    results = out / "results.jsonl"
    try:
        if args.remeasure:
            print(f"re-measured {remeasure(out)} points", flush=True)
            table = {}
        done = load_done(results)
    except JsonlError as exc:  # a results file this did not write: refused, kept as it is
        ap.error(str(exc))
    todo = [(p, c, sd) for c in candidates for row in table.values() for p in row
            for sd in seeds if point_key(p, c, args.dt_factor, sd) not in done]  # fmt: skip
    print(f"{len(todo)} points to run ({len(done)} already in {results})", flush=True)
    t0 = time.time()
    n_run = 0
    import numpy as np

    def record(res: dict[str, Any]) -> None:
        nonlocal n_run
        n_run += 1
        rec = res["record"]
        append_row(results, rec)
        if not args.no_traces:
            name = rec["key"].replace("|", "__").replace(",", "_")
            np.save(out / "traces" / f"{name}.npy", res["trace"])
        print(f"[{time.time() - t0:7.0f}s] {rec['key']}: {rec['pattern']} "
              f"A={_fmt(rec['amplitude'])} lx={_fmt(rec['wavelength_x'])} "
              f"R0={_fmt(rec['coil_radius'], 2)} ({rec['wall_s']} s)", flush=True)  # fmt: skip

    if args.backend == "ray" and todo:
        from cnt_env.sweep import ray_session

        with ray_session(args.jobs) as ray:  # every point submitted at once (no --max-wall)
            if run_point.__module__ != "__main__":  # imported: ship it by value all the same
                ray.cloudpickle.register_pickle_by_value(sys.modules[run_point.__module__])
            task = ray.remote(num_cpus=1, max_retries=0)(run_point)
            pending = [task.remote(p, c, args.dt_factor, deposit, sd) for p, c, sd in todo]
            while pending:
                finished, pending = ray.wait(pending, num_returns=1)
                record(ray.get(finished[0]))
    else:
        ctx = multiprocessing.get_context("spawn")
        with ProcessPoolExecutor(max_workers=args.jobs, mp_context=ctx) as pool:
            running = {}
            queue = list(todo)

            def submit() -> None:
                while queue and len(running) < args.jobs:
                    if args.max_wall is not None and time.time() - t0 > args.max_wall:
                        queue.clear()
                        return
                    p, c, sd = queue.pop(0)
                    running[pool.submit(run_point, p, c, args.dt_factor, deposit, sd)] = (p, c)

            submit()
            while running:
                fut = next(as_completed(running))
                running.pop(fut)
                record(fut.result())
                submit()
    wall = time.time() - t0
    if n_run:
        log_invocation(out, n_run, wall, args.jobs, args.dt_factor, argv)
    records = [r for r in load_done(results).values() if not _before_cap(r)]
    if args.study:
        (out / "study_table.md").write_text(study_table(records))
    for c in candidates:
        text = summary(records, c) + invocations_text(out)
        (out / f"summary_{c}.md").write_text(text)
        try:
            figures(records, c, out)
        except Exception as exc:
            print(f"figures failed: {exc}", file=sys.stderr)
    print(f"done in {wall:.0f} s; summary in {out}", flush=True)
    return 0


if __name__ == "__main__":
    os.environ.setdefault("PYTHONHASHSEED", "0")
    raise SystemExit(main())

"""Every per-preset default, in one place (docs/model.md §2, §6).

The paper's dimensionless groups live in :mod:`cnt_env.units` (``PAPER_GROUPS``); this
module holds what we chose on top of them and validated (benchmarks/RESULTS.md): the
mesh, the start-up arc, the run lengths the CLI deposits and measures, and the env's
speed settings. The CLI, the env, sweeps, ``reproduce`` and the benchmarks read these
tables and override them; none of them keeps a copy.
"""

from __future__ import annotations

import math
from types import MappingProxyType
from typing import Any

from cnt_env.units import PAPER_KAPPA_C_BAR, PRESETS

__all__ = [
    "DEFAULT_KAPPA_C",
    "DEMO_DEPOSIT",
    "ENV_MESH",
    "ENV_SIM_DEFAULTS",
    "FLOW_PROFILES",
    "INITIAL_RADIUS",
    "MESH",
    "MODEL",
    "NEWTON",
    "PRESETS",
    "RUN_DEPOSIT",
    "RUN_TRANSIENT",
    "SURROGATE",
    "graded_coarse",
    "mesh_for",
]

#: The model configuration, one for both substrates (issue 12, benchmarks/RESULTS.md
#: "Issue 12: one configuration, the paper's trends" and "The delta study"): the linear
#: drag law (docs/model.md §2), deposited nodes free in x and z until their edge snaps
#: into the steps (sliding "C"), the snap applied between steps ("jump"), no substrate
#: friction beyond the gas drag, the far deposited tail clamped in x, y and z, and the
#: paper's flow, uniform in height (a boundary layer is FLOW_PROFILES' other choice); on
#: MESH's rod of delta_bar = 0.2, where the serpentine's amplitude is converged in delta
#: (<= 2% per halving) and the coil's R0 meets the paper's (it still rises ~3% per
#: halving; the wavelength ~13%: RESULTS.md, "The delta study carried to delta_bar 0.1")
#: (candidate C_fine of benchmarks/reproduce.py). DepositionConfig
#: takes its defaults from here; the other candidates of the study stay named options,
#: and SURROGATE is the fast one the agents are trained on.
MODEL: MappingProxyType[str, Any] = MappingProxyType({
    "drag_law": "linear",
    "sliding": "C",
    "snap": "jump",
    "friction": 0.0,
    "tail_clamp": "xyz",
    "tail_length": 195.0,
    "flow_profile": "uniform",
})  # fmt: skip

#: The flow's profile over the height (DepositionConfig.flow_profile): the paper's
#: uniform flow, or a linear boundary layer with the set flow at the rod's top.
FLOW_PROFILES: tuple[str, ...] = ("uniform", "linear")

#: Mesh and start-up arc per preset: one discretisation for both, delta = 0.2 L_vb where
#: the rod bends (the delta study: R0 7.48, -2.2%, and the serpentine's A converged, where
#: delta = L_vb, the paper's delta ~ L_vb, gives 7.9 and an A that moves on refinement),
#: and a graded suspended rod above it: edges of ``coarse_delta`` = 4 L_vb are injected
#: at the top and split to delta_bar within ``fine_length`` = 20 L_vb of the contact
#: (RESULTS.md, issue 11 "graded mesh" and issue 12 "the graded mesh as the model's
#: default": against the uniform rod the figures move by <= 1.2% at 0.4-0.6x the solved
#: nodes). ``coarse_delta`` None is a uniform rod (``--coarse-delta 0`` on the command
#: line).
MESH: MappingProxyType[str, MappingProxyType[str, Any]] = MappingProxyType({
    "coil": MappingProxyType(
        {"delta_bar": 0.2, "coarse_delta": 4.0, "fine_length": 20.0, "initial_radius": 6.4}
    ),
    "serpentine": MappingProxyType(
        {"delta_bar": 0.2, "coarse_delta": 4.0, "fine_length": 20.0, "initial_radius": 3.9}
    ),
})  # fmt: skip

#: The fast surrogate (candidate printed_C of benchmarks/reproduce.py): the paper's drag
#: law as printed (eq. 2) on a rod of delta = L_vb, the paper's delta ~ L_vb, with the
#: model's other choices. It lays 6.5-7x (a serpentine run) to 13.8x (the env's
#: serpentine; 4.1x its coil; benchmarks/results/env_throughput.json) the trace per
#: CPU-second; its R0 is 7.91 (+3.6%) and not converged in delta, its serpentines have
#: the model's trends with a larger baseline amplitude (41 against 34; RESULTS.md, issue
#: 12). The shipped agents are trained on it (training/configs set these as env_kwargs)
#: and evaluated on the model (README, "Learning flow schedules"). On the command line:
#: ``--drag-law printed --delta 1``.
SURROGATE: MappingProxyType[str, Any] = MappingProxyType({"drag_law": "printed", "delta_bar": 1.0})

#: Newton options of the model (``NewtonOptions`` fields): stop at a residual of 1e-5
#: e_v instead of the stepper's generic 1e-8 (which is in its caller's force units), for
#: 15% fewer iterations; on the reduced-scale runs the traces move by < 1e-3 L_vb
#: (tests/test_stepper_speed_equivalence.py), on the model's serpentine baseline the
#: traces part after some 100 L_vb and A moves by 1.2% (RESULTS.md, issue 11, length
#: projection). And project the iterates' edge lengths (``stepper.project_lengths``,
#: each edge shortened by at most 2% per iteration): the rotating contact edge no longer
#: makes the residual bounce; same equations and solution, 10-25% fewer iterations
#: (RESULTS.md, issue 11, "length projection"). And reject a step that turns an edge by
#: more than 30 deg (``NewtonOptions.max_edge_rotation``; halved instead): at the model's
#: step no serpentine step turns an edge past 17.2 deg, but at half the step Newton
#: sometimes converged to a distant root with a hairpin beside the contact, which made
#: periodic serpentines irregular (RESULTS.md, issue 12, "The edge-rotation check"). And
#: keep the bend-twist and drag blocks of a step's first Jacobian for its later Newton
#: iterations (``NewtonOptions.lagged_jacobian``; stretch, vdW and every residual stay
#: exact): the same equations and solution, ~0.5 more iterations per step at ~2/3 of the
#: cost, 1.3x the env's L_vb per CPU-s (RESULTS.md, issue 11, "lagged soft Jacobian").
NEWTON: MappingProxyType[str, Any] = MappingProxyType({
    "residual_tol": 1e-5,
    "length_projection": 0.02,
    "max_edge_rotation": math.radians(30.0),
    "lagged_jacobian": True,
})  # fmt: skip


def graded_coarse(coarse_delta: float | None, delta_bar: float) -> float | None:
    """The preset's ``coarse_delta`` for a rod at ``delta_bar``: snapped to a whole
    multiple of delta_bar, None (a uniform rod) when that is below 2 delta_bar."""
    if coarse_delta is None:
        return None
    ratio = coarse_delta / delta_bar if delta_bar > 0 else math.inf
    if not math.isfinite(ratio):  # a zero, denormal or non-finite delta_bar
        raise ValueError(
            f"delta_bar = {delta_bar!r} is not a usable edge length (coarse_delta / delta_bar "
            "is not finite); use a delta_bar of order 1 L_vb"
        )
    n_fine = round(ratio)  # fine edges per coarse one
    return n_fine * delta_bar if n_fine >= 2 else None


#: Start-up contact arc radius R_i by substrate (~0.5 um: 6.4 L_vb flat, 3.9 stepped),
#: used when ``--substrate`` swaps the preset's substrate.
INITIAL_RADIUS: MappingProxyType[str, float] = MappingProxyType({"flat": 6.4, "stepped": 3.9})

#: Step cap by substrate [choice]: the default step dt_factor Hbar (DepositionConfig) is
#: held at dt_factor * cap above Hbar = cap. On the stepped substrate the error of the
#: step grows with the step in absolute time, whatever Hbar: at Hbar 400 the steps 20, 10
#: and 5 tau lay the irregular serpentine's A at 54.1, 57.9 and 59.6 (~first order, ~0.5%
#: per tau), while at the baseline Hbar 155 (7.75 tau) halving the step moves A and
#: lambda_x by <= 2.5%. So the cap is the serpentine's baseline Hbar: every stepped point
#: runs at a step <= the baseline's. The flat substrate needs none (the coil's R0 at Hbar
#: 400: 8.14, 8.12, 8.12 at 20, 10, 5 tau). None: no cap. RESULTS.md, issue 12, "a step
#: bounded in absolute time".
STEP_HBAR_CAP: MappingProxyType[str, float | None] = MappingProxyType(
    {"flat": None, "stepped": 155.0}
)

#: Critical curvature kappa_c L_vb that turns steps on when a flat preset is run stepped.
DEFAULT_KAPPA_C: float = PAPER_KAPPA_C_BAR

#: Trace length (L_vb) a run deposits when ``--deposit`` is not given. Coil: 600 L_vb
#: (~12 turns) after its transient. Serpentine: the reproduction's 3000 L_vb: the classes
#: need 10 cycles to call a serpentine periodic, and a cycle of the model is ~150 L_vb of
#: trace at the baseline (9 in the 1350 L_vb measured of a 1500 L_vb run, "too_short"),
#: ~225 at vbar 0.019 and ~270 at Hbar 400, so 3000 gives 10-19 at those points. (4000,
#: the length for the surrogate's ~170 L_vb cycles, costs ~540 s per point on the model.)
RUN_DEPOSIT: MappingProxyType[str, float] = MappingProxyType({"coil": 1500.0, "serpentine": 3000.0})
#: Start-up length dropped before measuring. Coil: the paper's transient, "about 2 us",
#: is 913 L_vb of trace at the surrogate's deposition speed (0.00327 L_vb per tau, tau =
#: 7.16 ps at the coil preset; chosen when the surrogate was the model). With 300 dropped
#: of 800, 2 of its seeds 0-5 were still precessing rosettes (no coil radius); with 900 of
#: 1500, seeds 0-6 give R0 7.913-7.915 and seed 7 is still a rosette (RESULTS.md, issue
#: 12, "The coil's start-up"). The model lays a coil at 1500 / 900 at every point of the
#: reproduction's coil rows (seed 0; other seeds not run). Serpentines settle after ~150.
RUN_TRANSIENT: MappingProxyType[str, float] = MappingProxyType({"coil": 900.0, "serpentine": 150.0})
#: The last fraction of a serpentine's U-turns on which its class is judged
#: (patterns.MeasureOptions.settled_fraction, ``--settled-fraction``): a start-up's decay
#: over its first cycles is not irregularity (RESULTS.md, "Classes of the settled pattern").
SETTLED_FRACTION: float = 0.5
#: ``cnt-sim demo``: a coil long enough to measure past its start-up (the second half:
#: R0 7.475 in ~30 s; 300 L_vb, the length before, was all start-up and measured nothing).
DEMO_DEPOSIT: float = 1200.0

#: The env's speed settings, on top of the model (RESULTS.md, issue 11). Stepped: 4x the
#: validated step and 60 L_vb of deposited tail kept in the solve instead of 195
#: (serpentine suite, case env_fast). Validated for the issue-4 model (linear, sliding B:
#: amplitude -0.2%, wavelength +4.7%); with sliding C the 60 L_vb tail alone moves A and
#: lambda by -8%/-3% at vbar = 0.019 and -13%/-11% at 0.12, and the 4x step by up to
#: +8.5% (RESULTS.md, issue 12). Flat: 2x the validated step, 1.58x the L_vb per CPU-s;
#: over seeds 0-3 (1500 L_vb, 900 dropped) it moves R0 by +0.15% (7.914 -> 7.926), the
#: loops' radius under flow by +0.2% (vbar 0.037) and +1.0% (0.13) and their drift per
#: loop by +2.1% and +4.0%; 4x would move them by up to 13%
#: (benchmarks/results/env_dt_factor_coil.jsonl). Both: a coarser graded rod than
#: MESH's, edges of 6 L_vb injected and split to delta_bar within 10 L_vb of the contact
#: (``ENV_MESH``, snapped to delta_bar like MESH's): against 4 / 20 on the shipped solver
#: it moves the serpentine's A by +0.01 to +0.75% and lambda_x by -0.1 to +0.4% (vbar
#: 0.019-0.12), the coil's R0 by +0.23%, its loops under flow by +0.1% (vbar 0.037) and
#: -1.2% / -2.2% in radius / drift (0.13), for 1.26x (serpentine) and 1.4-1.5x (coil) the
#: L_vb per CPU-s (RESULTS.md, issue 11, "the env's own mesh";
#: benchmarks/results/speed/env_mesh/).
ENV_MESH: MappingProxyType[str, float] = MappingProxyType(
    {"coarse_delta": 6.0, "fine_length": 10.0}
)
ENV_SIM_DEFAULTS: MappingProxyType[str, MappingProxyType[str, Any]] = MappingProxyType({
    "flat": MappingProxyType({"dt_factor": 0.1}),
    "stepped": MappingProxyType({"dt_factor": 0.2, "tail_length": 60.0}),
})  # fmt: skip

assert set(MESH) == set(PRESETS) == set(RUN_DEPOSIT) == set(RUN_TRANSIENT)


def mesh_for(preset: str) -> dict[str, Any]:
    """A fresh copy of ``MESH[preset]`` (raises ValueError on an unknown preset)."""
    if preset not in MESH:
        raise ValueError(f"unknown preset {preset!r}; choose one of {', '.join(PRESETS)}")
    return dict(MESH[preset])

"""benchmarks/power_budget.py: its drag powers are the solver's drag force, and the
budget it reports adds up."""

from __future__ import annotations

import numpy as np

from benchmarks import power_budget as pb  # the repo root is on pytest's pythonpath
from cnt_env.sim.deposition import DepositionSim, default_config
from cnt_env.sim.forces import add_linear_drag


def _sim_past_startup() -> DepositionSim:
    sim = DepositionSim(default_config("serpentine", delta_bar=1.0), seed=0)
    sim.run(15.0)
    return sim


def test_drag_powers_are_the_solvers_drag_force() -> None:
    """Power into the rod (flow power - dissipation) equals sum F . u over the nodes, with
    F the solver's own linear drag (forces.add_linear_drag) at the step's velocities."""
    sim = _sim_past_startup()
    rod = sim.rod
    n = rod.n_nodes
    q = rod.q[: 4 * n].copy()
    u = rod.u[: 4 * n].copy()
    force = np.zeros(4 * n)
    d = rod.drag
    # q_old = q - u dt with dt = 1: the solver's velocity (q - q_old) / dt is u
    no_jacobian, no_fixed = np.zeros((1, 1)), np.zeros(0, bool)
    add_linear_drag(q, q - u, 1.0, n, rod.rest_lengths, rod.drag_on, rod.flow, d.shear, d.mu,
                    d.sigma, d.c_sigma, force, no_jacobian, False, no_fixed)  # fmt: skip
    p = pb.edge_drag_powers(sim, near=5.0)
    into_rod = p["flow_in"] - p["susp_axial"] - p["susp_normal"] - p["deposited"]
    assert p["into_rod"] == into_rod
    mask = np.ones(4 * n, bool)
    mask[3::4] = False  # theta DOFs carry no drag
    expected = float(force[mask] @ u[mask])
    assert abs(expected) > 1e-6  # the rod is moving: the check has something to compare
    np.testing.assert_allclose(into_rod, expected, rtol=1e-9, atol=1e-14)
    # dissipation is a sum of squares; the part near the contact is a part of it
    assert p["susp_axial"] >= 0 and p["susp_normal"] >= 0 and p["deposited"] >= 0
    assert 0 <= p["susp_near"] <= p["susp_axial"] + p["susp_normal"]


def test_budget_adds_up_and_leaves_the_run_unchanged() -> None:
    """The vdW work is e_v per unit length laid (eq. 1); rest = solve dissipation - the
    events' jumps, and the steps' parts sum to it; and the instrumented run is the plain
    run (the same deposition speed to the last bit)."""
    r = pb.budget("serpentine", 1.0, 15.0, 10.0, 5.0)
    assert abs(r["vdw_work"] - 1.0) < 0.02
    jumps = sum(r[k] for k in r if k.startswith("jump_"))
    assert abs(r["solve_dissipation"] - (r["rest"] + jumps)) < 1e-9
    parts = sum(r[k] for k in r if k.startswith("solve_dissipation_since_touchdown_"))
    assert abs(parts - r["solve_dissipation"]) < 1e-6
    plain = _sim_past_startup()
    l0, t0 = plain.deposited_length, plain.time
    plain.run(l0 + 10.0)  # the budget's stopping rule
    laid = plain.deposited_length - l0
    assert laid == r["laid"]
    assert laid / (plain.time - t0) * plain.params.Hbar == r["V_Hbar"]


def test_cohesive_adhesion_removes_the_contacts_loss() -> None:
    """The finding the power budget made (docs/model.md §4): eq. 1's pull, jumping from
    node to node, loses a share of the adhesion energy in the step after each touchdown
    that grows as the mesh is refined (0.28 e_v per length here, at delta 0.3); the
    cohesive pull, handed over continuously, loses almost none (0.01) and deposits
    faster. Both release e_v per unit length."""
    from cnt_env.sim.deposition import ContactOptions

    eq1 = pb.budget("serpentine", 0.3, 15.0, 15.0, 5.0)
    coh = pb.budget("serpentine", 0.3, 15.0, 15.0, 5.0,
                    contact=ContactOptions(adhesion="cohesive", cohesive_range=0.1))  # fmt: skip
    assert abs(eq1["vdw_work"] - 1.0) < 0.02 and abs(coh["vdw_work"] - 1.0) < 0.02
    assert eq1["rest"] > 0.2
    assert coh["rest"] < 0.05
    assert coh["V_Hbar"] > 1.3 * eq1["V_Hbar"]

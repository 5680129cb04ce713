"""Writes tests/data/stepper_regression.npz: reference results of the implicit stepper
(issue 11), so that speed work on the stepper is checked bit for bit against them.

Run with the code whose results are the reference (it was generated at commit 9eb2b55,
whose Newton tolerance was residual_tol = 1e-8; the test passes that tolerance):

    PYTHONPATH=<checkout> python tests/data/make_stepper_regression.py OUT.npz

Two kinds of case:

* ``rod_*``: a Rod alone (cnt_env.sim.stepper), driven through its whole API: drag with
  a changing flow, a vdW contact node, fixed DOFs, append_node, split_edge, drop_front,
  step halvings. Independent of the deposition model's configuration.
* ``dep_*``: small DepositionSim runs (Hbar = 30, explicit DepositionConfig), coil
  (flat sticky) and serpentine (stepped) in the configuration of 9eb2b55 (linear drag,
  sliding B), passed explicitly; they depend on deposition.py / substrate.py too and
  must be regenerated if those change what that configuration computes.
"""

from __future__ import annotations

import sys

import numpy as np

from cnt_env.sim.deposition import DepositionConfig, DepositionSim
from cnt_env.sim.stepper import DragParams, Rod, RodMaterial
from cnt_env.units import paper_groups


def rod_case(newton=None) -> dict:
    n = 40
    s = np.arange(n, dtype=float)
    nodes = np.stack([2.0 * np.sin(s / 9.0), 0.3 + s, 0.1 * np.cos(s / 5.0)], axis=1)
    rod = Rod(nodes, RodMaterial(k_s=6.6e3, k_b=1.0, k_t=1.0, rho=300.0, r0=0.02),
              drag=DragParams(mu=1.0), options=newton, max_nodes=n + 2)  # fmt: skip
    rod.fix_node(0)
    rod.fix_theta(0)
    rod.vdw[:5] = (1.0, 0.5, 1.0, 0.05, 1.0)  # node 1 pulled down by eq. 1 (forces.VDW_*)
    iters = []
    for k in range(160):
        rod.flow[:] = (0.02 * np.cos(0.05 * k), 0.0, 0.02 * np.sin(0.07 * k))
        rod.step(2.0 if k != 40 else 4000.0)
        iters.append(rod.newton_iterations)
        if k % 15 == 7:  # injection at the top (grows past max_nodes: reallocation)
            top = rod.nodes[-1].copy()
            t = top - rod.nodes[-2]
            rod.append_node(top + t / np.linalg.norm(t), rod.node_velocities[-1].copy(), 1.0)
        if k == 50:
            rod.split_edge(rod.n_nodes - 5, 3)
        if k % 40 == 39:  # deletion at the bottom
            rod.drop_front(2)
            rod.fix_node(0)
            rod.fix_theta(0)
    nd = rod.n_dof
    return {"rod_q": rod.q[:nd].copy(), "rod_u": rod.u[:nd].copy(),
            "rod_iterations": np.array(iters), "rod_halvings": np.array(rod.halvings)}  # fmt: skip


def dep_case(name: str, preset: str, length: float, newton=None) -> dict:
    # the model configuration of 9eb2b55, explicit, so that later changes of the
    # defaults (presets.MODEL, issue 12) do not invalidate the reference
    extra = {"drag_law": "linear", "sliding": "B"}
    if newton is not None:
        extra["newton"] = newton
    if preset == "coil":
        params = paper_groups("coil", Hbar=30.0, Ibar=200.0)
        cfg = DepositionConfig(params=params, initial_radius=4.0, **extra)
    else:
        params = paper_groups("serpentine", Hbar=30.0, delta_bar=1.0)
        cfg = DepositionConfig(params=params, initial_radius=3.9, tail_length=40.0, **extra)
    sim = DepositionSim(cfg, seed=7)
    sim.run(length)
    st = sim.stats()
    nd = sim.rod.n_dof
    return {
        f"{name}_trace": sim.trace(), f"{name}_q": sim.rod.q[:nd].copy(),
        f"{name}_stats": np.array([st["steps"], st["newton_iterations"], st["events"],
                                   st["halvings"], st["snaps"]]),
    }  # fmt: skip


def main() -> None:
    out = {}
    out.update(rod_case())
    out.update(dep_case("dep_coil", "coil", 25.0))
    out.update(dep_case("dep_serp", "serpentine", 40.0))
    np.savez_compressed(sys.argv[1], **out)
    for k, v in out.items():
        print(k, np.shape(v), v if np.size(v) < 8 else "")


if __name__ == "__main__":
    main()

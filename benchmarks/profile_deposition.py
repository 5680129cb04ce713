"""Where the time of the deposition loop goes (issue 11): one process, one thread.

For a preset's baseline (``DepositionSim(default_config(preset)).run(L)``) or for the env
(``CNTDeposit-v0`` with seeded random actions) it reports:

* CPU seconds (process time) and L_vb of trace laid per CPU-second;
* committed physics steps per L_vb, Newton iterations per committed step and per
  Newton call, touchdown events and the extra Newton calls (rewinds) they cost;
* the time split: inside the compiled Newton solve (``newton_solve``), the rest of
  ``Rod`` stepping (copies, predictor, commit), the Python of ``DepositionSim.step``
  (event search bookkeeping, contact, injection, refinement, deletion, snapping), and
  for the env what lies outside ``DepositionSim.advance`` (observation, reward);
* the split of one Newton iteration into assembly (frames + residual + band Jacobian)
  and the banded LU (factor + solve), timed on the final state of the run.

Prints one JSON object. Run:

    python benchmarks/profile_deposition.py --preset serpentine --deposit 200
    python benchmarks/profile_deposition.py --preset coil --deposit 300
    python benchmarks/profile_deposition.py --env --preset coil --steps 200
"""

from __future__ import annotations

import os

for _var in ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS", "NUMBA_NUM_THREADS"):
    os.environ.setdefault(_var, "1")

import argparse  # noqa: E402
import json  # noqa: E402
import statistics  # noqa: E402
import tempfile  # noqa: E402
import time  # noqa: E402

import numpy as np  # noqa: E402

from cnt_env.rod.banded import band_lu_factor, band_lu_solve  # noqa: E402
from cnt_env.sim import deposition, stepper  # noqa: E402

_clock = time.process_time  # CPU seconds of this process: the machine is shared


class Probe:
    """Wraps methods with inclusive timers and call counters."""

    def __init__(self) -> None:
        self.t: dict[str, float] = {}
        self.n: dict[str, int] = {}

    def wrap(self, owner, name: str, key: str) -> None:
        inner = getattr(owner, name)
        t, n = self.t, self.n
        t[key] = 0.0
        n[key] = 0

        def timed(*args, **kwargs):
            t0 = _clock()
            try:
                return inner(*args, **kwargs)
            finally:
                t[key] += _clock() - t0
                n[key] += 1

        setattr(owner, name, timed)


def iteration_split(rod: stepper.Rod, dt: float, repeats: int = 200) -> dict:
    """Median µs of one assembly (frames + residual + Jacobian) and one LU (factor +
    solve; with fixed DOFs, as newton_solve does it: the gather of the free DOFs' band
    and the LU of that) on a copy of the rod's current state."""
    n = rod.n_nodes
    nd = rod.n_dof
    q_old = rod.q.copy()
    u_old = rod.u.copy()
    q = rod.q.copy()
    q[:nd] += dt * rod.u[:nd] * (rod.fixed[:nd] == 0)
    m, d = rod.material, rod.drag
    ab = rod._ab
    rhs = rod._rhs
    ipiv = rod._ipiv
    free = np.flatnonzero(rod.fixed[:nd] == 0).astype(np.int64)
    reduced = len(free) < nd
    rhs_r = np.zeros(nd)

    def asm():
        stepper.update_frames(q, n, rod.tangents_old, rod.d1_old, rod.ref_twist_old,
                              rod._tangents, rod._lengths, rod._d1, rod._d2, rod._ref_twist,
                              rod._m1, rod._m2, rod._kb, rod._kappa, rod._twist)  # fmt: skip
        stepper.assemble(q, q_old, u_old, n, dt, rod.mass, rod.fixed, rod.rest_lengths,
                         rod.voronoi_lengths, m.k_s, m.k_b, m.k_t, rod._m1, rod._m2,
                         rod._twist, rod.ext_force, rod.drag_on, rod.flow, d.shear, d.mu, d.sigma,
                         d.c_sigma, d.law_code, rod.vdw, rod.sub_friction, rod.sub_stiffness,
                         rod.sub_anchor, rod._force, ab, rhs, rod.tangents_old,
                         rod.options.exact_jacobian, not reduced, rod._ab_soft,
                         stepper.SOFT_FRESH)  # fmt: skip

    def lu():
        if reduced:
            stepper.gather_free(ab, free, len(free), rod._ab_r)
            rhs_r[: len(free)] = rhs[free]
            band_lu_factor(rod._ab_r, len(free), ipiv)
            band_lu_solve(rod._ab_r, len(free), ipiv, rhs_r)
        else:
            band_lu_factor(ab, nd, ipiv)
            band_lu_solve(ab, nd, ipiv, rhs)

    out = {}
    for key, fn in (("assemble_us", asm), ("lu_us", None)):
        times = []
        for _ in range(repeats):
            if key == "lu_us":
                asm()
                t0 = _clock()
                lu()
            else:
                t0 = _clock()
                fn()
            times.append(_clock() - t0)
        out[key] = round(1e6 * statistics.median(times), 1)
    out["n_nodes"] = n
    out["n_dof"] = nd
    out["n_free"] = len(free)
    out["assembly_share"] = round(out["assemble_us"] / (out["assemble_us"] + out["lu_us"]), 3)
    return out


def instrument() -> Probe:
    p = Probe()
    p.wrap(stepper.Rod, "_newton", "newton_solve")
    p.wrap(stepper.Rod, "_try_step", "rod_try_step")
    p.wrap(deposition.DepositionSim, "step", "sim_step")
    p.wrap(deposition.DepositionSim, "_restore_light", "restore_light")
    p.wrap(deposition.DepositionSim, "_light_state", "light_state")
    for name in ("_settle_contact", "_inject", "_refine", "_delete"):
        p.wrap(deposition.DepositionSim, name, name.lstrip("_"))
    return p


def summarise(p: Probe, wall: float, laid: float, sim, extra: dict, st0: dict) -> dict:
    st = {k: v - st0.get(k, 0) for k, v in sim.stats().items()}
    rod = sim.rod
    calls = p.n["newton_solve"]
    t_newton = p.t["newton_solve"]
    t_try = p.t["rod_try_step"]
    t_step = p.t["sim_step"]
    post = sum(p.t[k] for k in ("settle_contact", "inject", "refine", "delete"))
    split = iteration_split(rod, sim.dt)
    its = st["newton_iterations"]
    t_iter = split["assemble_us"] + split["lu_us"]
    shares = {
        "newton_solve": t_newton / wall,
        "rod_step_python": (t_try - t_newton) / wall,
        "sim_step_python_event_search": (t_step - t_try - post) / wall,
        "sim_step_contact_inject_refine_delete": post / wall,
        "outside_sim_step": (wall - t_step) / wall,
    }
    return {
        **extra,
        "cpu_s": round(wall, 2),
        "laid": round(laid, 2),
        "laid_per_cpu_s": round(laid / wall, 2),
        "committed_steps": st["steps"],
        "steps_per_laid": round(st["steps"] / laid, 3),
        "newton_calls": calls,
        "newton_calls_per_committed_step": round(calls / max(st["steps"], 1), 3),
        "events": st["events"],
        "event_failures": st["event_failures"],
        "halvings": st["halvings"],
        "newton_iterations": its,
        "iterations_per_committed_step": round(its / max(st["steps"], 1), 3),
        "iterations_per_newton_call": round(its / max(calls, 1), 3),
        "us_per_newton_call": round(1e6 * t_newton / max(calls, 1), 1),
        "us_per_iteration_in_solve": round(1e6 * t_newton / max(its, 1), 1),
        "us_python_per_sim_step": round(1e6 * (t_step - t_newton) / max(p.n["sim_step"], 1), 1),
        "iteration_split_final_state": split,
        # estimated from the final-state split (one more assembly per call: convergence check)
        "est_assembly_share_of_solve": round(
            (its + calls) * split["assemble_us"] / (its * t_iter + calls * split["assemble_us"]),
            3,
        ),
        "time_share": {k: round(v, 4) for k, v in shares.items()},
        "n_nodes_final": rod.n_nodes,
    }


def run_sim(preset: str, deposit: float) -> dict:
    cfg = deposition.default_config(preset)
    warm = deposition.DepositionSim(cfg, seed=0)
    warm.step()
    p = instrument()
    sim = deposition.DepositionSim(cfg, seed=0)
    st0 = sim.stats()
    t0 = _clock()
    sim.run(deposit)
    wall = _clock() - t0
    extra = {"mode": "baseline", "preset": preset}
    return summarise(p, wall, sim.deposited_length, sim, extra, st0)


#: The env's route while profiling: 2000 L_vb, never completed in a profile's steps.
LONG_ROUTE = {"waypoints": [[0.0, 0.0], [2000.0, 0.0]], "width": 40.0}


def run_env(preset: str, steps: int, seed: int = 0) -> dict:
    import gymnasium as gym

    import cnt_env  # noqa: F401  (registers CNTDeposit-v0)

    with tempfile.TemporaryDirectory() as cache:
        env = gym.make("CNTDeposit-v0", preset=preset, cache_dir=cache)
        # warm state + compile outside the timing; a route far longer than the run, so
        # that no reset (a new simulator, and a warm-up inside the probes) falls inside it
        env.reset(seed=seed, options={"target": LONG_ROUTE})
        env.action_space.seed(seed)
        p = instrument()
        t_adv = [0.0]
        sim = env.unwrapped.sim
        inner = sim.advance

        def adv(duration):
            t0 = _clock()
            try:
                inner(duration)
            finally:
                t_adv[0] += _clock() - t0

        sim.advance = adv
        st0 = sim.stats()
        rng = np.random.default_rng(seed)
        laid, prev, wall, done = 0.0, 0.0, 0.0, 0
        for _ in range(steps):
            a = rng.uniform(-1, 1, 2).astype(np.float32)
            t0 = _clock()
            _, _, term, trunc, info = env.step(a)
            wall += _clock() - t0
            laid += info["laid_length"] - prev
            prev = info["laid_length"]
            done += 1
            if term or trunc:  # the episode ended (a failure): profile what ran
                break
        out = summarise(p, wall, laid, sim, {"mode": "env", "preset": preset, "steps": done},
                        st0)  # fmt: skip
        out["control_steps_per_cpu_s"] = round(done / wall, 2)
        out["advance_share"] = round(t_adv[0] / wall, 4)
        return out


def main(argv: list[str] | None = None) -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--preset", choices=("coil", "serpentine"), default="serpentine")
    ap.add_argument("--deposit", type=float, default=200.0)
    ap.add_argument("--env", action="store_true")
    ap.add_argument("--steps", type=int, default=200)
    args = ap.parse_args(argv)
    out = run_env(args.preset, args.steps) if args.env else run_sim(args.preset, args.deposit)
    print(json.dumps(out, indent=2))


if __name__ == "__main__":
    main()

"""The best constant flow per target, by a small grid search over speed and direction.

A constant flow lays the same trace whatever the target is (the target only places the
scoring, and the reset draws the same random advance for the same seed when the target
is given by name). So the search simulates each flow of the grid once per seed, against
a target it never reaches (no early termination), and scores the recorded trace against
every target afterwards with :func:`cnt_env.task.scoring.score_trace`: the env's own
score Φ (the same implementation) evaluated on the final trace, cut where the target's end
point was first covered (the env would have terminated there). Selection uses this
offline score on the search seeds; reported numbers come from fresh env rollouts
(training/evaluate.py).
"""

from __future__ import annotations

import math
from collections.abc import Iterable, Mapping, Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np

from cnt_env.task import routes
from cnt_env.task import targets as targets_mod
from cnt_env.task.scoring import THIN_WEIGHTS, score_route_trace, score_trace
from cnt_env.task.spaces import action_from_flow

__all__ = ["ConstantTrace", "grid", "record_constant", "score_trace", "search"]

#: A straight target 3000 L_vb long: never completed, so the episode runs to its limit.
UNREACHABLE = np.array([[0.0, 0.0], [3000.0, 0.0]])


@dataclass
class ConstantTrace:
    """One constant-flow episode: the trace laid since reset, (n, 2) (x, z) relative to
    the contact point at reset, and the number of nodes laid after each control step."""

    vbar: float
    phi: float
    seed: int
    trace: np.ndarray
    n_after_step: np.ndarray


def grid(speeds: Sequence[float], n_directions: int) -> list[tuple[float, float]]:
    """Flows (vbar, phi): every speed at ``n_directions`` evenly spaced angles."""
    phis = [2.0 * math.pi * k / n_directions - math.pi for k in range(n_directions)]
    return [(float(v), float(p)) for v in speeds for p in phis]


def record_constant(env, vbar: float, phi: float, seed: int, max_steps: int) -> ConstantTrace:
    """Run ``env`` (a CNTDeposit-v0, unwrapped or not) with one flow for ``max_steps``."""
    base = env.unwrapped
    action = action_from_flow(vbar, phi, base.vbar_max)
    env.reset(seed=seed, options={"target": UNREACHABLE})
    # the contact point at reset, where the env puts a route's start: the node laid last
    # before reset may still slide on the stepped substrate, so not its final position
    origin = base.target_path[0]
    n_after = []
    for _ in range(max_steps):
        _, _, terminated, truncated, info = env.step(action)
        n_after.append(info["n_laid"])
        if terminated or truncated:
            break
    trace = base.sim.trace()[base.episode_start :, [0, 2]]
    return ConstantTrace(vbar, phi, seed, trace - origin, np.array(n_after))


def search(
    traces: Iterable[ConstantTrace],
    target_names: Sequence[str],
    tolerance: float,
    weights: Sequence[float] = THIN_WEIGHTS,
    score: str = "thin",
    step_limits: Mapping[str, int] | None = None,
    route_of: Mapping[str, routes.Route] | None = None,
) -> tuple[dict[str, dict[str, Any]], list[dict[str, Any]]]:
    """Best flow per target by mean offline score over seeds.

    ``score``: the env's score mode; "thin" scores held-out targets
    (:func:`~cnt_env.task.scoring.score_trace`), "corridor" held-out routes
    (:func:`~cnt_env.task.scoring.score_route_trace`), each cut at its episode length
    ``step_limits[name]`` (control steps; ``env.episode_steps_for(route)``);
    ``route_of[name]``, when given, is the route of that name (``cnt-evaluate
    --route-file``).

    Returns ``(best, rows)``: ``best[target] = {"vbar", "phi", "score"}`` and one row
    per (target, flow) with the mean score terms."""
    traces = list(traces)
    by_flow: dict[tuple[float, float], list[ConstantTrace]] = {}
    for t in traces:
        by_flow.setdefault((t.vbar, t.phi), []).append(t)
    rows: list[dict[str, Any]] = []
    best: dict[str, dict[str, Any]] = {}
    for name in target_names:
        if score == "corridor":
            route = route_of[name] if route_of and name in route_of else routes.held_out(name)
            limit = (step_limits or {}).get(name)

            def one(t: ConstantTrace, route=route, limit=limit) -> dict[str, float]:
                return score_route_trace(t.trace, route, t.n_after_step[:limit])
        else:
            pts = targets_mod.held_out(name).points

            def one(t: ConstantTrace, pts=pts) -> dict[str, float]:
                return score_trace(t.trace, pts, tolerance, weights, t.n_after_step)

        for (vbar, phi), group in by_flow.items():
            terms = [one(t) for t in group]
            mean: Mapping[str, float] = {k: float(np.mean([x[k] for x in terms])) for k in terms[0]}
            rows.append({"target": name, "vbar": vbar, "phi": phi, **mean})
            if name not in best or mean["score"] > best[name]["score"]:
                best[name] = {"vbar": vbar, "phi": phi, "score": mean["score"]}
    return best, rows

"""The planning oracle of the route task: the rollout algorithm (Bertsekas) with the route
follower as its base policy (issue 10).

At every control step, candidate actions are tried, each on a deep copy of the env and
of the follower (bit-identical continuations: the env is deterministic): the candidate
for one step, then the follower to the episode's end; the candidate whose copy ends with
the highest final score is played. The candidates are the follower's own action and its
flow turned by each ``turns`` angle and slowed to each ``speeds`` fraction. The
follower's own action wins ties, and its rollout's score is carried from the step before
(the continuation of the chosen candidate's rollout), so the oracle's final score is
never below the follower's (the rollout algorithm's improvement property, exact here).

It reads the simulator through the copies, so it is not a deployable policy: it measures
what flow schedules can reach (``benchmarks/mpc_oracle.py``) and labels the states a
trained agent should act on (``training/distil.py``). Cost: (K - 1) x the remaining
steps per control step, ~N^2 (K - 1) / 2 env steps per episode of N steps.

``horizon`` [choice] truncates the rollouts: each candidate, the follower's own action
included, is played for one step and the follower for ``horizon`` more (fewer at the
episode's end), and the candidates are compared by the score Φ reached there (the
potential, ``info["score"]``). It costs K (horizon + 1) env steps per control step,
~N K (horizon + 1) per episode, linear in N; the improvement property is then lost (a
short horizon can prefer a step whose cost comes later). None (default) rolls out to the
episode's end.

``confirm`` [choice, with a horizon] makes the truncated rollouts a screen: their best
candidate, when it is not the follower's own action, is rolled out to the episode's end
and played only if that final score beats the follower's (carried from the step before,
as without a horizon); otherwise the follower's action is played. The improvement
property is back (the final score is never below the follower's), at one full rollout
per screened departure instead of K - 1 per step. The returned scores are then the
final scores where a rollout reached the end (index 0 and a screened candidate), NaN
elsewhere.
"""

from __future__ import annotations

import copy
import math
from dataclasses import dataclass, field
from typing import Any

import numpy as np

__all__ = ["DEFAULT_SPEEDS", "DEFAULT_TURNS", "RolloutOracle", "best", "candidates", "finish"]

#: The candidate turns (rad) and speed fractions of the measured oracle
#: (benchmarks/results/mpc_oracle.jsonl).
DEFAULT_TURNS = (-0.4, 0.4)
DEFAULT_SPEEDS = (0.5,)


def candidates(action: Any, vbar_max: float, turns=DEFAULT_TURNS,
               speeds=DEFAULT_SPEEDS) -> list[np.ndarray]:  # fmt: skip
    """The follower's action first, then its flow turned by each angle (radians) and
    slowed to each fraction of its speed."""
    from cnt_env.task.spaces import action_from_flow, flow_from_action

    vbar, phi = flow_from_action(np.asarray(action, dtype=float), vbar_max)
    out = [np.asarray(action, dtype=np.float32)]
    out += [action_from_flow(vbar, phi + t, vbar_max) for t in turns]
    out += [action_from_flow(s * vbar, phi, vbar_max) for s in speeds]
    return [np.asarray(a, dtype=np.float32) for a in out]


def finish(env: Any, follower: Any, obs: Any, term: bool, trunc: bool, info: dict,
           steps: int | None = None) -> float:  # fmt: skip
    """Play ``follower`` (any policy with ``act``) from here for ``steps`` control steps,
    or to the episode's end (None, or when it ends first); the score Φ reached."""
    played = 0
    while not (term or trunc) and (steps is None or played < steps):
        obs, _, term, trunc, info = env.step(follower.act(obs))
        played += 1
    return float(info["score"])


def best(scores: list[float]) -> int:
    """The index of the highest score; the first (the follower's own action) wins ties
    within 1e-12, and so does any earlier candidate over a later one."""
    chosen = 0
    for i, score in enumerate(scores):
        if score > scores[chosen] + 1e-12:
            chosen = i
    return chosen


@dataclass
class RolloutOracle:
    """One episode's oracle over ``env`` (a CNTDeposit-v0, wrapped or not) and its
    ``follower`` (``policies.RouteFollower``), both reset by the caller. ``choose(obs,
    info)`` returns the candidates, their rollout scores (index 0: the follower's own
    action) and the index to play; the caller steps ``env`` with that candidate and then
    calls ``follower.act`` only through ``choose`` (the follower's memory advances once per
    control step)."""

    env: Any
    follower: Any
    turns: tuple[float, ...] = DEFAULT_TURNS
    speeds: tuple[float, ...] = DEFAULT_SPEEDS
    horizon: int | None = None  # follower steps after a candidate; None: to the end
    confirm: bool = False  # with a horizon: play a screened departure only if it wins
    base: float | None = None  # final score of following the follower from the state
    rollouts: int = 0
    history: list[int] = field(default_factory=list)

    def __post_init__(self) -> None:
        h = self.horizon
        if h is not None and (isinstance(h, bool) or not isinstance(h, int) or h < 0):
            raise ValueError(f"horizon must be None or an int >= 0, got {h!r}")
        if self.confirm and h is None:
            raise ValueError("confirm needs a horizon: without one every rollout is full")

    def choose(self, obs: Any, info: dict) -> tuple[list[np.ndarray], list[float], int]:
        # the copies hold the follower before this step's act(), so each rollout replays
        # it from the same memory as the real follower
        snapshot = copy.deepcopy((self.env, self.follower))
        a = self.follower.act(obs)
        cands = candidates(a, self.env.unwrapped.vbar_max, self.turns, self.speeds)
        if self.horizon is not None:
            scores = [self._rollout(snapshot, obs, c, self.horizon) for c in cands]
            chosen = best(scores)
            if self.confirm:
                scores, chosen = self._confirmed(snapshot, obs, info, cands, chosen)
            self.history.append(chosen)
            snapshot[0].close()
            return cands, scores, chosen
        scores = [self._base(snapshot, obs, info)]
        scores += [self._rollout(snapshot, obs, cand) for cand in cands[1:]]
        chosen = best(scores)
        self.base = scores[chosen]
        self.history.append(chosen)
        snapshot[0].close()
        return cands, scores, chosen

    def _base(self, snapshot: Any, obs: Any, info: dict) -> float:
        """The final score of following the follower from here: carried from the step
        before (the continuation of the candidate played there), else rolled out."""
        if self.base is None:
            e, f = copy.deepcopy(snapshot)
            self.base = finish(e, f, obs, False, False, info)
            self.rollouts += 1
            e.close()
        return self.base

    def _rollout(self, snapshot: Any, obs: Any, cand: np.ndarray,
                 steps: int | None = None) -> float:  # fmt: skip
        """Φ after ``cand`` and ``steps`` follower steps (None: to the end), on a copy of
        ``snapshot``."""
        e, f = copy.deepcopy(snapshot)
        f.act(obs)  # the follower's memory as the real one's after this step's act
        o, _, term, trunc, inf = e.step(cand)
        score = finish(e, f, o, term, trunc, inf, steps)
        self.rollouts += 1
        e.close()
        return score

    def _confirmed(self, snapshot: Any, obs: Any, info: dict, cands: list[np.ndarray],
                   screened: int) -> tuple[list[float], int]:  # fmt: skip
        """``confirm``: the full rollout of the screen's pick against the follower's."""
        scores = [math.nan] * len(cands)
        scores[0] = self._base(snapshot, obs, info)
        if screened == 0:
            return scores, 0
        scores[screened] = self._rollout(snapshot, obs, cands[screened])
        if best([scores[0], scores[screened]]):
            self.base = scores[screened]
            return scores, screened
        return scores, 0

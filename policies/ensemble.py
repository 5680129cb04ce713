"""Agents combined: the mean of their actions, or one agent per kind of route.

:class:`MeanPolicy` (``a+b`` in cnt-evaluate): each member acts on the same observation
with its own observation normalisation and, for a residual agent, its own base (the
route follower with the options its config pins); the ensemble plays the mean of their
actions. The members are deterministic, so the ensemble is too. Its training cost is the
sum of its members' (the results say so).

:class:`KeepoutSplit` (``a|b``): agent a plays the routes without a keep-out, agent b
those with one, decided at each episode's first observation as the residual agents' gate
decides (policies/residual.py ``has_keepout``). Its training cost is what its two
networks cost together: for a split whose b went on training a copy of a (a second
stage drawn only from the keep-out family), a's time plus b's second stage.
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np


class MeanPolicy:
    """Plays the mean of ``members``' actions (each in [-1, 1], so the mean is too)."""

    def __init__(self, members: Sequence, name: str = "ensemble") -> None:
        if len(members) < 2:
            raise ValueError(f"an ensemble needs at least two members, got {len(members)}")
        self.members = list(members)
        self.name = name

    def reset(self, seed: int | None = None) -> None:
        for m in self.members:
            m.reset(seed)

    def act(self, obs: np.ndarray) -> np.ndarray:
        actions = np.stack([np.asarray(m.act(obs), dtype=np.float64) for m in self.members])
        return actions.mean(axis=0).astype(np.float32)  # members in order: deterministic


class KeepoutSplit:
    """Plays ``open_agent`` on routes without a keep-out and ``keepout_agent`` on routes
    with one (the keep-out's nearest point in view at the episode's first observation,
    ``policies.residual.has_keepout``; ``slices``: the env's observation slices). Only
    the agent chosen acts in an episode, so a residual agent's base follows its own
    episodes only."""

    def __init__(self, open_agent, keepout_agent, slices: dict[str, slice],
                 name: str = "split") -> None:  # fmt: skip
        if "route" not in slices:
            raise ValueError("a keep-out split needs the route task's observation ('route' slice)")
        self.agents = (open_agent, keepout_agent)
        self.slices = slices
        self.name = name
        self._seed: int | None = None
        self._agent = None  # chosen at the episode's first observation

    def reset(self, seed: int | None = None) -> None:
        self._seed, self._agent = seed, None

    def act(self, obs: np.ndarray) -> np.ndarray:
        if self._agent is None:
            from .residual import has_keepout

            self._agent = self.agents[int(has_keepout(obs, self.slices))]
            self._agent.reset(self._seed)
        return np.asarray(self._agent.act(obs), dtype=np.float32)

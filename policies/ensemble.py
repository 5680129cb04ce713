"""An ensemble of trained agents: the mean of their actions.

Each member acts on the same observation with its own observation normalisation and, for
a residual agent, its own base (the route follower with the options its config pins);
the ensemble plays the mean of their actions. The members are deterministic, so the
ensemble is too. Its training cost is the sum of its members' (the results say so).
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

"""The policy interface shared by every baseline and trained model, and the two simplest
policies (random, constant flow).

A policy maps one vector observation of ``CNTDeposit-v0`` (shape (81,) at the default
K = M = 16) to one action in [-1, 1]^2. ``reset(seed)`` starts an episode (policies with
randomness reseed; closed-loop ones clear their memory).
"""

from __future__ import annotations

import math
from typing import Protocol, runtime_checkable

import numpy as np

from cnt_env.task.env import flow_from_action

__all__ = ["ConstantPolicy", "Policy", "RandomPolicy", "action_from_flow"]


@runtime_checkable
class Policy(Protocol):
    """``act(obs) -> action`` (float32 (2,) in [-1, 1]) and ``reset(seed)``."""

    name: str

    def reset(self, seed: int | None = None) -> None: ...

    def act(self, obs: np.ndarray) -> np.ndarray: ...


def action_from_flow(vbar: float, phi: float, vbar_max: float) -> np.ndarray:
    """The action whose flow is ``(vbar, phi)``: the inverse of the env's elliptical grid
    map (:func:`cnt_env.task.env.flow_from_action`), disk -> square (Fong 2015, eq. for the
    "elliptical grid" inverse)."""
    r = min(max(vbar / vbar_max, 0.0), 1.0)
    u, w = r * math.cos(phi), r * math.sin(phi)
    s2 = 2.0 * math.sqrt(2.0)
    d = u * u - w * w

    def half_diff(a: float, b: float) -> float:
        return 0.5 * math.sqrt(max(a, 0.0)) - 0.5 * math.sqrt(max(b, 0.0))

    x = half_diff(2.0 + d + s2 * u, 2.0 + d - s2 * u)
    z = half_diff(2.0 - d + s2 * w, 2.0 - d - s2 * w)
    return np.clip(np.array([x, z], dtype=np.float32), -1.0, 1.0)


class RandomPolicy:
    """Uniform actions in [-1, 1]^2 (the normalisation floor of the results table)."""

    name = "random"

    def __init__(self, seed: int | None = None) -> None:
        self._rng = np.random.default_rng(seed)

    def reset(self, seed: int | None = None) -> None:
        if seed is not None:
            self._rng = np.random.default_rng(seed)

    def act(self, obs: np.ndarray) -> np.ndarray:
        return self._rng.uniform(-1.0, 1.0, 2).astype(np.float32)


class ConstantPolicy:
    """One flow ``(vbar, phi)`` held for the whole episode."""

    name = "constant"

    def __init__(self, vbar: float, phi: float, vbar_max: float) -> None:
        self.vbar, self.phi, self.vbar_max = float(vbar), float(phi), float(vbar_max)
        self._action = action_from_flow(self.vbar, self.phi, self.vbar_max)

    @property
    def flow(self) -> tuple[float, float]:
        """The flow the env actually applies for this action."""
        return flow_from_action(self._action, self.vbar_max)

    def reset(self, seed: int | None = None) -> None:
        pass

    def act(self, obs: np.ndarray) -> np.ndarray:
        return self._action.copy()

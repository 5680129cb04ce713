"""The policy interface shared by every baseline and trained model, and the two simplest
policies (random, constant flow).

A policy maps one vector observation of ``CNTDeposit-v0`` (shape (81,) at the default
K = M = 16) to one action in [-1, 1]^2. ``reset(seed)`` starts an episode (policies with
randomness reseed; closed-loop ones clear their memory).
"""

from __future__ import annotations

import inspect
from typing import Any, Protocol, runtime_checkable

import numpy as np

from cnt_env.task.spaces import action_from_flow, flow_from_action

__all__ = [
    "ConstantPolicy",
    "Policy",
    "RandomPolicy",
    "action_from_flow",
    "option_defaults",
    "policy_options",
    "require_vector_observation",
    "vector_part",
]


def option_defaults(cls: type, exclude: tuple[str, ...]) -> dict[str, Any]:
    """The keyword defaults of ``cls.__init__`` but ``exclude`` (what the env supplies):
    a policy's options, in one home (its signature)."""
    params = inspect.signature(cls.__init__).parameters.values()
    return {p.name: p.default for p in params
            if p.default is not p.empty and p.name not in exclude}  # fmt: skip


def require_vector_observation(env: Any, who: str) -> None:
    """ValueError unless the (unwrapped) ``env`` gives the vector observation, alone or
    as the "vector" part of a Dict (``obs_mode="dict"``; :func:`vector_part`): ``who``
    reads the trace, the route ahead and the keep-out from its slices, which an image
    does not have (it would read pixels as positions)."""
    if getattr(env, "obs_mode", "vector") not in ("vector", "dict"):
        raise ValueError(f"{who} reads the vector observation, but the env gives "
                         f"obs_mode={env.obs_mode!r}: use obs_mode='vector' or 'dict' (a "
                         "residual agent's base, cnt-evaluate's scripted baseline)")  # fmt: skip


def vector_part(obs: np.ndarray | dict[str, np.ndarray]) -> np.ndarray:
    """The vector observation: ``obs`` itself, or the "vector" part of a Dict one."""
    return obs["vector"] if isinstance(obs, dict) else obs


def policy_options(policy: Any) -> dict[str, Any]:
    """A policy's options (the keys of its class's ``OPTIONS``), as set."""
    return {k: getattr(policy, k) for k in policy.OPTIONS}


@runtime_checkable
class Policy(Protocol):
    """``act(obs) -> action`` (float32 (2,) in [-1, 1]) and ``reset(seed)``."""

    name: str

    def reset(self, seed: int | None = None) -> None: ...

    def act(self, obs: np.ndarray) -> np.ndarray: ...


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

"""Residual actions (Silver et al. 2018; Johannink et al. 2019): the agent's action ``a``
corrects a base policy's, and the env receives ``clip(base(obs) + scale * a, -1, 1)``.

The one implementation, used by the training wrapper (``training/common.py``
``ResidualAction``) and by trained residual agents at inference (``policies/sb3.py``).
"""

from __future__ import annotations

from typing import Any

import numpy as np

__all__ = ["BASES", "WRAPPER", "combine", "make_base_policy", "residual_settings", "zoo_entry"]

#: Base policies a residual agent can correct.
BASES = ("scripted",)
#: The rl-zoo ``env_wrapper`` entry of a residual agent (training/common.py).
WRAPPER = "training.common.ResidualAction"


def residual_settings(entry: dict) -> dict | None:
    """The residual settings ``{"base", "scale"}`` of an rl-zoo config entry: its
    ``env_wrapper`` ``training.common.ResidualAction`` (with its kwargs), or the older
    ``residual`` key; None for a plain agent."""
    if entry.get("residual"):
        return dict(entry["residual"])
    return zoo_entry(entry.get("env_wrapper"), WRAPPER)


def zoo_entry(entries: Any, name: str) -> dict[str, Any] | None:
    """The kwargs of ``name`` in an rl-zoo list (``env_wrapper``, ``callback``): entries
    are a name, or a one-key dict name -> kwargs; a single entry may stand alone.
    None when ``name`` is absent."""
    for e in entries if isinstance(entries, list) else [entries] if entries else []:
        if e == name:
            return {}
        if isinstance(e, dict) and name in e:
            return dict(e[name] or {})
    return None


def combine(base_action: np.ndarray, residual: np.ndarray, scale: float) -> np.ndarray:
    """clip(base + scale * residual, -1, 1) as float32."""
    a = np.asarray(base_action, dtype=np.float64) + scale * np.asarray(residual, dtype=np.float64)
    return np.clip(a, -1.0, 1.0).astype(np.float32)


def make_base_policy(name: str, env):
    """The base policy ``name`` for ``env`` (a CNTDeposit-v0, wrapped or not): "scripted"
    is the scripted baseline of its task (the route follower for ``score="corridor"``,
    the tangent heuristic for ``"thin"``)."""
    from .route_follower import RouteFollower
    from .scripted import ScriptedPolicy

    if name not in BASES:
        raise ValueError(f"unknown residual base {name!r}; choose one of {BASES}")
    if env.unwrapped.score_mode == "corridor":
        return RouteFollower.from_env(env)
    return ScriptedPolicy.from_env(env)

"""Residual actions (Silver et al. 2018; Johannink et al. 2019): the agent's action ``a``
corrects a base policy's, and the env receives ``clip(base(obs) + scale * a, -1, 1)``.

The one implementation, used by the training wrapper (``training/common.py``
``ResidualAction``) and by trained residual agents at inference (``policies/sb3.py``).
"""

from __future__ import annotations

import numpy as np

__all__ = ["BASES", "combine", "make_base_policy"]

#: Base policies a residual agent can correct.
BASES = ("scripted",)


def combine(base_action: np.ndarray, residual: np.ndarray, scale: float) -> np.ndarray:
    """clip(base + scale * residual, -1, 1) as float32."""
    a = np.asarray(base_action, dtype=np.float64) + scale * np.asarray(residual, dtype=np.float64)
    return np.clip(a, -1.0, 1.0).astype(np.float32)


def make_base_policy(name: str, target_slice: slice, vbar_max: float):
    """The base policy ``name`` for observations whose target points are ``target_slice``."""
    from .scripted import ScriptedPolicy

    if name not in BASES:
        raise ValueError(f"unknown residual base {name!r}; choose one of {BASES}")
    return ScriptedPolicy(target_slice, vbar_max)

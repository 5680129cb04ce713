"""Baseline policies for CNTDeposit-v0: random, constant flow, scripted (the route follower
for the route task, the tangent heuristic for the thin one), SB3 loaders.

Every policy has ``act(obs) -> action`` (float32 (2,) in [-1, 1]) and ``reset(seed)``
(:class:`~policies.base.Policy`). ``pretrained/`` holds the shipped agents: each
``<name>.zip``, its VecNormalize statistics (``<name>_vecnormalize.npz`` + ``.json``), the
resolved training config ``<name>.yml``, and ``MANIFEST.json`` (their sha256).
``MeanPolicy`` plays the mean of several trained agents' actions (an ensemble;
``cnt-evaluate --policies a+b``), ``KeepoutSplit`` one agent on routes without a keep-out
and another on routes with one (``'a|b'``).
"""

from pathlib import Path

from . import mkl  # noqa: F401  (first: pins MKL's code path before torch runs)
from .base import ConstantPolicy, Policy, RandomPolicy, action_from_flow
from .ensemble import KeepoutSplit, MeanPolicy
from .route_follower import RouteFollower
from .sb3 import SB3Policy, load_policy
from .scripted import ScriptedPolicy

PRETRAINED_DIR = Path(__file__).resolve().parent / "pretrained"

__all__ = [
    "PRETRAINED_DIR",
    "ConstantPolicy",
    "KeepoutSplit",
    "MeanPolicy",
    "Policy",
    "RandomPolicy",
    "RouteFollower",
    "SB3Policy",
    "ScriptedPolicy",
    "action_from_flow",
    "load_policy",
]

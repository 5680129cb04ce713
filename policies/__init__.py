"""Baseline policies for CNTDeposit-v0: random, constant flow, scripted (the route follower
for the route task, the tangent heuristic for the thin one), SB3 loaders.

Every policy has ``act(obs) -> action`` (float32 (2,) in [-1, 1]) and ``reset(seed)``
(:class:`~policies.base.Policy`). ``pretrained/`` holds one trained model per algorithm
(``<algo>.zip`` + ``<algo>_vecnormalize.pkl``) and its ``env.yml``.
"""

from pathlib import Path

from .base import ConstantPolicy, Policy, RandomPolicy, action_from_flow
from .route_follower import RouteFollower
from .sb3 import SB3Policy, load_policy
from .scripted import ScriptedPolicy

PRETRAINED_DIR = Path(__file__).resolve().parent / "pretrained"

__all__ = [
    "PRETRAINED_DIR",
    "ConstantPolicy",
    "Policy",
    "RandomPolicy",
    "RouteFollower",
    "SB3Policy",
    "ScriptedPolicy",
    "action_from_flow",
    "load_policy",
]

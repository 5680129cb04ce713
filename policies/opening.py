"""A learned opening: turns of the flow in a route's first control steps, per context.

The planning oracle's gains on the open held-out routes are start corrections: a few
±0.4 rad turns of the follower's flow in the first control steps, which hold on
neighbouring trajectories (``benchmarks/chaos.py``; benchmarks/RESULTS.md, issue 10,
"Chaos and the oracle's gains"). The agents train on the surrogate, whose warm swing is
not the model's, and miss them. An opening is the smallest policy that can hold them: a
table from a context read off the first observation to one turn, applied to a base
policy's flow at the control steps ``steps`` (the speed kept). It is learned on the model
by ``training/opening.py`` (paired episodes, one per candidate turn, from the same start).

The context [choice] is the route's initial heading (``sectors`` equal sectors of the
angle from +x, the warm flow's direction, the first centred on it) and the side of the
route the contact edge points to (the swing's phase): ``"<sector>:<+|->"``. A context
the table lacks plays the base unchanged.
"""

from __future__ import annotations

import json
import math
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from cnt_env.task.spaces import action_from_flow, flow_from_action

__all__ = [
    "AXES",
    "OpenedPolicy",
    "Opening",
    "context_of",
    "route_axis",
    "route_direction",
    "turned",
]

#: The route point whose direction from the first one is the heading (4 points ahead:
#: ~20 L_vb at the env's target spacing, past the start's noise and before a first turn).
HEADING_POINT = 4


#: The axes of :func:`route_axis`, counter-clockwise from +x (the warm flow's direction).
AXES = ("+x", "+z", "-x", "-z")


def route_direction(obs: np.ndarray, slices: dict[str, slice]) -> tuple[float, float]:
    """The route's direction (x, z) ahead in one observation: from its first route point
    to the ``HEADING_POINT``-th (not normalised)."""
    target = np.asarray(obs[slices["target"]], dtype=float).reshape(-1, 2)
    j = min(HEADING_POINT, len(target) - 1)
    hx, hz = target[j] - target[0]
    return float(hx), float(hz)


def axis_of(dx: float, dz: float) -> str:
    """The axis of :data:`AXES` nearest the direction (dx, dz); x on a tie, "+x" for (0, 0)."""
    if abs(dx) >= abs(dz):
        return "+x" if dx >= 0.0 else "-x"
    return "+z" if dz > 0.0 else "-z"


def route_axis(obs: np.ndarray, slices: dict[str, slice]) -> str:
    """The axis nearest the route's direction ahead in one observation (at an episode's
    first: its first leg's, :func:`axis_of`)."""
    return axis_of(*route_direction(obs, slices))


def context_of(obs: np.ndarray, slices: dict[str, slice], sectors: int) -> str:
    """The opening's context of one observation: heading sector and swing side."""
    hx, hz = route_direction(obs, slices)
    heading = math.atan2(hz, hx) if (hx or hz) else 0.0
    width = 2.0 * math.pi / sectors
    sector = math.floor((heading + 0.5 * width) / width) % sectors
    rod = obs[slices["rod"]]
    side = "+" if hx * float(rod[2]) - hz * float(rod[1]) >= 0.0 else "-"
    return f"{sector}:{side}"


def turned(action: np.ndarray, angle: float, vbar_max: float) -> np.ndarray:
    """``action`` with its flow turned by ``angle`` (rad), speed kept (float32)."""
    if angle == 0.0:
        return np.asarray(action, dtype=np.float32)
    vbar, phi = flow_from_action(np.asarray(action, dtype=float), vbar_max)
    return np.asarray(action_from_flow(vbar, phi + angle, vbar_max), dtype=np.float32)


@dataclass(frozen=True)
class Opening:
    """``turns``: context -> turn (rad) of the flow at the control steps ``steps``."""

    turns: dict[str, float] = field(default_factory=dict)
    steps: tuple[int, ...] = (1, 2, 3)
    sectors: int = 8

    def __post_init__(self) -> None:
        if self.sectors < 1:
            raise ValueError(f"sectors must be >= 1, got {self.sectors}")
        if any(s < 0 for s in self.steps):
            raise ValueError(f"steps must be control steps >= 0, got {self.steps}")
        bad = {k: v for k, v in self.turns.items() if not math.isfinite(v)}
        if bad:
            raise ValueError(f"turns must be finite angles (rad), got {bad}")

    def to_dict(self) -> dict[str, Any]:
        return {"turns": dict(self.turns), "steps": list(self.steps), "sectors": self.sectors}

    @classmethod
    def from_dict(cls, data: dict[str, Any]) -> Opening:
        return cls({str(k): float(v) for k, v in data["turns"].items()},
                   tuple(int(s) for s in data["steps"]), int(data["sectors"]))  # fmt: skip

    @classmethod
    def load(cls, path: str | Path) -> Opening:
        """The opening of ``opening.json`` (written by ``training/opening.py``)."""
        try:
            data = json.loads(Path(path).read_text())
            return cls.from_dict(data["opening"] if "opening" in data else data)
        except (OSError, ValueError, KeyError, TypeError) as exc:
            raise ValueError(f"{path} is not an opening file ({exc}); "
                             "make one with python training/opening.py") from exc  # fmt: skip


class OpenedPolicy:
    """``base`` with ``opening``'s turn at its control steps; the context is read off the
    episode's first observation."""

    def __init__(self, base: Any, opening: Opening, vbar_max: float,
                 slices: dict[str, slice], name: str | None = None) -> None:  # fmt: skip
        self.base, self.opening, self.vbar_max, self.slices = base, opening, vbar_max, slices
        self.name = name or f"{getattr(base, 'name', 'base')}+opening"
        self.step = 0
        self.context: str | None = None

    def reset(self, seed: int | None = None) -> None:
        self.base.reset(seed)
        self.step, self.context = 0, None

    def act(self, obs: np.ndarray) -> np.ndarray:
        if self.step == 0:
            self.context = context_of(obs, self.slices, self.opening.sectors)
        a = self.base.act(obs)
        if self.step in self.opening.steps:
            a = turned(a, self.opening.turns.get(self.context, 0.0), self.vbar_max)
        self.step += 1
        return a

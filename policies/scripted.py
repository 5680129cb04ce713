"""Closed-loop heuristic: flow along the target's tangent ahead of the contact point,
with the speed read off the measured amplitude curve of the serpentine.

Direction. The observation holds M target points ahead of the furthest covered one,
relative to the contact point (``observation_slices["target"]``). The flow points from
the contact point to the mean of the first ``lookahead`` of them: along the target's
tangent a few L_vb ahead, and back towards the target when the trace has drifted off.

Speed. Under a constant flow across the steps the trace is a serpentine whose amplitude
A falls as v̄ grows (the v̄ sweep, ``benchmarks/results/sweep_vbar/sweep.csv``: A ~ 30
L_vb at v̄ = 0.037, ~19 at 0.08; shipped as package data,
``policies/data/amplitude_curve.json``). The policy estimates the local half-width of the
target ahead (half the spread of the ahead points across their chord) and picks the v̄
whose measured A is closest to it by linear interpolation of A(v̄); a straight target
(width ~0) gets the v̄ of the smallest measured A.
"""

from __future__ import annotations

import csv
import json
import math
from collections import defaultdict
from importlib import resources
from pathlib import Path

import numpy as np

from cnt_env import numerics
from cnt_env.task.spaces import action_from_flow

from .base import option_defaults, require_vector_observation, vector_part

__all__ = ["CURVE_RESOURCE", "ScriptedPolicy", "amplitude_curve", "amplitude_curve_from_csv"]

#: The packaged amplitude curve (policies/data/amplitude_curve.json, package data).
CURVE_RESOURCE = "data/amplitude_curve.json"


def amplitude_curve(path: str | Path | None = None) -> tuple[np.ndarray, np.ndarray, str]:
    """The measured serpentine amplitude per v̄, sorted by v̄: ``(vbar, amplitude,
    source)``. Default: the curve shipped with the package (the band widths of the env's
    step response, ``benchmarks/results/step_response_surrogate.json``); with ``path``, a JSON file
    of the same format (keys ``vbar``, ``amplitude``)."""
    if path is None:
        text = resources.files("policies").joinpath(CURVE_RESOURCE).read_text()
        source = f"policies/{CURVE_RESOURCE}"
    else:
        text, source = Path(path).read_text(), str(path)
    data = json.loads(text)
    v = np.asarray(data["vbar"], dtype=float)
    order = np.argsort(v)
    return v[order], np.asarray(data["amplitude"], dtype=float)[order], source


def amplitude_curve_from_csv(path: str | Path) -> dict[str, list[float]]:
    """Mean amplitude per v̄ of a ``cnt-sim sweep --param vbar`` CSV, rows measured as a
    periodic serpentine only: the content of the packaged JSON (regenerate it with this)."""
    rows: dict[float, list[float]] = defaultdict(list)
    with Path(path).open() as fh:
        for row in csv.DictReader(fh):
            try:
                v, a = float(row["vbar"]), float(row["amplitude"])
            except (KeyError, ValueError):
                continue
            if "serpentine" in row.get("pattern", "") and "coil" not in row.get("pattern", ""):
                if math.isfinite(a) and not row.get("failure"):
                    rows[v].append(a)
    vs = sorted(rows)
    return {"vbar": vs, "amplitude": [float(np.mean(rows[x])) for x in vs]}


class ScriptedPolicy:
    """Tangent-following flow with the speed from the amplitude curve (module doc)."""

    name = "scripted"

    def __init__(
        self,
        target_slice: slice,
        vbar_max: float,
        lookahead: int = 3,
        curve: tuple[np.ndarray, np.ndarray] | None = None,
    ) -> None:
        self.target_slice = target_slice
        self.vbar_max = float(vbar_max)
        self.lookahead = int(lookahead)
        if curve is None:
            v, a, self.curve_source = amplitude_curve()
        else:
            (v, a), self.curve_source = curve, "given"
        v = np.minimum(np.asarray(v, dtype=float), self.vbar_max)
        # A(v) falls with v: sort by amplitude for np.interp (amplitude -> speed)
        order = np.argsort(a)
        self._amp = np.asarray(a, dtype=float)[order]
        self._vbar = v[order]

    @classmethod
    def from_env(cls, env, **kwargs) -> ScriptedPolicy:
        base = env.unwrapped
        require_vector_observation(base, "the scripted policy")
        return cls(base.observation_slices["target"], base.vbar_max, **kwargs)

    def reset(self, seed: int | None = None) -> None:
        pass

    def speed_for(self, half_width: float) -> float:
        """v̄ whose measured amplitude is closest to ``half_width`` (L_vb)."""
        return float(np.interp(half_width, self._amp, self._vbar))

    def act(self, obs: np.ndarray | dict[str, np.ndarray]) -> np.ndarray:
        ahead = np.asarray(vector_part(obs)[self.target_slice], dtype=float).reshape(-1, 2)
        aim = ahead[: self.lookahead].mean(axis=0)
        if math.hypot(*aim) < 1e-9:
            return np.zeros(2, dtype=np.float32)
        phi = math.atan2(aim[1], aim[0])
        chord = ahead[-1] - ahead[0]
        n = math.hypot(*chord)
        if n > 1e-9:
            normal = np.array([-chord[1], chord[0]]) / n
            across = numerics.rows_dot(ahead - ahead[0], normal)
            half_width = 0.5 * float(across.max() - across.min())
        else:
            half_width = 0.0
        return action_from_flow(self.speed_for(half_width), phi, self.vbar_max)


#: The heuristic's options and their defaults (a custom ``curve`` is not one: it is data).
ScriptedPolicy.OPTIONS = option_defaults(ScriptedPolicy, ("curve",))

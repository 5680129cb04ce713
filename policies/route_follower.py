"""Scripted route follower for the corridor task (``score="corridor"``, docs/task.md).

The nanotube is a pen whose *drift* follows the flow and which draws a band: a serpentine
~34 L_vb wide drifting ~0.16-0.19 L_vb per L_vb of trace along ±x (across the steps), an
almost straight run drifting 0.6-1.0 along ±z (benchmarks/results/step_response.json).
Steering the contact point itself fails: it swings across the band every period. So the
follower steers the pattern's *centre*, the mean of the trace over its last ~60 L_vb
(the K trace points of the route observation span ``trace_window`` = 64 L_vb, so their
mean is that centre), toward a point ``lookahead`` L_vb ahead on the route:

* the route points of the observation start at the furthest point reached and are
  ``spacing`` apart; the aim is the one ``lookahead`` beyond the route point nearest the
  centre (default 20 L_vb, about one control step of trace; on u_turn, l_up,
  detour_block and staircase3, seed 0, it scored a mean 0.76 against 0.70 at 12 and 0.75
  at 30);
* the flow points from the centre to the aim, plus ``gain`` times the centre's offset
  across the route (back toward the route's line, which the drift alone corrects slowly);
* a keep-out closer to the centre, or to the aim, than the band's half-width plus
  ``clearance`` pushes the aim away from it, ``repulsion`` per L_vb of intrusion (the
  observation's ``route`` slice holds the nearest keep-out point);
* the speed: the fastest flow whose band fits the corridor (the amplitude curve
  ``policies/data/amplitude_curve.json``: A = 17 L_vb at v̄ = 0.13, 19 at 0.1, ...),
  v̄_max when none fits (the narrowest band). With the measured curve that is v̄_max for
  every corridor: the fastest flow both drifts fastest (0.19 L_vb per L_vb at 0.13, 0.10
  at 0.065) and lays the narrowest band. ``margin`` narrows what "fits".
"""

from __future__ import annotations

import math

import numpy as np

from cnt_env.task.spaces import action_from_flow

from .scripted import amplitude_curve

__all__ = ["RouteFollower"]


class RouteFollower:
    """Steer the pattern's centre along the route ahead (module doc)."""

    name = "follower"

    def __init__(
        self,
        slices: dict[str, slice],
        vbar_max: float,
        spacing: float = 2.0,
        lookahead: float = 20.0,
        gain: float = 0.5,
        margin: float = 0.0,
        clearance: float = 4.0,
        repulsion: float = 2.0,
    ) -> None:
        for key in ("trace", "target", "route"):
            if key not in slices:
                raise ValueError(f"the observation has no {key!r} slice: make the env with "
                                 "score='corridor'")  # fmt: skip
        self.slices = slices
        self.vbar_max = float(vbar_max)
        self.spacing = float(spacing)
        self.lookahead = float(lookahead)
        self.gain = float(gain)
        self.margin = float(margin)
        self.clearance = float(clearance)
        self.repulsion = float(repulsion)
        v, a, _ = amplitude_curve()
        self._v, self._a = v, a

    @classmethod
    def from_env(cls, env, **kwargs) -> RouteFollower:
        base = env.unwrapped
        return cls(base.observation_slices, base.vbar_max, spacing=base.target_spacing, **kwargs)

    def reset(self, seed: int | None = None) -> None:
        pass

    def speed_for(self, half_width: float) -> float:
        """The fastest measured v̄ whose band half-width (amplitude) fits ``half_width``
        less ``margin``; v̄_max when none does."""
        fits = self._v[(self._a <= half_width - self.margin) & (self._v <= self.vbar_max)]
        return float(fits.max()) if fits.size else self.vbar_max

    def act(self, obs: np.ndarray) -> np.ndarray:
        o = np.asarray(obs, dtype=float)
        past = o[self.slices["trace"]].reshape(-1, 2)
        ahead = o[self.slices["target"]].reshape(-1, 2)
        route = o[self.slices["route"]]
        width, keep = float(route[0]), route[1:3]
        centre = past.mean(axis=0)
        # the route ahead, from the centre's nearest point on it
        j0 = int(np.argmin(np.hypot(*(ahead - centre).T)))
        j = min(len(ahead) - 1, j0 + max(1, round(self.lookahead / self.spacing)))
        aim = ahead[j] - centre
        if j > j0:
            t = ahead[j] - ahead[j0]
        else:
            t = ahead[-1] - ahead[max(0, len(ahead) - 2)]
        n = math.hypot(*t)
        if n > 1e-9:
            t = t / n
            across = (centre - ahead[j0]) @ np.array([-t[1], t[0]])
            aim = aim - self.gain * across * np.array([-t[1], t[0]])
        vbar = self.speed_for(width)
        # keep the band (half-width A(v̄) around the centre) off the nearest keep-out,
        # by where the centre is and where it is heading (the aim), whichever is closer
        reach = float(np.interp(vbar, self._v, self._a)) + self.clearance
        intrusion, push = 0.0, np.zeros(2)
        for p in (centre, centre + aim):
            away = p - keep
            dist = math.hypot(*away)
            if 1e-9 < dist < reach and reach - dist > intrusion:
                intrusion, push = reach - dist, away / dist
        aim = aim + self.repulsion * intrusion * push
        if math.hypot(*aim) < 1e-9:
            return np.zeros(2, dtype=np.float32)
        phi = math.atan2(aim[1], aim[0])
        return action_from_flow(vbar, phi, self.vbar_max)

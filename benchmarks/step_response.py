"""Step response of CNTDeposit-v0: how much trace is laid before the pattern's drift
follows a new flow direction, and how wide the pattern is over the flow range.

The env is run at its default physics with a target it never reaches, one control step
~1 L_vb of trace (``control_interval`` 1.5 H̄). Measured:

* ``hold``: for each flow direction φ of ``PHIS`` (0, π/2, π, -π/2, 0, π, π/2) at
  v̄ = ``--vbar``, held for
  ``--hold`` control steps after the previous direction: the steady drift of the pattern
  centre (the mean of the last ``CENTRE_WINDOW`` L_vb of trace) per L_vb of trace laid
  (rate and direction), and the band's width (peak-to-peak extent of the trace across the
  drift, over the second half of the hold);
* ``response``: at each switch of direction, the trace laid (L_vb) after the switch until
  (a) the rod leans the new way (its lean at each observed height, 2, 8, H̄/2 and H̄ L_vb,
  turns to within 45° of the new flow direction: the rod's response), and (b) the
  centre's drift since the switch points to within 45° of the new steady drift and stays
  there (the pattern's response);
* ``widths``: the band's peak-to-peak width and drift rate at φ = 0 for each of
  ``--speeds`` (the corridor's default half-width is chosen from these).

Writes ``benchmarks/results/step_response.json`` (``--out``) and prints it.

    python benchmarks/step_response.py [--hold 150] [--vbar 0.13] [--speeds 0.065,0.1,0.13]
        [--env-kwargs JSON] [--out FILE]
"""

from __future__ import annotations

import os

for _var in ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS", "NUMBA_NUM_THREADS"):
    os.environ.setdefault(_var, "1")

import argparse  # noqa: E402
import json  # noqa: E402
import math  # noqa: E402
import platform  # noqa: E402
import time  # noqa: E402
from pathlib import Path  # noqa: E402

import numpy as np  # noqa: E402

from cnt_env.cli.common import float_list  # noqa: E402
from cnt_env.io import to_jsonable  # noqa: E402
from cnt_env.task.env import CNTDepositEnv  # noqa: E402
from cnt_env.task.spaces import action_from_flow  # noqa: E402

#: Trace length (L_vb) whose mean is the pattern centre (about one serpentine period's
#: worth of run across the band, the follower's definition in policies/route_follower.py).
CENTRE_WINDOW = 60.0
#: A response is complete when the direction is within this angle of the new one.
ANGLE_TOL = math.radians(45.0)
#: Window (L_vb of trace) over which the centre's drift velocity is measured.
DRIFT_WINDOW = 20.0
#: The held directions, in order: every switch of 90° and 180° appears once or more.
PHIS = (0.0, math.pi / 2, math.pi, -math.pi / 2, 0.0, math.pi, math.pi / 2)
UNREACHABLE = np.array([[0.0, 0.0], [0.0, -3000.0]])
OUT = Path(__file__).resolve().parent / "results" / "step_response.json"


def centre(xz: np.ndarray, s: np.ndarray, window: float = CENTRE_WINDOW) -> np.ndarray:
    """Mean of the trace over its last ``window`` L_vb (arc length ``s``)."""
    keep = s >= s[-1] - window
    return xz[keep].mean(axis=0)


def run(env: CNTDepositEnv, flows: list[tuple[float, float]], hold: int, seed: int) -> dict:
    """Hold each flow for ``hold`` steps; per step: laid length, centre, rod lean."""
    env.reset(seed=seed, options={"target": UNREACHABLE})
    rod = env.observation_slices["rod"]
    rows = []
    for k, (vbar, phi) in enumerate(flows):
        a = action_from_flow(vbar, phi, env.vbar_max)
        for _ in range(hold):
            obs, _, terminated, _, info = env.step(a)
            if terminated:
                raise RuntimeError(f"episode ended: {info.get('failure')}")
            trace = env.sim.trace()[env.episode_start - 1 :, [0, 2]]
            s = np.concatenate([[0.0], np.cumsum(np.hypot(*np.diff(trace, axis=0).T))])
            # the lean at the heights of the observation (2, 8, H̄/2, H̄), (x, z) each
            lean = np.asarray(obs[rod][3:], float).reshape(-1, 2)
            rows.append({"phase": k, "laid": float(s[-1]), "centre": centre(trace, s),
                         "lean": lean})  # fmt: skip
    return {"rows": rows, "trace": env.sim.trace()[env.episode_start - 1 :, [0, 2]]}


def _drift(rows: list[dict], i0: int, i1: int) -> tuple[float, float]:
    """(rate L_vb per L_vb of trace, angle) of the centre's motion from row i0 to i1."""
    d = rows[i1]["centre"] - rows[i0]["centre"]
    dl = rows[i1]["laid"] - rows[i0]["laid"]
    return float(math.hypot(*d) / dl), float(math.atan2(d[1], d[0]))


def _angle_between(a: float, b: float) -> float:
    return abs(math.remainder(a - b, 2 * math.pi))


def _index_after(rows: list[dict], i0: int, length: float) -> int:
    target = rows[i0]["laid"] + length
    for i in range(i0, len(rows)):
        if rows[i]["laid"] >= target:
            return i
    return len(rows) - 1


def analyse(result: dict, flows: list[tuple[float, float]], hold: int) -> dict:
    rows, trace = result["rows"], result["trace"]
    s = np.concatenate([[0.0], np.cumsum(np.hypot(*np.diff(trace, axis=0).T))])
    phases = []
    for k, (vbar, phi) in enumerate(flows):
        first, last = k * hold, (k + 1) * hold - 1
        mid = first + hold // 2
        rate, angle = _drift(rows, mid, last)
        # band width across the steady drift over the second half of the hold
        seg = trace[(s >= rows[mid]["laid"]) & (s <= rows[last]["laid"])]
        normal = np.array([-math.sin(angle), math.cos(angle)])
        across = seg @ normal
        phase = {"vbar": vbar, "phi": phi, "drift_rate": rate,
                 "drift_angle": angle, "width_peak_to_peak": float(np.ptp(across)),
                 "laid": rows[last]["laid"] - (rows[first - 1]["laid"] if k else 0.0)}  # fmt: skip
        if k > 0:
            start = rows[first - 1]
            # (a) the rod: its lean at each observed height within ANGLE_TOL of the new
            # flow direction
            rod_len = []
            for h in range(len(start["lean"])):
                found = math.nan
                for r in rows[first : last + 1]:
                    lean = r["lean"][h]
                    if math.hypot(*lean) > 0.5 and _angle_between(
                        math.atan2(lean[1], lean[0]), phi) < ANGLE_TOL:  # fmt: skip
                        found = r["laid"] - start["laid"]
                        break
                rod_len.append(found)
            # (b) the pattern: centre's drift over DRIFT_WINDOW within ANGLE_TOL of the
            # new steady drift, and staying within it to the end of the hold
            pat_len = math.nan
            for i in range(first, last + 1):
                j = _index_after(rows, i, DRIFT_WINDOW)
                if j <= i:
                    break
                ok = all(
                    _angle_between(_drift(rows, m, _index_after(rows, m, DRIFT_WINDOW))[1], angle)
                    < ANGLE_TOL
                    for m in range(i, last + 1)
                    if _index_after(rows, m, DRIFT_WINDOW) > m
                )
                if ok:
                    pat_len = rows[i]["laid"] - start["laid"]
                    break
            phase["rod_response_length"] = rod_len
            phase["pattern_response_length"] = pat_len
        phases.append(phase)
    return {"phases": phases}


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("--hold", type=int, default=150, help="control steps per direction")
    p.add_argument("--vbar", type=float, default=0.13)
    p.add_argument(
        "--speeds", type=float_list, default="0.065,0.1,0.13", help="speeds of the width runs"
    )
    p.add_argument("--width-steps", type=int, default=200)
    p.add_argument("--seed", type=int, default=0)
    p.add_argument("--out", type=Path, default=OUT)
    p.add_argument("--env-kwargs", type=json.loads, default={},
                   help='JSON env keywords on top of the defaults, e.g. \'{"drag_law": '
                        '"linear", "delta_bar": 0.2}\' (the model)')  # fmt: skip
    args = p.parse_args(argv)
    t0 = time.perf_counter()
    # the thin task: control steps of ~1 L_vb (1.5 H̄), finer than any choice measured here
    env = CNTDepositEnv(**{"score": "thin", "pattern_every": 0, **args.env_kwargs})
    flows = [(args.vbar, phi) for phi in PHIS]
    steps = analyse(run(env, flows, args.hold, args.seed), flows, args.hold)
    widths = []
    for v in args.speeds:
        ph = analyse(run(env, [(v, 0.0)], args.width_steps, args.seed), [(v, 0.0)],
                     args.width_steps)["phases"][0]  # fmt: skip
        widths.append({k: ph[k] for k in ("vbar", "drift_rate", "drift_angle",
                                          "width_peak_to_peak")})  # fmt: skip
    resp = [ph for ph in steps["phases"] if "pattern_response_length" in ph]
    out = {
        "env": {
            "control_interval": env.control_interval,
            "n_substeps": env.n_substeps,
            "Hbar": env.params.Hbar,
            "preset": "serpentine",
            "kwargs": args.env_kwargs,
        },
        "method": {
            "centre_window": CENTRE_WINDOW,
            "angle_tol_deg": math.degrees(ANGLE_TOL),
            "drift_window": DRIFT_WINDOW,
            "hold_steps": args.hold,
            "seed": args.seed,
        },
        "hold": steps["phases"],
        "widths": widths,
        "summary": {
            "rod_heights": "2, 8, Hbar/2, Hbar (L_vb)",
            "rod_response_length_median": np.nanmedian(
                [r["rod_response_length"] for r in resp], axis=0
            ).tolist(),
            "pattern_response_length_median": float(
                np.nanmedian([r["pattern_response_length"] for r in resp])
            ),
            "pattern_response_length_mean": float(
                np.nanmean([r["pattern_response_length"] for r in resp])
            ),
            "pattern_response_length_max": float(
                np.nanmax([r["pattern_response_length"] for r in resp])
            ),
            "max_half_width": 0.5
            * max(
                w["width_peak_to_peak"]
                for w in widths
                + [{"width_peak_to_peak": h["width_peak_to_peak"]} for h in steps["phases"]]
            ),
            "laid_per_step": steps["phases"][0]["laid"] / args.hold,
        },
        "wall_time_s": round(time.perf_counter() - t0, 1),
        "machine": platform.platform(),
    }
    args.out.parent.mkdir(parents=True, exist_ok=True)
    args.out.write_text(json.dumps(to_jsonable(out), indent=2) + "\n")
    print(json.dumps(to_jsonable(out["summary"]), indent=2))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())

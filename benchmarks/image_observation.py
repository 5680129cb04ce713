"""Cost of the image observation's route layers (``image_layers``: "route", the default,
against "path", the route's line alone): the median time of one
:func:`cnt_env.task.raster.image_observation` call per held-out route, on a trace laid
along the route's first leg, at the env's default image (64 pixels over 64 L_vb).

    python benchmarks/image_observation.py [--repeats 400] [--size 64] [--out FILE.json]

The env builds one image per control step, which lays ~12-24 L_vb of trace in ~170
physics steps (~450 ms on the default env: ``benchmarks/results/env_throughput.json``),
so the figure to compare with is the step's time, not zero.
"""

from __future__ import annotations

import argparse
import functools
import json
import platform
import statistics
import time
from pathlib import Path

import numpy as np

from cnt_env.task import raster, routes


def trace_along(route: routes.Route, n: int = 2000, spacing: float = 0.2) -> np.ndarray:
    """A serpentine of ``n`` nodes, ``spacing`` apart, swinging 10 L_vb either side of
    the route's first leg: a trace as long as the env keeps (400 L_vb)."""
    a, b = route.waypoints[0], route.waypoints[1]
    e = (b - a) / np.hypot(*(b - a))
    s = spacing * np.arange(n) / 4.0  # progress along the leg (a serpentine drifts slowly)
    swing = 10.0 * np.sin(2.0 * np.pi * s / 8.0)
    return a + np.outer(s, e) + np.outer(swing, [-e[1], e[0]])


def time_call(fn, repeats: int) -> float:
    fn()  # numba's first call
    times = []
    for _ in range(repeats):
        t0 = time.perf_counter()
        fn()
        times.append(time.perf_counter() - t0)
    return statistics.median(times)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--repeats", type=int, default=400)
    parser.add_argument("--size", type=int, default=64)
    parser.add_argument("--out", default=None, help="also write the JSON here")
    args = parser.parse_args()
    rows = []
    for name in routes.HELD_OUT:
        route = routes.held_out(name)
        trace = trace_along(route)
        rod = trace[-1] + np.outer(np.linspace(0, 30, 150), [0.3, 0.1])
        layers = raster.RouteLayers(route.width, route.pads, route.pad_width, route.keepouts)
        call = functools.partial(raster.image_observation, args.size, 64.0, trace,
                                 len(trace) // 2, route.points, None, rod)  # fmt: skip
        ms = {key: 1e3 * time_call(functools.partial(call, route=lay), args.repeats)
              for key, lay in (("path", None), ("route", layers))}  # fmt: skip
        rows.append({"route": name, "path_ms": round(ms["path"], 4),
                     "route_ms": round(ms["route"], 4),
                     "ratio": round(ms["route"] / ms["path"], 3)})  # fmt: skip
        print(f"{name:>16}: path {ms['path']:.3f} ms, route {ms['route']:.3f} ms "
              f"({ms['route'] / ms['path']:.2f}x)")  # fmt: skip
    out = {"benchmark": "image_observation", "machine": platform.processor() or platform.machine(),
           "size": args.size, "repeats": args.repeats, "rows": rows}  # fmt: skip
    if args.out:
        Path(args.out).write_text(json.dumps(out, indent=1) + "\n")


if __name__ == "__main__":
    main()

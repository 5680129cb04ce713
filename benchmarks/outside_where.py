"""Where the trace leaves the corridor: the episode's first swing against the rest (issue 10).

For each evaluated route episode of ``cnt-evaluate`` result directories (``episodes.json``
and ``traces.npz``), the length of trace laid outside the route's corridor (a trace node
farther than the half-width w from the route, weighted by its share of the trace's arc
length, as the score's precision counts nodes) within the first ``--first`` L_vb of trace
and after it. The first swing is laid from the env's warm state (the rod after H̄ of
trace at the warm-start flow, then a random advance), before the rod can follow a new
flow (its lag: docs/task.md): a loss that the steady steering does not show.

    python benchmarks/outside_where.py training/results --out benchmarks/results/outside_where.json

prints, per policy, the mean outside length in the first ``--first`` L_vb and after, the
precision without the first part's loss, and the per-episode first-part table; with
``--out`` it writes them as JSON (one entry per directory). With ``--legs ROUTE`` it
prints instead, per policy, the outside length per episode on that route by its nearest
leg and side (where a detour's loss lies). With ``--corners ROUTES`` it prints, per policy,
how far the trace runs past each corner of those routes along the leg that arrives there.
"""

from __future__ import annotations

import argparse
import json
import sys
from collections import defaultdict
from collections.abc import Callable, Iterator
from pathlib import Path
from typing import Any

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))
from cnt_env.cli.common import csv_list  # noqa: E402


def _outside_nodes(trace: np.ndarray, route: np.ndarray,
                   width: float) -> tuple[np.ndarray, np.ndarray, np.ndarray]:  # fmt: skip
    """``(arc length, weight, outside)`` per node of a trace (n, 2): its arc length from
    the start, its share of the arc, and whether it lies farther than ``width`` from
    ``route`` (m, 2)."""
    from cnt_env.task.scoring import distances
    from cnt_env.task.targets import cumulative_length

    s = cumulative_length(trace)
    weight = np.gradient(s) if len(s) > 1 else np.zeros(1)
    return s, weight, distances(trace, route) > width


def _episodes(results: Path, keep: Callable[[dict[str, Any]], bool]
              ) -> Iterator[tuple[dict[str, Any], np.ndarray, np.ndarray, float]]:  # fmt: skip
    """``(row, trace, route, width)`` of each episode of a cnt-evaluate directory whose
    row ``keep`` accepts and whose trace was saved, in the results' frame (float64)."""
    from cnt_env.task import routes

    rows = json.loads((results / "episodes.json").read_text())
    traces = np.load(results / "traces.npz")
    for i, r in enumerate(rows):
        if keep(r) and f"trace_{i}" in traces:
            trace, route = (traces[f"{k}_{i}"].astype(np.float64) for k in ("trace", "target"))
            yield r, trace, route, routes.held_out(r["target"]).width


def outside_lengths(trace: np.ndarray, route: np.ndarray, width: float,
                    first: float) -> tuple[float, float, float]:  # fmt: skip
    """``(outside within the first L_vb, outside after, laid length)`` of a trace (n, 2)
    against the corridor of half-width ``width`` around ``route`` (m, 2), in the trace's
    frame."""
    s, weight, out = _outside_nodes(trace, route, width)
    early = s < first
    return (float(weight[out & early].sum()), float(weight[out & ~early].sum()), float(s[-1]))


def outside_by_leg(trace: np.ndarray, route: np.ndarray, width: float) -> np.ndarray:
    """The length of a trace (n, 2) laid outside the corridor of half-width ``width``
    around ``route`` (m, 2), by the route's leg nearest to each node and its side: an
    (m - 1, 2) array, column 0 left of the leg's direction (90° anticlockwise in (x, z)),
    column 1 right. Nodes are weighted as in :func:`outside_lengths`."""
    _, weight, out = _outside_nodes(trace, route, width)
    a, ab = route[:-1], np.diff(route, axis=0)  # (m-1, 2) legs
    rel = trace[:, None, :] - a[None]  # (n, m-1, 2)
    u = np.clip(np.einsum("nmk,mk->nm", rel, ab) / np.maximum((ab**2).sum(1), 1e-12), 0, 1)
    gap = np.hypot(*np.moveaxis(rel - u[..., None] * ab[None], -1, 0))
    leg = np.argmin(gap, axis=1)
    left = (ab[leg, 0] * rel[np.arange(len(trace)), leg, 1]
            - ab[leg, 1] * rel[np.arange(len(trace)), leg, 0]) > 0  # fmt: skip
    by = np.zeros((len(ab), 2))
    np.add.at(by, (leg[out], np.where(left[out], 0, 1)), weight[out])
    return by


def corner_overshoot(trace: np.ndarray, waypoints: np.ndarray, width: float) -> list[float]:
    """How far a trace (n, 2) runs past each corner (interior waypoint) of a route, along
    the leg that arrives there: the largest (p - corner) . u over the nodes within
    ``width`` of that leg's line, u its direction, laid before the trace first comes
    within ``width`` of the next leg's midpoint (negative: it turned before the corner).
    A run along the steps that overshoots a corner lays its excess outside the corridor
    and turns late into the next leg."""
    wp = np.asarray(waypoints, dtype=np.float64)
    out = []
    for k in range(1, len(wp) - 1):
        u = (wp[k] - wp[k - 1]) / np.hypot(*(wp[k] - wp[k - 1]))
        rel = trace - wp[k]
        along = rel @ u
        lateral = np.abs(rel @ np.array([-u[1], u[0]]))
        reached = np.nonzero(np.hypot(*(trace - 0.5 * (wp[k] + wp[k + 1])).T) <= width)[0]
        end = int(reached[0]) if reached.size else len(trace)
        near = lateral[:end] <= width
        out.append(float(along[:end][near].max()) if near.any() else float("nan"))
    return out


def corners(results: Path, target: str) -> dict[str, list[list[float]]]:
    """Per policy, :func:`corner_overshoot` of each episode on the route ``target`` of a
    cnt-evaluate directory (the held-out route's waypoints: the results' frame starts the
    route at the origin, as the held-out routes do)."""
    from cnt_env.task import routes

    waypoints = routes.held_out(target).waypoints
    per: dict[str, list[list[float]]] = defaultdict(list)
    for r, trace, _, width in _episodes(results, lambda r: r["target"] == target):
        per[r["policy"]].append(corner_overshoot(trace, waypoints, width))
    return dict(per)


def legs(results: Path, target: str) -> dict[str, list[list[float]]]:
    """Per policy, the mean per episode of :func:`outside_by_leg` on the route
    ``target`` of a cnt-evaluate directory."""
    per: dict[str, list[np.ndarray]] = defaultdict(list)
    for r, trace, route, width in _episodes(results, lambda r: r["target"] == target):
        per[r["policy"]].append(outside_by_leg(trace, route, width))
    return {p: np.mean(v, axis=0).round(1).tolist() for p, v in per.items()}


def analyse(results: Path, first: float, skip: set[str]) -> dict[str, Any]:
    per_policy: dict[str, list[tuple[float, float, float]]] = defaultdict(list)
    episodes = []
    for r, trace, target, width in _episodes(results, lambda r: r["target"] not in skip):
        early, late, laid = outside_lengths(trace, target, width, first)
        per_policy[r["policy"]].append((early, late, laid))
        episodes.append({"policy": r["policy"], "target": r["target"], "seed": r["seed"],
                         "score": r["score"], "outside_first": round(early, 2),
                         "outside_after": round(late, 2), "laid": round(laid, 1)})  # fmt: skip
    summary = {}
    for p, v in per_policy.items():
        a = np.array(v)
        summary[p] = {
            "episodes": len(a),
            "outside_first": float(a[:, 0].mean()),
            "outside_after": float(a[:, 1].mean()),
            "laid": float(a[:, 2].mean()),
            "precision": float(np.mean(1.0 - (a[:, 0] + a[:, 1]) / a[:, 2])),
            "precision_without_first": float(np.mean(1.0 - a[:, 1] / a[:, 2])),
        }
    return {"results": str(results), "first": first, "skipped": sorted(skip),
            "summary": summary, "episodes": episodes}  # fmt: skip


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("results", type=Path, nargs="+", help="cnt-evaluate result directories")
    ap.add_argument("--first", type=float, default=60.0, help="L_vb of trace from the start")
    ap.add_argument("--skip", type=csv_list, default="detour_block",
                    help="comma separated routes left out (default: the keep-out route, "
                         "whose loss is its detour)")  # fmt: skip
    ap.add_argument("--out", type=Path, help="write the figures here (JSON)")
    ap.add_argument(
        "--legs", metavar="ROUTE", help="instead: the outside length per leg of this route and side"
    )
    ap.add_argument(
        "--corners",
        type=csv_list,
        metavar="ROUTES",
        help="instead: how far the trace runs past each corner of these routes",
    )
    args = ap.parse_args(argv)
    if args.corners:
        for d in args.results:
            for target in args.corners:
                per = corners(d, target)
                n = len(next(iter(per.values()))[0]) if per else 0
                print(f"## {d}: {target}, L_vb past each corner (episodes, then their mean)")
                print("| policy | " + " | ".join(f"corner {j + 1}" for j in range(n)) + " |")
                print("|---|" + "---|" * n)
                for p, eps in per.items():
                    cols = np.array(eps).T
                    print(f"| {p} | " + " | ".join(
                        " / ".join(f"{x:.1f}" for x in c) + f" ({np.mean(c):.1f})"
                        for c in cols) + " |")  # fmt: skip
                print()
        return 0
    if args.legs:
        for d in args.results:
            by = legs(d, args.legs)
            print(
                f"## {d}: {args.legs}, outside (L_vb per episode) by nearest leg, "
                "left / right of its direction"
            )
            n = len(next(iter(by.values()))) if by else 0
            print("| policy | " + " | ".join(f"leg {j}" for j in range(n)) + " |")
            print("|---|" + "---|" * n)
            for p, v in by.items():
                print(f"| {p} | " + " | ".join(f"{lft:.1f} / {rgt:.1f}" for lft, rgt in v) + " |")
            print()
        return 0
    skip = set(args.skip)
    reports = []
    for d in args.results:
        rep = analyse(d, args.first, skip)
        reports.append(rep)
        print(f"## {d} (first {args.first:g} L_vb of trace; routes without {sorted(skip)})")
        print("| policy | outside, first (L_vb) | outside, after | laid | precision | "
              "without the first part's loss |")  # fmt: skip
        print("|---|---|---|---|---|---|")
        for p, m in rep["summary"].items():
            print(f"| {p} | {m['outside_first']:.1f} | {m['outside_after']:.1f} | "
                  f"{m['laid']:.0f} | {m['precision']:.3f} | "
                  f"{m['precision_without_first']:.3f} |")  # fmt: skip
        table: dict[tuple[str, int], dict[str, float]] = defaultdict(dict)
        for e in rep["episodes"]:
            table[(e["target"], e["seed"])][e["policy"]] = e["outside_first"]
        pols = list(rep["summary"])
        print(f"\n| route | seed | {' | '.join(pols)} |")
        print("|---|---|" + "---|" * len(pols))
        for (t, s), v in sorted(table.items()):
            print(f"| {t} | {s} | " + " | ".join(f"{v.get(p, float('nan')):.1f}" for p in pols)
                  + " |")  # fmt: skip
        print()
    if args.out:
        args.out.write_text(json.dumps(reports, indent=1) + "\n")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())

"""Re-score ``is_success`` in saved ``cnt-evaluate`` results from their traces.

``info["is_success"]`` meant "route completed" until 2026-12-07; it now means the circuit
works: completed, every pad met, no trace in a keep-out
(:meth:`cnt_env.task.scoring.RouteScore.succeeded`). A results directory that kept its
traces (``episodes.json`` + ``traces.npz``) can be re-scored without simulating again:
each episode's final trace is scored against its route, the score found is checked
against the one recorded (the traces are saved as float32, so to ``--tolerance``), and
``is_success`` in ``episodes.json`` / ``episodes.csv`` and ``success_rate`` in
``results.csv`` are rewritten. Nothing else in the files changes.

    python benchmarks/rescore_success.py            # report what would change
    python benchmarks/rescore_success.py --write    # rewrite the files

With no directories given it takes every results directory with traces under
``training/results`` and ``benchmarks/results``. Exit status 1 when a recorded score is
not reproduced (the files are then left alone), 0 otherwise.
"""

from __future__ import annotations

import argparse
import csv
import io
import json
import sys
from collections.abc import Sequence
from pathlib import Path
from typing import Any

import numpy as np

from cnt_env.task import routes
from cnt_env.task.scoring import route_score
from training.evaluate import aggregate

ROOT = Path(__file__).resolve().parents[1]
DEFAULT_ROOTS = (ROOT / "training" / "results", ROOT / "benchmarks" / "results")
NEEDED = ("episodes.json", "traces.npz", "summary.json")  # what cnt-evaluate wrote


def result_dirs(roots: Sequence[Path]) -> list[Path]:
    """Every directory under ``roots`` with the files of :data:`NEEDED`."""
    found = {p.parent for r in roots for p in r.rglob("traces.npz")}
    return sorted(d for d in found if all((d / f).is_file() for f in NEEDED))


def rescore(path: Path, tolerance: float) -> tuple[list[dict[str, Any]], list[str]]:
    """The rows of ``path/episodes.json`` with ``is_success`` re-scored, and the problems
    found (a route that cannot be resolved, a target or a score not reproduced)."""
    summary = json.loads((path / "summary.json").read_text())
    if summary.get("env_kwargs", {}).get("score", "corridor") != "corridor":
        return [], []  # the thin score: success is its termination, unchanged
    custom = {k: routes.resolve(v, np.random.default_rng(0))
              for k, v in summary.get("custom_routes", {}).items()}  # fmt: skip
    rows = json.loads((path / "episodes.json").read_text())
    with np.load(path / "traces.npz") as npz:
        data = {k: npz[k] for k in npz.files}
    out, problems = [], []
    for i, row in enumerate(rows):
        name = row["target"]
        where = f"{path.name}: {row['policy']} {name} seed {row['seed']}"
        route = custom.get(name)
        if route is None:
            if name not in routes.HELD_OUT:
                problems.append(f"{where}: route {name!r} is neither held out nor recorded")
                continue
            route = routes.held_out(name)
        # The saved frame's origin is the reset contact node where it lay at the end (it
        # relaxes a little after reset), the score's where it lay at reset: the two
        # differ by the saved target's offset from the route.
        saved = np.asarray(data[f"target_{i}"], dtype=np.float64)
        shift = saved[0] - route.points[0]
        if saved.shape != route.points.shape or not np.allclose(saved - shift, route.points,
                                                                 atol=1e-3):  # fmt: skip
            problems.append(f"{where}: the saved target is not the route {name!r}")
            continue
        trace = np.asarray(data[f"trace_{i}"], dtype=np.float64)[1:] - shift  # row 0: origin
        score = route_score(route)
        m = score.update(trace, len(trace))
        phi = float(np.sum(score.potentials(m)))
        failed = bool(row.get("failure"))
        if not failed and abs(phi - row["score"]) > tolerance:
            problems.append(f"{where}: score {phi:.6f} from the trace, {row['score']:.6f} "
                            f"recorded")  # fmt: skip
            continue
        if row["is_success"] and not m["completed"]:  # either meaning implies completed
            problems.append(f"{where}: recorded a success the trace does not complete")
            continue
        out.append(dict(row, is_success=bool(score.succeeded(m)) and not failed))
    return out, problems


def _rewrite_csv(path: Path, column: str, value_of) -> str:
    """``path``'s text with ``column`` replaced by ``value_of(row)`` (None: kept)."""
    with path.open(newline="") as fh:
        reader = csv.DictReader(fh)
        fields, rows = list(reader.fieldnames or ()), list(reader)
    buf = io.StringIO()
    w = csv.DictWriter(buf, fieldnames=fields, lineterminator="\r\n")
    w.writeheader()
    for r in rows:
        v = value_of(r)
        w.writerow(r if v is None else dict(r, **{column: v}))
    return buf.getvalue()


def success_rates(rows: Sequence[dict[str, Any]]) -> dict[tuple[str, str], float]:
    """Per (policy, target) and (policy, "ALL") the ``success_rate`` of ``rows``, from
    ``cnt-evaluate``'s own table (:func:`training.evaluate.aggregate`)."""
    policies = list(dict.fromkeys(r["policy"] for r in rows))
    targets = list(dict.fromkeys(r["target"] for r in rows))
    seeds = sorted({r["seed"] for r in rows})
    table = aggregate(rows, policies, targets, seeds)
    return {(t["policy"], t["target"]): t["success_rate"] for t in table}


def recorded_rates_differ(path: Path, rows: Sequence[dict[str, Any]]) -> str:
    """Where ``path/results.csv``'s ``success_rate`` is not the rate of ``rows`` (the
    episodes as recorded): a check that the table was made from these episodes."""
    res = path / "results.csv"
    if not res.is_file():
        return ""
    rates = success_rates(rows)
    with res.open(newline="") as fh:
        for r in csv.DictReader(fh):
            v = rates.get((r["policy"], r["target"]))
            if v is None or abs(v - float(r["success_rate"])) > 1e-5:
                return f"{r['policy']} {r['target']}"
    return ""


def write(path: Path, rows: Sequence[dict[str, Any]]) -> None:
    """Rewrite ``is_success`` / ``success_rate`` in ``path``'s files from ``rows``."""
    (path / "episodes.json").write_text(json.dumps(list(rows)) + "\n")
    flag = {(r["policy"], r["target"], str(r["seed"])): r["is_success"] for r in rows}
    eps = path / "episodes.csv"
    if eps.is_file():
        text = _rewrite_csv(eps, "is_success",
                            lambda r: flag.get((r["policy"], r["target"], r["seed"])))  # fmt: skip
        eps.write_text(text, newline="")
    rates = success_rates(rows)
    res = path / "results.csv"
    if res.is_file():

        def rate(r: dict[str, str]) -> str | None:
            v = rates.get((r["policy"], r["target"]))
            return None if v is None else f"{v:.6g}"

        res.write_text(_rewrite_csv(res, "success_rate", rate), newline="")


def main(argv: Sequence[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("dirs", nargs="*", type=Path, help="results directories (default: all)")
    ap.add_argument("--write", action="store_true", help="rewrite the files")
    ap.add_argument(
        "--tolerance", type=float, default=1e-3,
        help="largest |score of the trace - score recorded| (float32 traces)",
    )  # fmt: skip
    args = ap.parse_args(argv)
    dirs = args.dirs or result_dirs(DEFAULT_ROOTS)
    for d in dirs:
        lacking = [f for f in NEEDED if not (d / f).is_file()]
        if lacking:
            ap.error(f"{d} has no {', '.join(lacking)}: it cannot be re-scored")
    status = 0
    for d in dirs:
        rows, problems = rescore(d, args.tolerance)
        for p in problems:
            print(f"  PROBLEM {p}")
        if problems:
            status = 1
            print(f"{d}: {len(problems)} problems, left alone")
            continue
        if not rows:
            print(f"{d}: the thin score, unchanged")
            continue
        old = json.loads((d / "episodes.json").read_text())
        stale = recorded_rates_differ(d, old)
        if stale:
            print(f"{d}: results.csv does not hold the rates of its episodes ({stale}), "
                  "left alone")  # fmt: skip
            status = 1
            continue
        flips = [(o["policy"], o["target"], o["seed"]) for o, n in zip(old, rows, strict=True)
                 if o["is_success"] != n["is_success"]]  # fmt: skip
        before = sum(o["is_success"] for o in old)
        after = sum(n["is_success"] for n in rows)
        print(f"{d.relative_to(ROOT) if d.is_relative_to(ROOT) else d}: {len(rows)} episodes, "
              f"successes {before} -> {after}")  # fmt: skip
        for f in flips:
            print(f"  no longer a success: {f[0]} {f[1]} seed {f[2]}")
        if args.write and flips:
            write(d, rows)
    return status


if __name__ == "__main__":
    sys.exit(main())

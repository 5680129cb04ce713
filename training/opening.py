"""Learn an opening on the model (issue 10): turns of a base policy's flow in a route's
first control steps, per context (``policies/opening.py``).

**Learn.** For reset seeds ``seed0, seed0 + 1, ...`` (routes drawn from the training
families at the env's difficulty: never a held-out route) the base is played once per
candidate turn (0 included) from the same start, on the held-out evaluation's env (the
model, ``training/configs/eval.yml``), each episode to its end; rows go to
``DIR/rows.jsonl`` (resumable: a finished episode is not run again) until
``--max-wall-seconds`` (0: fit the rows already there). **Fit** (``DIR/opening.json``):
per context, the paired gains score(turn) - score(0) over the seeds whose every turn
finished; a context gets the turn of the largest mean gain if that mean is positive, its
t statistic (mean over standard error) at least ``--t-min`` and its seeds at least
``--n-min`` [choice: 2 and 3, a one-sided ~95% rule on a handful of pairs, per test: with
~20 contexts and turns, about one passes by chance]; else no turn.

**Evaluate** (``--evaluate``): the base and the base with the opening on the held-out
routes and seeds, paired, on one machine::

    python -m training.opening --out runs/opening --max-wall-seconds 3600 --jobs 2
    python -m training.opening --out runs/opening --evaluate --seeds 0,1,2
"""

from __future__ import annotations

import argparse
import json
import math
import statistics
import sys
import time
from concurrent.futures import FIRST_COMPLETED, ProcessPoolExecutor, wait
from pathlib import Path
from typing import Any

from cnt_env.jsonl import append_row, read_rows

ROOT = Path(__file__).resolve().parents[1]
AGENT = ROOT / "policies/pretrained/ppo_residual.zip"


def _base(name: str, env: Any) -> Any:
    from policies import RouteFollower, load_policy

    if name == "follower":
        return RouteFollower.from_env(env)
    return load_policy(Path(name), env=env)


def play(job: dict[str, Any]) -> dict[str, Any]:
    """One episode of the base with a fixed turn (``job["turn"]``) at ``job["steps"]``,
    or with the opening of ``job["opening"]`` (a dict)."""
    from policies.opening import OpenedPolicy, Opening, context_of
    from training.common import env_settings, limit_threads, load_config, make_env

    limit_threads()
    env_kwargs, max_steps = env_settings(load_config(Path(job["config"])))
    env = make_env(env_kwargs, max_steps)
    options = {"target": job["target"]} if job.get("target") else None
    obs, info = env.reset(seed=job["seed"], options=options)
    base = env.unwrapped
    if job.get("opening") is not None:
        opening = Opening.from_dict(job["opening"])
    else:
        opening = Opening({}, tuple(job["steps"]), job["sectors"])
    context = context_of(obs, base.observation_slices, opening.sectors)
    if job.get("opening") is None:
        opening = Opening({context: job["turn"]}, opening.steps, opening.sectors)
    policy = OpenedPolicy(_base(job["base"], env), opening, base.vbar_max,
                          base.observation_slices)  # fmt: skip
    policy.reset(job["seed"])
    steps = 0
    while True:
        obs, _, term, trunc, info = env.step(policy.act(obs))
        steps += 1
        if term or trunc:
            break
    route = str(info.get("target", job.get("target") or ""))
    env.close()
    return {"seed": job["seed"], "target": job.get("target"), "route": route,
            "context": context, "turn": job.get("turn"), "opened": job.get("opening") is not None,
            "score": float(info["score"]), "shorts": int(info["shorts"]),
            "completed": bool(info["completed"]), "steps": steps}  # fmt: skip


def fit(rows: list[dict[str, Any]], turns: list[float], t_min: float,
        n_min: int) -> tuple[dict[str, float], dict[str, Any]]:  # fmt: skip
    """The table (context -> turn) and, per context and turn, the paired gains' n, mean
    and t statistic."""
    by_seed: dict[int, dict[float, dict[str, Any]]] = {}
    for r in rows:
        by_seed.setdefault(int(r["seed"]), {})[float(r["turn"])] = r
    gains: dict[str, dict[float, list[float]]] = {}
    for arms in by_seed.values():
        if not all(t in arms for t in turns) or 0.0 not in arms:
            continue
        ctx = arms[0.0]["context"]
        for t in turns:
            if t != 0.0:
                gains.setdefault(ctx, {}).setdefault(t, []).append(
                    arms[t]["score"] - arms[0.0]["score"]
                )
    table: dict[str, float] = {}
    stats: dict[str, Any] = {}
    for ctx, per_turn in sorted(gains.items()):
        stats[ctx] = {}
        best, best_mean = 0.0, 0.0
        for t, g in per_turn.items():
            mean = statistics.fmean(g)
            se = statistics.stdev(g) / math.sqrt(len(g)) if len(g) > 1 else math.inf
            tstat = mean / se if se > 0 else (math.inf if mean > 0 else 0.0)
            stats[ctx][str(t)] = {"n": len(g), "mean": round(mean, 5), "t": round(tstat, 2)}
            if len(g) >= n_min and mean > best_mean and tstat >= t_min:
                best, best_mean = t, mean
        if best != 0.0:
            table[ctx] = best
    return table, stats


def _run(jobs_iter, n_jobs: int, deadline: float, sink) -> int:
    """Run the jobs of ``jobs_iter`` on ``n_jobs`` processes, two in flight per process,
    until it is exhausted or ``deadline`` (time.monotonic) passes; ``sink(row)`` each
    result. The number run."""
    done = 0
    with ProcessPoolExecutor(max_workers=n_jobs) as pool:
        running: set = set()
        for job in jobs_iter:
            if time.monotonic() > deadline:
                break
            running.add(pool.submit(play, job))
            if len(running) >= 2 * n_jobs:
                finished, running = wait(running, return_when=FIRST_COMPLETED)
                for f in finished:
                    sink(f.result())
                    done += 1
        for f in running:
            sink(f.result())
            done += 1
    return done


def main(argv: list[str] | None = None) -> int:
    from cnt_env.cli.common import float_list, name_list, positive_int, seed_list
    from cnt_env.task.routes import HELD_OUT
    from policies.opening import Opening
    from training.common import EVAL_CONFIG, shown_path

    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--out", type=Path, required=True)
    ap.add_argument("--base", default=str(AGENT), help="a model .zip, or 'follower'")
    ap.add_argument("--turns", type=float_list, default="0,0.4,-0.4", help="radians")
    ap.add_argument("--steps", type=float_list, default="1,2,3", help="control steps turned")
    ap.add_argument("--sectors", type=positive_int, default=8)
    ap.add_argument("--seed0", type=int, default=1000)
    ap.add_argument("--max-wall-seconds", type=float, default=3600.0)
    ap.add_argument("--t-min", type=float, default=2.0)
    ap.add_argument("--n-min", type=positive_int, default=3)
    ap.add_argument("--config", type=Path, default=EVAL_CONFIG)
    ap.add_argument("--jobs", type=positive_int, default=2)
    ap.add_argument("--evaluate", action="store_true", help="held-out: base against opened")
    ap.add_argument("--targets", type=name_list, default=",".join(HELD_OUT))
    ap.add_argument("--seeds", type=seed_list, default="0,1,2")
    args = ap.parse_args(argv)
    turns = sorted(set(args.turns) | {0.0})
    steps = [int(s) for s in args.steps]
    args.out.mkdir(parents=True, exist_ok=True)
    common = {"base": args.base, "config": str(args.config), "sectors": args.sectors,
              "steps": steps}  # fmt: skip
    deadline = time.monotonic() + args.max_wall_seconds

    if args.evaluate:
        opening = Opening.load(args.out / "opening.json").to_dict()
        out = args.out / "evaluate.jsonl"
        rows: list[dict[str, Any]] = []

        def sink(row: dict[str, Any]) -> None:
            rows.append(row)
            append_row(out, row)

        jobs = [{**common, "target": t, "seed": s, "turn": 0.0,
                 **({"opening": opening} if opened else {})}
                for s in args.seeds for t in args.targets for opened in (False, True)]  # fmt: skip
        _run(iter(jobs), args.jobs, math.inf, sink)
        pairs: dict[tuple[str, int], dict[bool, float]] = {}
        for r in rows:
            pairs.setdefault((r["target"], r["seed"]), {})[r["opened"]] = r["score"]
        print("| target | seed | base | opened | gain |\n|---|---|---|---|---|")
        for (t, s), p in sorted(pairs.items()):
            print(f"| {t} | {s} | {p[False]:.3f} | {p[True]:.3f} | {p[True] - p[False]:+.3f} |")
        for opened in (False, True):
            per_seed = [statistics.fmean(p[opened] for (t, s), p in pairs.items() if s == seed)
                        for seed in args.seeds]  # fmt: skip
            print(f"{'opened' if opened else 'base'}: {statistics.fmean(per_seed):.4f} "
                  f"(per seed {', '.join(f'{v:.4f}' for v in per_seed)})")  # fmt: skip
        return 0

    rows_path = args.out / "rows.jsonl"
    rows = read_rows(rows_path)
    have = {(int(r["seed"]), float(r["turn"])) for r in rows}

    def sink(row: dict[str, Any]) -> None:
        rows.append(row)
        append_row(rows_path, row, echo=True)

    def jobs_iter():
        seed = args.seed0
        while True:
            for t in turns:
                if (seed, t) not in have:
                    yield {**common, "seed": seed, "turn": t}
            seed += 1

    t0 = time.perf_counter()
    n = _run(jobs_iter(), args.jobs, deadline, sink)
    table, stats = fit(rows, turns, args.t_min, args.n_min)
    opening = Opening(table, tuple(steps), args.sectors)
    record = {"opening": opening.to_dict(), "gains": stats, "turns": turns,
              "t_min": args.t_min, "n_min": args.n_min,
              "base": args.base if args.base == "follower" else shown_path(args.base, ROOT),
              "config": shown_path(args.config, ROOT), "episodes": len(rows), "run_this_time": n,
              "wall_s_this_run": round(time.perf_counter() - t0, 1)}  # fmt: skip
    (args.out / "opening.json").write_text(json.dumps(record, indent=1) + "\n")
    print(json.dumps(record, indent=1))
    return 0


if __name__ == "__main__":
    sys.exit(main())

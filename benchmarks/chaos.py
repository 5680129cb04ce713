"""How much of a route score is the flow schedule, and how much the rollout's chaos
(issue 10).

The route task is deterministic (one machine, one seed, one action sequence: one
rollout), but a rollout is chaotic: the same follower on the same seed scores 0.846 on
one machine and 0.785 on another (docs/architecture.md, "Determinism"). This benchmark
measures that sensitivity directly, on one machine. Each episode is replayed with the
flow of one control step (``--at``, default the first) turned by a tiny angle ε (default
1e-4 rad, a flow direction no experiment can set), and the final scores are compared:

- ``follower``: the route follower (``policies/route_follower.py``);
- ``agent``: the shipped residual PPO (``policies/pretrained/ppo_residual.zip``);
- ``oracle``: the planning oracle's recorded departures (``choices`` of a
  ``benchmarks/mpc_oracle.py`` row, read with ``--oracle-rows``) replayed over the
  follower: at step i the candidate ``choices[i]`` of ``training.oracle.candidates`` of
  the follower's action (the follower's own action past the record).

Unperturbed (ε = 0) the oracle replay lays the oracle's episode again where the machine
rounds as the recording one did. Perturbed, it tells whether the oracle's departures are
corrections that hold on a neighbouring trajectory (its gain survives) or picks among
chaotic outcomes of the rollouts (the gain falls to the follower's spread).

    python benchmarks/chaos.py --targets detour_block --seeds 2 --perturbations 6 \
        --modes follower,oracle,agent \
        --oracle-rows benchmarks/results/mpc_oracle_detour/detour_block_model.jsonl

writes one JSON line per episode to ``benchmarks/results/chaos/chaos.jsonl`` and prints
per route and mode the unperturbed score and the perturbed mean, std, min and max
(``--summarize``: the table of the episodes already in ``--out``, running nothing).
"""

from __future__ import annotations

import argparse
import math
import statistics
import sys
import time
from concurrent.futures import ProcessPoolExecutor
from pathlib import Path
from typing import Any

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))
from cnt_env.cli.common import name_list, nonnegative_int, seed_list  # noqa: E402
from cnt_env.jsonl import append_row, read_rows  # noqa: E402

OUT = ROOT / "benchmarks/results/chaos/chaos.jsonl"
AGENT = ROOT / "policies/pretrained/ppo_residual.zip"
MODES = ("follower", "agent", "oracle")


def perturbation(k: int, eps: float) -> float:
    """The turn (rad) of perturbation k: 0 for k = 0, then +eps, -eps, +2 eps, -2 eps, ..."""
    return 0.0 if k == 0 else (1 if k % 2 else -1) * eps * ((k + 1) // 2)


def episode(job: dict[str, Any]) -> dict[str, Any]:
    """One episode of ``job["mode"]`` with the flow of step ``job["at"]`` turned by
    ``job["turn"]``."""
    from policies import RouteFollower, load_policy
    from policies.opening import turned
    from training.common import env_settings, load_config, make_env
    from training.oracle import candidates

    env_kwargs, max_steps = env_settings(load_config(Path(job["config"])))
    env = make_env(env_kwargs, max_steps)
    obs, info = env.reset(seed=job["seed"], options={"target": job["target"]})
    if job["mode"] == "agent":
        policy = load_policy(AGENT, env=env)
    else:
        policy = RouteFollower.from_env(env)
    policy.reset(job["seed"])
    vbar_max = env.unwrapped.vbar_max
    choices = job.get("choices") or []
    t0 = time.perf_counter()
    step = 0
    while True:
        a = policy.act(obs)
        if job["mode"] == "oracle" and step < len(choices):
            a = candidates(a, vbar_max)[choices[step]]
        if step == job["at"]:
            a = turned(a, job["turn"], vbar_max)
        obs, _, term, trunc, info = env.step(a)
        step += 1
        if term or trunc:
            break
    env.close()
    return {
        "mode": job["mode"], "target": job["target"], "seed": job["seed"],
        "k": job["k"], "turn": job["turn"], "at": job["at"],
        "score": float(info["score"]), "inside": float(info["inside"]),
        "shorts": int(info["shorts"]), "completed": bool(info["completed"]),
        "steps": step, "config": job["config_shown"],
        "wall_s": round(time.perf_counter() - t0, 1),
    }  # fmt: skip


def oracle_choices(paths: list[Path]) -> dict[tuple[str, int], list[int]]:
    """(target, seed) -> the recorded ``choices`` of each oracle row of the files (the
    last row wins)."""
    out: dict[tuple[str, int], list[int]] = {}
    for path in paths:
        for row in read_rows(path):
            if row.get("mode") == "oracle" and row.get("choices") and row.get("horizon") is None:
                out[(row["target"], int(row["seed"]))] = [int(c) for c in row["choices"]]
    return out


def parse_jobs(argv: list[str] | None = None) -> tuple[argparse.Namespace, list[dict[str, Any]]]:
    from training.common import EVAL_CONFIG, shown_path

    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--targets", type=name_list, default="detour_block")
    ap.add_argument("--seeds", type=seed_list, default="0")
    ap.add_argument("--modes", type=name_list, default="follower")
    ap.add_argument(
        "--perturbations", type=nonnegative_int, default=6,
        help="perturbed episodes per route, seed and mode (and the unperturbed one)",
    )  # fmt: skip
    ap.add_argument("--eps", type=float, default=1e-4, help="turn of the first perturbation (rad)")
    ap.add_argument("--at", type=nonnegative_int, default=0, help="the control step perturbed")
    ap.add_argument(
        "--oracle-rows", type=str, default="",
        help="comma-separated mpc_oracle.py JSONL files holding the oracle's choices",
    )  # fmt: skip
    ap.add_argument("--config", type=Path, default=EVAL_CONFIG)
    ap.add_argument("--jobs", type=int, default=2)
    ap.add_argument("--out", type=Path, default=OUT, help="JSONL, appended (one ε per file)")
    ap.add_argument(
        "--summarize", action="store_true",
        help="run nothing: print the table of every episode already in --out",
    )  # fmt: skip
    args = ap.parse_args(argv)
    if args.summarize:
        return args, []
    bad = sorted(set(args.modes) - set(MODES))
    if bad:
        ap.error(f"--modes takes {', '.join(MODES)}; got {','.join(bad)}")
    if not (math.isfinite(args.eps) and args.eps > 0):
        ap.error("--eps must be a positive angle in radians")
    records = oracle_choices([Path(p) for p in args.oracle_rows.split(",") if p])
    jobs = []
    for s in args.seeds:
        for t in args.targets:
            for mode in args.modes:
                extra: dict[str, Any] = {}
                if mode == "oracle":
                    if (t, s) not in records:
                        ap.error(f"no oracle row with choices for {t}, seed {s} in --oracle-rows")
                    extra["choices"] = records[(t, s)]
                for k in range(args.perturbations + 1):
                    jobs.append({
                        "mode": mode, "target": t, "seed": s, "k": k, "at": args.at,
                        "turn": perturbation(k, args.eps), "config": str(args.config),
                        "config_shown": shown_path(args.config, ROOT), **extra,
                    })  # fmt: skip
    return args, jobs


def summary(rows: list[dict[str, Any]]) -> list[str]:
    """Per route, seed and mode: the unperturbed score, then the perturbed episodes'
    mean, std, min and max."""
    lines = ["| target | seed | mode | ε = 0 | perturbed: mean ± std | min | max | n |",
             "|---|---|---|---|---|---|---|---|"]  # fmt: skip
    groups: dict[tuple[str, int, str], list[dict[str, Any]]] = {}
    for r in rows:
        groups.setdefault((r["target"], r["seed"], r["mode"]), []).append(r)
    for (t, s, m), rs in sorted(groups.items()):
        base = [r["score"] for r in rs if r["k"] == 0]
        pert = [r["score"] for r in rs if r["k"] > 0]
        b = f"{base[0]:.3f}" if base else "-"
        if pert:
            sd = statistics.stdev(pert) if len(pert) > 1 else 0.0
            p = f"{statistics.fmean(pert):.3f} ± {sd:.3f} | {min(pert):.3f} | {max(pert):.3f}"
        else:
            p = "- | - | -"
        lines.append(f"| {t} | {s} | {m} | {b} | {p} | {len(pert)} |")
    return lines


def main(argv: list[str] | None = None) -> int:
    args, jobs = parse_jobs(argv)
    if args.summarize:
        if not args.out.is_file():
            print(f"chaos.py: no episodes in {args.out}", file=sys.stderr)
            return 2
        rows = read_rows(args.out)
        print("\n".join(summary(rows)))
        return 0
    args.out.parent.mkdir(parents=True, exist_ok=True)
    rows = []
    with ProcessPoolExecutor(max_workers=args.jobs) as pool:
        for row in pool.map(episode, jobs):
            rows.append(row)
            append_row(args.out, row, echo=True)
    print("\n".join(summary(rows)))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())

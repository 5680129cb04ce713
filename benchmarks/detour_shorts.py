"""The shipped residual agent and the follower on drawn detours, on the model (issue 10).

The held-out set has one route with a keep-out (``detour_block``, whose first leg runs
along +x) and no route whose first leg runs along -z.
This plays the routes the env draws for ``--count`` reset seeds from ``--first`` (its
default families at its default difficulty, as ``training/opening.py`` drew them) and
keeps those of ``--family`` (``any``: all) and, with ``--heading``, those whose first leg
runs along that axis: per route, the policies ``--policies`` of :data:`POLICIES`: the
follower; the agent as shipped (with its config's ``keepout_headings``: a route with a
keep-out whose first leg runs along -z is handed to the follower, policies/residual.py
``HeadingGate``); the agent without them (``ungated``); and the shield, the ungated agent
with its residual dropped (its base's action played) while the nearest keep-out point is
within ``--shield`` L_vb of the contact point (a probe of a safety shield); ``base``, the
agent's base alone (the follower with the options the agent's config pins). ``--agent``
plays another residual agent in their place (a cnt-train model, e.g. an unshipped run's).
Rows written before the gate was shipped (2026-12-06) have the ungated agent as "ungated".

    python benchmarks/detour_shorts.py --first 1000 --count 124 \
        --policies follower,ungated,shield --shield 30
    python benchmarks/detour_shorts.py --first 1000 --count 124 --policies follower,ungated \
        --config policies/pretrained/ppo_residual.yml \
        --out benchmarks/results/detour_shorts_surrogate.jsonl
    python benchmarks/detour_shorts.py --first 2000 --count 100 --family any --heading=-z \
        --policies follower,ungated --out benchmarks/results/minus_z_starts.jsonl
    python benchmarks/detour_shorts.py --first 6000 --count 400 --heading=+z \
        --policies follower,ungated --out benchmarks/results/plus_z_detours.jsonl

(and ``--family detour --heading=-z --policies agent`` or ``base`` on each, into
``*_agent.jsonl`` and ``*_base.jsonl``: benchmarks/RESULTS.md, issue 10, "Drawn detours";
the last with ``--policies ungated --agent MODEL.zip`` for unshipped agents, into
``plus_z_detours_<name>.jsonl``: "Mirrored starts in the first stage only")

writes one JSON line per episode to ``--out`` (default
``benchmarks/results/detour_shorts.jsonl``) and prints the mean score and the routes
shorted (trace in a keep-out: ``short_length`` > 0; a node in one for records made
before 2026-12-07) per policy. ``--config``: the env of a config's
``env_kwargs`` (default ``training/configs/eval.yml``, the model); the second command plays
the detours of the surrogate the agent was trained on. Each row records the axis the
route's first leg runs along and, for a shorted episode, the control step and progress
at its first short; ``--summarize FILE ...`` prints the summary of files again.
"""

from __future__ import annotations

import argparse
import math
import statistics
import sys
from concurrent.futures import ProcessPoolExecutor
from pathlib import Path
from typing import Any

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))
from cnt_env.jsonl import append_row, read_rows  # noqa: E402

OUT = ROOT / "benchmarks/results/detour_shorts.jsonl"
AGENT = ROOT / "policies/pretrained/ppo_residual.zip"
#: follower; the agent as shipped (with its config's keepout_headings); the agent without
#: them ("ungated"); the shield probe over the ungated agent; the agent's base alone
POLICIES = ("follower", "agent", "ungated", "shield", "base")


def _env(config: str | None = None):
    """The env of ``config`` (a training config's path; None: configs/eval.yml, the model)."""
    from training.common import EVAL_CONFIG, env_settings, limit_threads, load_config, make_env

    limit_threads()
    return make_env(*env_settings(load_config(config or EVAL_CONFIG)))


def drawn_route(job: tuple[int, str | None]) -> tuple[str, str]:
    """The family of the route the env of config ``job[1]`` draws at reset ``job[0]``, and
    the axis its first leg runs along (:func:`first_heading`)."""
    seed, config = job
    env = _env(config)
    _, info = env.reset(seed=seed)
    heading = first_heading(env.unwrapped.target.waypoints)
    env.close()
    return str(info["target"]), heading


def episode(job: dict[str, Any]) -> dict[str, Any]:
    """One episode of ``job["policy"]`` (one of :data:`POLICIES`) at reset ``job["seed"]``."""
    from policies import RouteFollower, load_policy
    from policies.residual import combine

    env = _env(job.get("config"))
    obs, info = env.reset(seed=job["seed"])
    route = env.unwrapped.observation_slices["route"]
    agent = job.get("agent") or AGENT
    if job["policy"] == "follower":
        policy = RouteFollower.from_env(env)
    elif job["policy"] == "agent":  # as shipped: its config's keepout_headings
        policy = load_policy(agent, env=env)
    else:  # ungated, shield, base: the agent without them
        policy = load_policy(agent, env=env, keepout_headings=())
        if job["policy"] == "base":  # its base alone, with the options its config pins
            policy = policy.base
    policy.reset(job["seed"])
    steps = shielded = 0
    first_short: tuple[int, float] | None = None  # (control step, progress G then)
    while True:
        if job["policy"] == "shield":
            b = policy.base.act(obs)
            o = policy.vecnormalize.normalize_obs(np.asarray(obs, dtype=np.float32)[None])
            a, _ = policy.model.predict(o, deterministic=True)
            action = combine(b, np.asarray(a, dtype=np.float32).reshape(-1), policy.scale)
            kx, kz = float(obs[route][1]), float(obs[route][2])
            if math.hypot(kx, kz) < job["shield"]:
                action, shielded = np.asarray(b, dtype=np.float32), shielded + 1
        else:
            action = policy.act(obs)
        obs, _, term, trunc, info = env.step(action)
        steps += 1
        first_short = short_onset(first_short, steps, info)
        if term or trunc:
            break
    heading = first_heading(env.unwrapped.target.waypoints)
    env.close()
    return {"seed": job["seed"], "route": str(info["target"]), "policy": job["policy"],
            "config": job.get("config"), "agent": job.get("agent"), "heading": heading,
            "shield": job.get("shield"), "score": float(info["score"]),
            "shorts": int(info["shorts"]), "short_length": float(info["short_length"]),
            "steps": steps, "shielded": shielded,
            "first_short_step": first_short and first_short[0],
            "progress_at_short": first_short and first_short[1]}  # fmt: skip


def short_onset(onset: tuple[int, float] | None, step: int, info: dict) -> tuple[int, float] | None:
    """(control step, progress G) where the episode's final run of steps with shorts began,
    updated after ``step``. ``info["shorts"]`` counts the unfrozen tail too, so a touch that
    the tail lifts off again is forgotten: only a short that lasts to the end has an onset
    (before 2026-12-06 the first touch was kept, e.g. seed 6189 in plus_z_detours.jsonl)."""
    if not shorted(info):
        return None
    return onset if onset is not None else (step, float(info["progress"]))


def shorted(record: dict[str, Any]) -> bool:
    """Whether an episode's record (or info) has trace in a keep-out: by its length in
    keep-outs (``short_length``, the score's measure since 2026-12-07), or by the nodes in
    them for records made before (a thin keep-out can be stepped over by the nodes)."""
    if "short_length" in record:
        return record["short_length"] > 0.0
    return record["shorts"] > 0


def first_heading(waypoints: np.ndarray) -> str:
    """The axis the route's first leg runs along: "+x", "-x", "+z" or "-z" (the nearest;
    :func:`policies.opening.axis_of`)."""
    from policies.opening import axis_of

    dx, dz = np.asarray(waypoints[1], dtype=float) - np.asarray(waypoints[0], dtype=float)
    return axis_of(dx, dz)


def summary(rows: list[dict[str, Any]]) -> list[str]:
    """Per policy: the mean score and the routes shorted, over all and per first heading."""
    from policies.opening import AXES

    lines = []
    for p in dict.fromkeys(r["policy"] for r in rows):
        rs = [r for r in rows if r["policy"] == p]
        hit = [r["seed"] for r in rs if shorted(r)]
        lines.append(f"{p}: mean {statistics.fmean(r['score'] for r in rs):.3f} over "
                     f"{len(rs)} routes, {len(hit)} shorted {hit}")  # fmt: skip
        for h in AXES:
            hs = [r for r in rs if r.get("heading") == h]
            if hs:
                at = [(r["seed"], r["first_short_step"], round(r["progress_at_short"], 2))
                      for r in hs if shorted(r)]  # fmt: skip
                lines.append(f"  first leg {h}: mean {statistics.fmean(r['score'] for r in hs):.3f}"
                             f" over {len(hs)}; shorted (seed, step, progress): {at}")  # fmt: skip
    return lines


def main(argv: list[str] | None = None) -> int:
    from cnt_env.cli.common import name_list, positive_int, seed_int
    from policies.opening import AXES

    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--first", type=seed_int, default=1000, help="the first reset seed")
    ap.add_argument("--count", type=positive_int, default=124, help="reset seeds drawn")
    ap.add_argument("--family", default="detour", help="the family kept, or 'any'")
    ap.add_argument("--heading", choices=AXES,
                    help="keep only routes whose first leg runs along this axis")  # fmt: skip
    ap.add_argument("--policies", type=name_list, default="follower,agent,ungated,shield")
    ap.add_argument("--shield", type=float, default=30.0, help="L_vb (policy 'shield')")
    ap.add_argument("--jobs", type=int, default=2)
    ap.add_argument(
        "--config",
        help="the env of this config's env_kwargs (default: "
        "training/configs/eval.yml, the model; the agent's own, "
        "policies/pretrained/ppo_residual.yml, is the surrogate it trained on)",
    )
    ap.add_argument("--agent", type=Path,
                    help="the residual agent (a cnt-train .zip with its .yml) that plays "
                    "agent, ungated, shield and base (default: the shipped one, "
                    "policies/pretrained/ppo_residual.zip)")  # fmt: skip
    ap.add_argument("--out", type=Path, default=OUT)
    ap.add_argument("--summarize", type=Path, nargs="+", metavar="JSONL",
                    help="print the summary of files this wrote, and run nothing")  # fmt: skip
    args = ap.parse_args(argv)
    if args.summarize is not None:
        missing = [str(f) for f in args.summarize if not f.is_file()]
        if missing:
            ap.error(f"--summarize: no such file {', '.join(missing)}")
        rows = [row for f in args.summarize for row in read_rows(f)]
        print("\n".join(summary(rows)))
        return 0
    bad = sorted(set(args.policies) - set(POLICIES))
    if bad:
        ap.error(f"--policies takes {', '.join(POLICIES)}; got {','.join(bad)}")
    if args.config is not None and not Path(args.config).is_file():
        ap.error(
            f"--config {args.config}: no such file (a training config, e.g. "
            "policies/pretrained/ppo_residual.yml)"
        )
    if args.agent is not None and not args.agent.is_file():
        ap.error(f"--agent {args.agent}: no such file (a model saved by cnt-train, .zip)")
    rows: list[dict[str, Any]] = []
    args.out.write_text("")  # a fresh file per run; rows are appended as episodes end
    with ProcessPoolExecutor(max_workers=args.jobs) as pool:
        drawn = list(range(args.first, args.first + args.count))
        kinds = list(pool.map(drawn_route, [(s, args.config) for s in drawn]))
        seeds = [s for s, (f, h) in zip(drawn, kinds, strict=True)
                 if args.family in ("any", f) and args.heading in (None, h)]  # fmt: skip
        if not seeds:
            print(f"no route of family {args.family!r}" + (f", first leg {args.heading}" if
                  args.heading else "") + f" in reset seeds {drawn[0]}-{drawn[-1]}",
                  file=sys.stderr)  # fmt: skip
            return 1
        agent = None if args.agent is None else str(args.agent)
        jobs = [{"seed": s, "policy": p, "shield": args.shield if p == "shield" else None,
                 "config": args.config, "agent": agent}
                for s in seeds for p in args.policies]  # fmt: skip
        for row in pool.map(episode, jobs):
            rows.append(row)
            append_row(args.out, row, echo=True)
    print("\n".join(summary(rows)))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())

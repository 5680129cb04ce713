"""Model selection on more validation routes: does it pick a better agent?

A training run keeps ``best_model.zip`` by its HeldOutEval score on four validation routes
(4 episodes per evaluation), and checkpoints every 20k steps. This scores every given
model on ``--routes`` validation routes (routes drawn from the training families with the
fixed reset seeds 50 000 + i, ``training.common.VALIDATION_SEED0``; never a held-out test
route), and, with ``--heldout`` (a ``cnt-evaluate`` results directory that evaluated the
same models), sets each model's validation mean beside its held-out mean: the model a
larger validation set would pick from each run, and how well the two agree.

    python benchmarks/checkpoint_selection.py --models DIR [DIR ...] \
        --names ppo_a40,ppo_abest,... --routes 12 --jobs 2 [--heldout RESULTS_DIR] \
        [--difficulty D] [--out FILE.json]

A name ``a+b`` is the ensemble of models a and b (``cnt-evaluate``'s, the mean of their
actions).

The run's prefix groups the names (``ppo_a40`` and ``ppo_abest`` are run ``ppo_a``):
the selection is made within a run, as one run's budget allows.
"""

from __future__ import annotations

import argparse
import json
import re
import time
from concurrent.futures import ProcessPoolExecutor
from pathlib import Path

import numpy as np

from cnt_env.cli.common import name_list


def _episode(job: tuple[str, str, int, str, float | None]) -> tuple[str, int, float]:
    """Score of model ``name`` (or the follower, ``scripted``) on validation route i (drawn
    at ``difficulty``; None: the config's)."""
    from training.common import VALIDATION_SEED0, env_settings, limit_threads, load_config, make_env
    from training.evaluate import _make_policy, _play, ensemble_members, model_file

    limit_threads()
    models, name, i, config, difficulty = job
    env_kwargs, max_steps = env_settings(load_config(config))
    if difficulty is not None:
        env_kwargs = {**env_kwargs, "difficulty": difficulty}
    env = make_env(env_kwargs, max_steps)
    spec = (
        {"kind": "scripted"}
        if name == "scripted"
        else {"kind": name, "models": [str(model_file(m, models)) for m in ensemble_members(name)]}
    )
    policy = _make_policy(spec, env)
    obs, _ = env.reset(seed=VALIDATION_SEED0 + i)
    policy.reset(i)
    score = float(_play(env, policy, obs)[2]["score"])
    env.close()
    return name, i, score


def _heldout(results: Path) -> dict[str, float]:
    """Mean held-out score per policy, from a cnt-evaluate results directory's summary."""
    policies = json.loads((results / "summary.json").read_text())["policies"]
    return {k: float(v["score_mean"]) for k, v in policies.items()}


def main(argv: list[str] | None = None) -> None:
    from training.common import CONFIG_DIR, VALIDATION_SEED0

    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--models", nargs="+", required=True,
                   help="model directories, the first holding a name wins")  # fmt: skip
    p.add_argument("--names", type=name_list, required=True, help="comma separated model names")
    p.add_argument("--routes", type=int, default=12)
    p.add_argument("--jobs", type=int, default=2)
    p.add_argument("--config", default=str(CONFIG_DIR / "ppo_residual.yml"))
    p.add_argument("--difficulty", type=float, default=None,
                   help="draw routes at this difficulty (None: config's)")  # fmt: skip
    p.add_argument("--heldout", default=None, help="cnt-evaluate results dir of the models")
    p.add_argument("--out", default=None, help="JSON file of the scores")
    args = p.parse_args(argv)
    names = ["scripted", *args.names]
    jobs = [(args.models, n, i, args.config, args.difficulty)
            for n in names for i in range(args.routes)]  # fmt: skip
    t0 = time.perf_counter()
    scores: dict[str, list[float]] = {n: [float("nan")] * args.routes for n in names}
    with ProcessPoolExecutor(max_workers=args.jobs) as pool:
        for name, i, s in pool.map(_episode, jobs):
            scores[name][i] = s
    wall = time.perf_counter() - t0
    held = _heldout(Path(args.heldout)) if args.heldout else {}
    val = {n: float(np.mean(v)) for n, v in scores.items()}
    last = VALIDATION_SEED0 + args.routes - 1
    print(f"{args.routes} validation routes (reset seeds {VALIDATION_SEED0}-{last}), "
          f"{len(jobs)} episodes in {wall:.0f} s")  # fmt: skip
    print("| model | validation mean | held-out mean |")
    print("|---|---|---|")
    for n in names:
        h = f"{held[n]:.3f}" if n in held else "-"
        print(f"| {n} | {val[n]:.3f} | {h} |")
    runs: dict[str, list[str]] = {}
    for n in names[1:]:
        runs.setdefault(re.sub(r"(\d+|best|final)$", "", n), []).append(n)
    picks = {}
    for run, members in runs.items():
        pick = max(members, key=val.__getitem__)
        picks[run] = pick
        line = f"run {run}: validation picks {pick} ({val[pick]:.3f})"
        if held and all(m in held for m in members):
            best = max(members, key=held.__getitem__)
            line += (f", held-out {held[pick]:.3f}; its best_model {held.get(run + 'best', 0):.3f};"
                     f" the best held-out member {best} {held[best]:.3f}")  # fmt: skip
        print(line)
    both = [n for n in names[1:] if n in held]
    if len(both) > 2:
        r = float(np.corrcoef([val[n] for n in both], [held[n] for n in both])[0, 1])
        print(f"correlation of validation and held-out means over {len(both)} models: {r:.2f}")
    if args.out:
        Path(args.out).write_text(json.dumps({
            "routes": args.routes, "models": args.models, "config": args.config,
            "difficulty": args.difficulty,
            "validation": scores, "validation_mean": val, "heldout_mean": held,
            "picks": picks, "wall_s": round(wall, 1),
        }, indent=1) + "\n")  # fmt: skip


if __name__ == "__main__":
    main()

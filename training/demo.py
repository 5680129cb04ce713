"""End-to-end demo (``cnt-demo``; the main job of ``make demo``), within a time budget.

    cnt-demo [--budget-minutes 10] [--targets jog,s_curve,hairpin] [--seeds 0,1,2]
             [--out demo_out] [--no-train] [--no-rrd]

1. A short PPO training run (about a quarter of the budget, stopped by wall time; its
   model, VecNormalize stats, checkpoints, learning curve and tensorboard logs land in
   ``<out>/runs/ppo_s0``), to show the pipeline working end to end.
2. Evaluation of random, constant (the committed grid-search choice,
   ``training/results/constant_best.json``), scripted and the pretrained PPO, SAC and
   residual PPO (``policies/pretrained``) on a subset of held-out targets with 3 seeds: the table,
   ``summary.json`` and the trace plots in ``<out>/results``, the learning curve of
   step 1.
3. A rerun recording per policy and target (first seed) in ``<out>/rrd`` when rerun is
   installed (``pip install -e ".[rerun]"``), else a message.

The short run is for show: with a 2-minute budget it is far from the pretrained
models, whose training (``cnt-train``, configs in ``training/configs``) took ~20 min
each on 2 shared cores.
"""

from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path

from .common import CONFIG_DIR, load_config
from .evaluate import PRETRAINED, evaluate
from .train import train

RESULTS = Path(__file__).resolve().parent / "results"
#: Config of the demo: the task the pretrained models were trained on.
DEMO_CONFIG = "ppo_thin.yml"
#: Share of the budget given to the short training run.
TRAIN_SHARE = 0.25


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(prog="cnt-demo", description=__doc__.split("\n\n")[0],
                                formatter_class=argparse.ArgumentDefaultsHelpFormatter)  # fmt: skip
    p.add_argument("--budget-minutes", type=float, default=10.0)
    p.add_argument("--targets", default="jog,s_curve,hairpin")
    p.add_argument("--seeds", default="0,1,2")
    p.add_argument("--out", type=Path, default=Path("runs/demo"), help="output folder")
    p.add_argument("--jobs", type=int, default=2)
    p.add_argument("--no-train", action="store_true", help="skip the short training run")
    p.add_argument("--no-rrd", action="store_true", help="skip the rerun recordings")
    args = p.parse_args(argv)
    t0 = time.perf_counter()
    budget = 60.0 * args.budget_minutes
    targets = [t for t in args.targets.split(",") if t]
    seeds = [int(s) for s in args.seeds.split(",") if s]
    # the thin task's config: the pretrained models and committed results are of the v0
    # task until the route task's final training lands (training/README.md)
    config = load_config(CONFIG_DIR / DEMO_CONFIG)
    runs = []
    if not args.no_train:
        train_s = TRAIN_SHARE * budget
        cfg = dict(config, eval_targets=targets[:1], n_eval_episodes=1,
                   eval_freq=1024, save_freq=1024)  # fmt: skip
        print(f"[demo] 1/3 short PPO run, {train_s:.0f} s of wall time")
        train("ppo", cfg, args.out / "runs" / "ppo_s0", seed=0, max_wall_seconds=train_s)
        runs.append(args.out / "runs" / "ppo_s0")
    print(f"[demo] 2/3 evaluation on {targets}, seeds {seeds} (pretrained PPO and SAC)")
    policies = ["random", "constant", "scripted", "ppo", "sac"]
    if (PRETRAINED / "ppo_residual.zip").is_file():
        policies.append("ppo_residual")
    evaluate(
        policies,
        targets,
        seeds,
        config,
        args.out / "results",
        models=PRETRAINED,
        runs=runs,
        constant_from=RESULTS / "constant_best.json",
        jobs=args.jobs,
        save_episodes=args.out / "episodes",
        rrd=None if args.no_rrd else args.out / "rrd",
    )
    print(f"[demo] 3/3 done in {time.perf_counter() - t0:.0f} s; see {args.out}/results")
    return 0


if __name__ == "__main__":
    sys.exit(main())

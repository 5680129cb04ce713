"""Two training stages inside one wall-time budget: the shipped residual agent's recipe.

    python -m training.two_stage \\
        --stage1 training/configs/ppo_residual_recipe_shipped.yml \\
        --stage2 training/configs/ppo_residual_shipped_detour_finetune.yml \\
        --seed 1 [--stage1-seconds 2400] [--total-seconds 3600] \\
        [--steps-per-second 50] [--startup-seconds 45] [--out runs]
    python -m training.two_stage --stage1-model STAGE1/ppo.zip --stage1-spent 2406 \\
        --stage2 CONFIG --stage2-seed 1 [--total-seconds 3600] [--out runs]

Stage 1 trains ``--stage1`` from scratch (seed ``--seed``) until its ``n_timesteps`` or
``--stage1-seconds`` of wall time, whichever comes first (its learning-rate schedule
runs over ``n_timesteps``; the shipped run was stopped by the wall). Stage 2 goes on
training stage 1's final model with ``--stage2`` (cnt-train's ``--trained-agent`` with
``--new-base-options``: the residual's base follower takes stage 2's options, recorded
as ``base_kwargs_was``) for what is left of ``--total-seconds``, less
``--startup-seconds`` for its start-up, with ``n_timesteps`` = that time x
``--steps-per-second`` so that its schedule anneals inside it (seed ``--stage2-seed``).
Both stages' start-ups count against the total.

The shipped agent (``policies/pretrained/ppo_residual``) was trained by this sequence
written out as a shell script (``training/results/route_runs/resid_two40_s1/drive.sh``,
which rewrote the stage-1 model's base options instead of ``--new-base-options``); the
defaults above are its numbers, with its stage-1 config ``ppo_residual_recipe_shipped.yml``
and its second stage ``ppo_residual_shipped_detour_finetune.yml``.

With ``--stage1-model PATH --stage1-spent SECONDS`` stage 1 is not trained: stage 2 goes
on from that model (a cnt-train zip with its ``.yml``, which stands for ``--stage1`` in the
check below) and ``SECONDS``, the wall time that model cost with its start-up, counts
against the total: a second stage tried again over one first stage, inside the same hour
(``route_runs/mirror_stage1``, ``mirror_symgate`` and ``mirror_stage1_s1`` ran that as
shell lines over ``route_runs/mirror_hour``'s first stage, 2 406 s).

One run directory ``<out>/two_stage_s<seed>/``, or with ``--stage1-model``
``<out>/stage2_s<stage2-seed>/`` (``_2``, ``_3``, ... when it exists: a run never
overwrites an earlier one) holds ``stage1/`` (not with ``--stage1-model``), ``stage2/``
(each a cnt-train run directory) and ``timing.json`` (the wall time of each stage, the
steps given to stage 2).
"""

from __future__ import annotations

import argparse
import json
import sys
import time
from pathlib import Path
from typing import Any

from policies.sb3 import ALGOS

from .common import (
    check_dir_option,
    fresh_dir,
    load_config,
    normalize_settings,
    parse_cli,
    positive_float,
    seed_int,
)
from .train import check_acts_alike, check_config, train

__all__ = ["main", "run_two_stages", "stage2_budget"]


def stage2_budget(total_s: float, elapsed_s: float, startup_s: float,
                  steps_per_second: float) -> tuple[float, int]:  # fmt: skip
    """Stage 2's wall time and steps: what is left of ``total_s`` after ``elapsed_s`` and
    the start-up allowance, and that time x ``steps_per_second``. Raises ValueError when
    nothing is left."""
    left = total_s - elapsed_s - startup_s
    steps = int(left * steps_per_second)
    if left <= 0.0 or steps < 1:
        raise ValueError(f"stage 1 took {elapsed_s:.0f} s of the {total_s:.0f} s budget: no "
                         f"time is left for stage 2 (start-up allowance {startup_s:.0f} s); "
                         "give a shorter --stage1-seconds or a longer --total-seconds")  # fmt: skip
    return left, steps


def run_two_stages(algo: str, stage1: dict[str, Any], stage2: dict[str, Any], out: Path,
                   seed: int, stage2_seed: int, stage1_s: float, total_s: float,
                   steps_per_second: float, startup_s: float = 45.0,
                   progress_bar: bool = False, stage1_model: Path | None = None,
                   stage1_spent_s: float = 0.0) -> Path:  # fmt: skip
    """Train both stages into ``out`` (made here); returns stage 2's final model. Given
    ``stage1_model``, stage 1 is that model and ``stage1_spent_s`` its wall time (``stage1``
    and ``stage1_s`` are then unused)."""
    t0 = time.monotonic()
    if stage1_model is None:
        first = train(algo, stage1, out / "stage1", seed=seed, max_wall_seconds=stage1_s,
                      progress_bar=progress_bar)  # fmt: skip
        t1 = time.monotonic()
    else:
        first, t1 = Path(stage1_model), time.monotonic()
        t0 = t1 - stage1_spent_s
    left, steps = stage2_budget(total_s, t1 - t0, startup_s, steps_per_second)
    second = train(algo, {**stage2, "n_timesteps": steps}, out / "stage2", seed=stage2_seed,
                   max_wall_seconds=left, progress_bar=progress_bar, trained_agent=first,
                   new_base_options=True)  # fmt: skip
    t2 = time.monotonic()
    timing = {"stage1_s": round(t1 - t0, 1), "stage2_s": round(t2 - t1, 1),
              "total_s": round(t2 - t0, 1), "budget_s": total_s,
              "stage2_budget_s": round(left, 1), "stage2_n_timesteps": steps,
              "stage1_model": str(first)}  # fmt: skip
    (out / "timing.json").write_text(json.dumps(timing, indent=1) + "\n")
    return second


def build_parser() -> argparse.ArgumentParser:
    p = argparse.ArgumentParser(prog="python -m training.two_stage",
                                description=__doc__.splitlines()[0])  # fmt: skip
    p.add_argument("--algo", choices=ALGOS, default="ppo")
    p.add_argument("--stage1", type=Path, default=None, help="stage 1's config (rl-zoo YAML)")
    p.add_argument("--stage1-model", type=Path, default=None,
                   help="a trained stage 1 (cnt-train zip): go on from it")  # fmt: skip
    p.add_argument("--stage1-spent", type=positive_float, default=None,
                   help="with --stage1-model: its wall time (s), start-up in")  # fmt: skip
    p.add_argument("--stage2", type=Path, required=True, help="stage 2's config (rl-zoo YAML)")
    p.add_argument("--seed", type=seed_int, default=0, help="stage 1's seed")
    p.add_argument("--stage2-seed", type=seed_int, default=0, help="stage 2's seed")
    p.add_argument("--stage1-seconds", type=positive_float, default=2400.0)
    p.add_argument("--total-seconds", type=positive_float, default=3600.0)
    p.add_argument("--steps-per-second", type=positive_float, default=50.0,
                   help="stage 2's n_timesteps per second of its wall time")  # fmt: skip
    p.add_argument("--startup-seconds", type=positive_float, default=45.0,
                   help="kept from stage 2's wall time for its start-up")  # fmt: skip
    p.add_argument("--out", type=Path, default=Path("runs"), help="parent of the run directory")
    p.add_argument("--progress", action="store_true", help="progress bars")
    return p


def main(argv: list[str] | None = None) -> int:
    parser = build_parser()
    args = parse_cli(parser, argv)
    given = args.stage1_model is not None
    if (args.stage1 is not None) == given:  # exactly one of the two
        parser.error("give one of --stage1 (a config to train) and --stage1-model (trained)")
    if given != (args.stage1_spent is not None):
        parser.error("--stage1-model and --stage1-spent go together")
    if given:
        args.stage1_model = args.stage1_model.with_suffix(".zip")
        args.stage1 = args.stage1_model.with_suffix(".yml")  # its resolved config
        if not args.stage1_model.is_file():
            parser.error(f"--stage1-model {args.stage1_model} does not exist")
        try:  # the budget is known before anything runs
            stage2_budget(args.total_seconds, args.stage1_spent, args.startup_seconds,
                          args.steps_per_second)  # fmt: skip
        except ValueError as exc:
            parser.error(str(exc).replace("--stage1-seconds", "--stage1-spent"))
    elif args.stage1_seconds >= args.total_seconds:
        parser.error("--stage1-seconds must be below --total-seconds (stage 2 needs time)")
    try:  # both configs checked before anything trains
        stage1, stage2 = load_config(args.stage1), load_config(args.stage2)
        for config in (stage1, stage2):
            check_config(config)
        # stage 2 must accept stage 1's agent (cnt-train --trained-agent's check)
        check_acts_alike(stage1, stage2, True, bool(normalize_settings(stage1)),
                         f"stage 1's agent ({args.stage1.name})")  # fmt: skip
    except (ValueError, OSError) as exc:
        parser.error(str(exc))
    check_dir_option(parser, "out", args.out)
    # named by the seed that trains: --seed is unused over a given first stage
    name = f"stage2_s{args.stage2_seed}" if given else f"two_stage_s{args.seed}"
    run = fresh_dir(args.out / name)
    model = run_two_stages(args.algo, stage1, stage2, run, args.seed, args.stage2_seed,
                           args.stage1_seconds, args.total_seconds, args.steps_per_second,
                           args.startup_seconds, progress_bar=args.progress,
                           stage1_model=args.stage1_model,
                           stage1_spent_s=args.stage1_spent or 0.0)  # fmt: skip
    print(f"stage 2's final model: {model}")
    return 0


if __name__ == "__main__":
    sys.exit(main())

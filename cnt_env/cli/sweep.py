"""``cnt-sim sweep``: argparse and formatting over :mod:`cnt_env.sweep` (docs/cli.md).

Exit codes as ``cnt-sim run``: 0, 1 when a point failed (the sweep still finishes and
records it), 2 on bad input (before any simulation).
"""

from __future__ import annotations

import argparse
import math
import sys
from collections.abc import Mapping, Sequence
from pathlib import Path
from typing import Any

from cnt_env import runs, sweep, units
from cnt_env.cli.common import (
    EXIT_FAILED,
    EXIT_OK,
    PROG,
    CliError,
    add_group_arguments,
    add_limit_arguments,
    add_model_arguments,
    add_settled_argument,
    package_version,
    print_json,
    warn,
)
from cnt_env.io import OutputSet, config_json_text
from cnt_env.sweep import (
    BACKENDS,
    DEFAULT_OUT,
    MAX_POINTS,
    MAX_POINTS_CEILING,
    SweepPoint,
    row_class,
)


def _float(value: Any) -> float:
    try:
        return float(value)
    except (TypeError, ValueError):
        return math.nan


def _fmt(value: Any, spec: str = ".4g") -> str:
    v = _float(value)
    return "-" if not math.isfinite(v) else format(v, spec)


def _point_line(point: SweepPoint, row: Mapping[str, Any], done: int, total: int) -> str:
    what = row_class(row)
    if row.get("failure") and what == "failed":
        what = f"FAILED ({row['failure'][:160]})"
    return (
        f"[{done}/{total}] {point.label()}: {what}, amplitude {_fmt(row.get('amplitude'))}, "
        f"wavelength {_fmt(row.get('wavelength'))}, {_fmt(row.get('wall_time_s'), '.1f')} s"
    )


def format_table(rows: Sequence[Mapping[str, Any]], params: Sequence[str]) -> str:
    head = [*params, "seed", "pattern", "amplitude", "wavelength", "n_uturns", "wall_s"]
    lines = [head]
    for row in rows:
        lines.append(
            [_fmt(row[p], ".6g") for p in params]
            + [
                str(row["seed"]),
                row_class(row),
                _fmt(row.get("amplitude")),
                _fmt(row.get("wavelength")),
                _fmt(row.get("n_uturns"), ".0f"),
                _fmt(row.get("wall_time_s"), ".1f"),
            ]
        )
    widths = [max(len(line[i]) for line in lines) for i in range(len(head))]
    return "\n".join(
        "  ".join(c.ljust(w) for c, w in zip(line, widths, strict=True)) for line in lines
    )


def sweep_options(args: argparse.Namespace) -> sweep.SweepOptions:
    """The typed inputs of a sweep from parsed flags."""
    from cnt_env.cli.run import run_options

    return sweep.SweepOptions(
        run=run_options(args),
        axes=(
            sweep.Axis(args.param, args.values, args.range, ""),
            sweep.Axis(args.param2, args.values2, args.range2, "2"),
        ),
        repeats=args.repeats,
        seed_per_point=args.seed_per_point,
        jobs=args.jobs,
        backend=args.backend,
        ray_address=args.ray_address,
        retry_failed=args.retry_failed,
        out=args.out,
        plots=args.plots,
        no_plots=args.no_plots,
        traces=args.traces,
        max_points=args.max_points,
        argv=tuple(getattr(args, "argv", None) or ()),
    )


def cmd_sweep(args: argparse.Namespace) -> int:
    if args.backend == "ray":
        sweep.import_ray()  # a missing extra is a usage error, found before any work
    plan = sweep.resolve_sweep(sweep_options(args), warn=warn)
    config_json = Path(f"{plan.csv_path}.json")
    OutputSet().check(config_json, "--out")  # the path now; the file once the CSV is accepted

    bar = None

    def on_start(n_todo: int, n_skipped: int) -> None:
        # the CSV passed its checks (a different sweep or a foreign file is refused before
        # this): only now does its record describe this sweep
        with OutputSet() as outputs:
            outputs.write_text(config_json, "--out",
                               config_json_text(plan.csv_path, plan.resolved))  # fmt: skip
        nonlocal bar
        if not args.json and sys.stderr.isatty() and n_todo:
            from tqdm import tqdm

            bar = tqdm(total=n_todo, file=sys.stderr, desc="sweep", unit="point")
        elif not args.json and n_skipped:
            print(f"{PROG} sweep: {n_skipped} points already in {plan.csv_path}",
                  file=sys.stderr)  # fmt: skip

    def on_result(point: SweepPoint, row: Mapping[str, Any], done: int, total: int) -> None:
        if bar is not None:
            bar.update(1)
            bar.set_postfix_str(f"{point.label()}: {row_class(row)}")
        elif not args.json:
            print(_point_line(point, row, done, total), file=sys.stderr)

    try:
        outcome = sweep.execute(plan, on_result=on_result, on_start=on_start, warn=warn)
    finally:
        if bar is not None:
            bar.close()

    written: list[Path] = []
    if plan.plots_dir is not None:
        try:
            written = sweep.plot_sweep(sweep.plan_rows(plan), plan.params, plan.grids,
                                       plan.plots_dir, plan.csv_path.stem)  # fmt: skip
        except OSError as exc:
            raise CliError(f"cannot write the plots: {exc}", EXIT_FAILED) from exc

    rows = outcome["rows"]
    others = outcome["other_configs"]
    if others:  # a changed base config is another sweep in the same file
        warn(f"{plan.csv_path} also holds rows of {len(others)} other configuration(s) "
             f"(config_hash {', '.join(others)[:120]}); {config_json} describes this one "
             f"({plan.config_hash}): pass another --out to keep sweeps apart")  # fmt: skip
    failed = [r for r in rows if row_class(r) == "failed"]
    summary = {
        "csv": str(plan.csv_path),
        "config": str(config_json),
        "plots": [str(p) for p in written],
        "config_hash": plan.config_hash,
        "params": list(plan.params),
        "n_points": outcome["n_points"],
        "n_run": outcome["n_run"],
        "n_skipped": outcome["n_skipped"],
        "n_failed": len(failed),
        "wall_time_s": outcome["wall_time_s"],
        "version": package_version(),
        "rows": rows,
    }
    if args.json:
        print_json(summary)
    else:
        print(
            f"{PROG} sweep: {outcome['n_points']} points over {' x '.join(plan.params)} "
            f"({outcome['n_run']} run, {outcome['n_skipped']} already done, "
            f"{len(failed)} failed) in {outcome['wall_time_s']:.1f} s"
        )
        print(format_table(rows, plan.params))
        print(f"wrote {plan.csv_path} (config: {config_json})")
        for path in written:
            print(f"wrote {path}")
    return EXIT_FAILED if failed else EXIT_OK


def add_parser(sub: Any) -> argparse.ArgumentParser:
    """Add the ``sweep`` subcommand to ``cnt-sim``'s subparsers."""
    p = sub.add_parser(
        "sweep",
        help="run a grid of depositions in parallel (CSV and plots)",
        allow_abbrev=False,
        description="Run a one- or two-parameter grid of depositions in parallel, "
        "resumably, and plot amplitude, wavelength and pattern class. Negative values "
        "need the = form: --values=-1,1.",
    )
    p.add_argument("--preset", choices=units.PRESETS, default="coil", help="base groups")
    p.add_argument(
        "--substrate", choices=("flat", "stepped"), default=None, help="default: the preset's"
    )

    grid = p.add_argument_group("grid (NAME: any dimensionless group, e.g. vbar, Ibar, kappa-c)")
    grid.add_argument("--param", metavar="NAME", help="the swept group")
    grid.add_argument("--values", metavar="A,B,...", help="its values")
    grid.add_argument("--range", metavar="START:STOP:N[:log]", help="N values, ends included")
    grid.add_argument("--param2", metavar="NAME", help="a second swept group (2-D grid)")
    grid.add_argument("--values2", metavar="A,B,...")
    grid.add_argument("--range2", metavar="START:STOP:N[:log]")
    grid.add_argument(
        "--repeats", type=int, default=1, help="seeds per point: seed, seed+1, ... (default 1)"
    )

    g = p.add_argument_group("base groups (override the preset; lengths in L_vb)")
    add_group_arguments(g)
    g.add_argument(
        "--deposit",
        type=float,
        metavar="LENGTH",
        help="trace length per point, L_vb (default: as cnt-sim run)",
    )

    m = p.add_argument_group("model and solver options (as cnt-sim run)")
    m.add_argument("--seed", type=int, default=0, help="seed of every point (default 0)")
    m.add_argument(
        "--seed-per-point",
        action="store_true",
        help="give each grid point its own seed (seed + point index x repeats)",
    )
    add_model_arguments(m)
    m.add_argument("--transient", type=float, metavar="L", help="arc dropped before measuring")
    add_settled_argument(m)

    x = p.add_argument_group("execution")
    x.add_argument(
        "--jobs",
        type=int,
        default=1,
        help="parallel simulations: worker processes, or the CPUs of a local Ray instance "
        "(default 1: in this process)",
    )
    x.add_argument("--backend", choices=BACKENDS, default="local", help="local processes or Ray")
    x.add_argument(
        "--ray-address",
        default=None,
        help="Ray cluster address for ray.init (default: start a local instance)",
    )
    x.add_argument(
        "--retry-failed", action="store_true", help="run again points recorded as failed"
    )

    x.add_argument(
        "--max-points",
        type=int,
        default=MAX_POINTS,
        metavar="N",
        help=f"sweep size limit: grid points x repeats (default {MAX_POINTS}; at most "
        f"{MAX_POINTS_CEILING})",
    )
    add_limit_arguments(p.add_argument_group("limits of each run (docs/cli.md)"))

    o = p.add_argument_group("outputs")
    o.add_argument("--out", default=DEFAULT_OUT, metavar="SWEEP.csv", help="results CSV")
    o.add_argument("--plots", metavar="DIR", help="plot directory (default: the CSV's)")
    o.add_argument("--no-plots", action="store_true", help="write no plots")
    o.add_argument("--traces", metavar="DIR", help="also save each point's trace and figure")
    o.add_argument("--json", action="store_true", help="print one JSON summary on stdout")
    # cnt-sim run's SI options are not offered: the sweep varies dimensionless groups
    p.set_defaults(func=cmd_sweep, **dict.fromkeys(runs.SI_FIELDS))
    return p

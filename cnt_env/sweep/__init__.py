"""Sweeps as a library: a one- or two-parameter grid of depositions, run in parallel.

Each grid point is one run: its :class:`cnt_env.runs.RunSpec` is resolved from the
sweep's base :class:`cnt_env.runs.RunOptions` with the swept groups set
(:func:`cnt_env.sweep.grid.resolve_sweep`), and :func:`run_point` runs it with
:func:`cnt_env.runs.simulate`, exactly as ``cnt-sim run`` does, and returns one flat CSV
row. Every point is resolved (and so validated) before anything runs.

* **Grid** (:mod:`cnt_env.sweep.grid`): ``param`` with ``values`` ``a,b,...`` or a
  ``span`` ``start:stop:n[:log]``, one or two axes. A name is any field of
  :class:`cnt_env.units.DimensionlessParams` or a ``cnt-sim run`` flag name
  (``kappa-c``, ``delta``). The sweep size is limited (``max_points``).
* **Seeds**: every point runs with the base seed unless ``seed_per_point``; ``repeats``
  N runs each point with N seeds ``seed + r``.
* **Parallel**: ``jobs`` worker processes (``spawn``: no numba state is shared), or the
  ``ray`` backend (the ``[ray]`` extra). ``jobs == 1`` runs in this process.
* **Resumable** (:mod:`cnt_env.sweep.store`): each finished point is appended to the CSV
  at once. A point whose (config hash, swept values, seed) is already there is not run
  again; the hash (:func:`cnt_env.io.config_hash`) covers every setting but the swept
  groups and the seed. A failed point is recorded with its ``failure`` text and not
  retried unless ``retry_failed``.
* **Plots** (:mod:`cnt_env.sweep.plots`): ``<stem>_curves.png`` and, for a 2-D grid,
  ``<stem>_phase.png``.

There is no argparse here: ``cnt_env.cli.sweep`` is the command line.
"""

from __future__ import annotations

import math
import multiprocessing
import os
import time
from collections.abc import Callable, Iterator, Mapping, Sequence
from concurrent.futures import FIRST_COMPLETED, Future, ProcessPoolExecutor, wait
from concurrent.futures.process import BrokenProcessPool
from contextlib import contextmanager
from pathlib import Path
from typing import Any

from cnt_env import runs
from cnt_env.runs import RunInputError
from cnt_env.sweep.grid import (
    BACKENDS,
    DEFAULT_OUT,
    LATER_RESULT_COLUMNS,
    MAX_POINTS,
    MAX_POINTS_CEILING,
    RESULT_COLUMNS,
    SWEEPABLE,
    Axis,
    SweepOptions,
    SweepPlan,
    SweepPoint,
    parse_range,
    parse_values,
    point_key,
    resolve_param,
    resolve_sweep,
    sweep_hash,
)
from cnt_env.sweep.plots import PATTERN_COLORS, plot_sweep, row_class
from cnt_env.sweep.store import CsvSink, finished_rows, read_rows

__all__ = [
    "BACKENDS",
    "DEFAULT_OUT",
    "LATER_RESULT_COLUMNS",
    "MAX_POINTS",
    "MAX_POINTS_CEILING",
    "PATTERN_COLORS",
    "RESULT_COLUMNS",
    "SWEEPABLE",
    "Axis",
    "CsvSink",
    "SweepFailure",
    "SweepOptions",
    "SweepPlan",
    "SweepPoint",
    "execute",
    "failure_row",
    "finished_rows",
    "import_ray",
    "parse_range",
    "parse_values",
    "plot_sweep",
    "point_key",
    "ray_session",
    "read_rows",
    "resolve_param",
    "resolve_sweep",
    "row_class",
    "run_point",
    "run_point_safe",
    "sweep_hash",
]

RAY_HINT = (
    "--backend ray needs Ray, which is not installed: install the extra "
    "(pip install 'cnt-env[ray]', or pip install 'ray[default]')"
)


class SweepFailure(RuntimeError):
    """The sweep could not go on (e.g. a worker process died); the CSV keeps the points."""


def _row_base(point: SweepPoint) -> dict[str, Any]:
    row: dict[str, Any] = dict(point.values)
    row["seed"] = point.seed
    row.update(dict.fromkeys(RESULT_COLUMNS, math.nan))
    row["pattern"] = ""
    row["failure"] = ""
    row["config_hash"] = point.config_hash
    return row


def run_point(point: SweepPoint) -> dict[str, Any]:
    """Run one point as ``cnt-sim run`` does and return its flat CSV row.

    Builds the DepositionSim from ``point.run.sim_config``, deposits
    ``point.run.deposit_length`` L_vb under the run's limits and measures the trace
    (:func:`cnt_env.runs.simulate`), and flattens its report. A trace too short to
    measure gives an empty ``pattern`` and ``failure`` "not measured: ...". Raises
    SimulationError when the solver fails. With ``point.trace_path`` the trace and its
    figure are saved too.
    """
    spec = point.run
    outcome = runs.simulate(spec)
    trace, stats, measurement = outcome.trace, outcome.stats, outcome.measurement
    params, config = spec.params.as_dict(), spec.config_dict()
    result = outcome.report()
    m = result["measure"]
    row = _row_base(point)
    for key in ("pattern", "amplitude", "wavelength", "coil_radius", "deposited_length"):
        row[key] = result[key]
    for key in ("sim_time", "steps", "newton_iterations", "wall_time_s"):
        row[key] = result[key]
    measured = ("peak_to_peak", "n_uturns", "n_loops", "n_cycles", "amplitude_cv",
                "wavelength_cv", "settled_amplitude_cv", "settled_wavelength_cv",
                "settled_loop_events")  # fmt: skip
    for key in measured:  # NaN where the pattern has no such measure (a coil's CVs)
        row[key] = m.get(key, math.nan)
    for key in ("amplitude", "wavelength"):
        lo, hi = m.get(f"{key}_spread", (math.nan, math.nan))
        row[f"{key}_p16"], row[f"{key}_p84"] = lo, hi
    row["pattern"] = result["pattern"] or ""
    if m.get("error"):
        row["failure"] = f"not measured: {m['error']}"
    if point.trace_path is not None:
        from cnt_env.io import OutputSet, save_trace
        from cnt_env.plotting import plot_run

        suspended = outcome.suspended
        path = Path(point.trace_path)
        with OutputSet() as outputs:
            tmp = outputs.add(path, "--traces")
            save_trace(tmp, trace, params, config, stats, suspended, version=result["version"])
            png = outputs.add(path.with_suffix(".png"), "--traces")
            plot_run(trace, suspended, measurement, png,
                     title=f"{point.label()}: {result['pattern']}")  # fmt: skip
    return row


def failure_row(point: SweepPoint, exc: BaseException, wall_time: float) -> dict[str, Any]:
    """The CSV row of a point whose run raised ``exc``."""
    row = _row_base(point)
    text = " ".join(str(exc).split())
    row["failure"] = f"{type(exc).__name__}: {text}"[:500]
    row["wall_time_s"] = wall_time
    return row


def run_point_safe(point: SweepPoint) -> dict[str, Any]:
    """:func:`run_point`, with a failure (SimulationError or any error) as a row."""
    start = time.perf_counter()
    try:
        return run_point(point)
    except Exception as exc:
        return failure_row(point, exc, time.perf_counter() - start)


ResultCallback = Callable[[SweepPoint, dict[str, Any]], None]


def _run_serial(points: Sequence[SweepPoint], on_result: ResultCallback) -> None:
    for point in points:
        on_result(point, run_point_safe(point))


def _run_processes(points: Sequence[SweepPoint], jobs: int, on_result: ResultCallback) -> None:
    """Each point in a fresh ``spawn`` worker process (no numba state is inherited)."""
    context = multiprocessing.get_context("spawn")
    pool = ProcessPoolExecutor(max_workers=min(jobs, len(points)), mp_context=context)
    futures: dict[Future, SweepPoint] = {}
    started: dict[Future, float] = {}
    try:
        for point in points:
            future = pool.submit(run_point_safe, point)
            futures[future] = point
            started[future] = time.perf_counter()
        pending = set(futures)
        while pending:
            done, pending = wait(pending, return_when=FIRST_COMPLETED)
            for future in done:
                point = futures[future]
                try:
                    row = future.result()
                except BrokenProcessPool as exc:
                    raise SweepFailure(
                        f"a worker process died ({exc}); the finished points are in the "
                        "CSV: run the sweep again to resume"
                    ) from exc
                except Exception as exc:  # e.g. a point that cannot be pickled
                    row = failure_row(point, exc, time.perf_counter() - started[future])
                on_result(point, row)
    except BaseException:
        # interrupted or broken: drop the queued points, do not wait for running ones
        pool.shutdown(wait=False, cancel_futures=True)
        raise
    pool.shutdown(wait=True)


def import_ray():
    """Ray, or RunInputError with the install hint (a missing extra is a usage error)."""
    try:
        import ray
    except ImportError as exc:
        raise RunInputError(RAY_HINT) from exc
    return ray


@contextmanager
def ray_session(jobs: int, address: str | None = None) -> Iterator[Any]:
    """Ray, initialised for the block: on ``address``'s cluster (this cnt_env package
    shipped to its workers), or a local instance of ``jobs`` CPUs whose workers import
    cnt_env from this source tree, shut down afterwards. An instance already running is
    used as it is. RunInputError with the install hint when Ray is missing."""
    ray = import_ray()
    import cnt_env

    started_here = not ray.is_initialized()
    if started_here:
        package_root = str(Path(cnt_env.__file__).resolve().parent.parent)
        if address is None:
            path = os.pathsep.join(p for p in (package_root, os.environ.get("PYTHONPATH")) if p)
            runtime_env: dict[str, Any] = {"env_vars": {"PYTHONPATH": path}}
            ray.init(
                num_cpus=jobs,
                include_dashboard=False,
                log_to_driver=False,
                runtime_env=runtime_env,
            )
        else:
            ray.init(address=address, log_to_driver=False, runtime_env={"py_modules": [cnt_env]})
    try:
        yield ray
    finally:
        if started_here:
            ray.shutdown()


def _run_ray(
    points: Sequence[SweepPoint], jobs: int, address: str | None, on_result: ResultCallback
) -> None:
    """:func:`run_point_safe` as Ray tasks (:func:`ray_session`)."""
    with ray_session(jobs, address) as ray:
        task = ray.remote(num_cpus=1, max_retries=0)(run_point_safe)
        refs = {task.remote(point): point for point in points}
        pending = list(refs)
        start = time.perf_counter()
        while pending:
            done, pending = ray.wait(pending, num_returns=1)
            for ref in done:
                point = refs[ref]
                try:
                    row = ray.get(ref)
                except Exception as exc:  # the task or its worker died
                    row = failure_row(point, exc, time.perf_counter() - start)
                on_result(point, row)


def execute(
    plan: SweepPlan,
    on_result: Callable[[SweepPoint, Mapping[str, Any], int, int], None] | None = None,
    on_start: Callable[[int, int], None] | None = None,
    warn: Callable[[str], None] | None = None,
) -> dict[str, Any]:
    """Run the plan's unfinished points, appending each row to the CSV as it comes.

    ``on_start(n_todo, n_skipped)`` is called before the first point,
    ``on_result(point, row, done, n_todo)`` after each. Returns the rows of the plan's
    points (in grid order), ``n_points``, ``n_run``, ``n_skipped``, ``wall_time_s`` and
    ``other_configs``: the config hashes of the CSV's rows from other configurations.
    """
    opts = plan.options
    sink = CsvSink(plan.csv_path, plan.columns, warn=warn)
    try:
        _, existing = read_rows(plan.csv_path)
        done = finished_rows(existing, plan.params, opts.retry_failed)
        todo = [p for p in plan.points if p.key() not in done]
        rows: dict[tuple, Mapping[str, Any]] = {
            p.key(): done[p.key()] for p in plan.points if p.key() in done
        }
        n_skipped = len(plan.points) - len(todo)
        hashes = {r.get("config_hash") for r in existing}
        other_configs = sorted(hashes - {plan.config_hash, None, ""})
        if on_start is not None:
            on_start(len(todo), n_skipped)
        counter = {"done": 0}

        def record(point: SweepPoint, row: dict[str, Any]) -> None:
            sink.write(row)
            rows[point.key()] = row
            counter["done"] += 1
            if on_result is not None:
                on_result(point, row, counter["done"], len(todo))

        start = time.perf_counter()
        if todo:
            if opts.backend == "ray":
                _run_ray(todo, opts.jobs, opts.ray_address, record)
            elif opts.jobs == 1 or len(todo) == 1:
                _run_serial(todo, record)
            else:
                _run_processes(todo, opts.jobs, record)
        wall = time.perf_counter() - start
    finally:
        sink.close()
    ordered = [rows[p.key()] for p in plan.points if p.key() in rows]
    return {
        "rows": ordered,
        "n_points": len(plan.points),
        "n_run": counter["done"],
        "n_skipped": n_skipped,
        "wall_time_s": wall,
        "other_configs": other_configs,
    }


def plan_rows(plan: SweepPlan) -> list[Mapping[str, Any]]:
    """Every finished row of the plan's configuration in its CSV (for the plots)."""
    _, all_rows = read_rows(plan.csv_path)
    mine = [r for r in all_rows if r.get("config_hash") == plan.config_hash]
    return list(finished_rows(mine, plan.params, retry_failed=False).values())

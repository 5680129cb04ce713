"""``cnt-sim sweep``: a one- or two-parameter grid of depositions, run in parallel.

Each grid point is one ``cnt-sim run``: its :class:`cnt_env.cli.RunSpec` is built by
:func:`cnt_env.cli.resolve_run` from the sweep's options with the swept groups set,
and :func:`run_point` runs it with :func:`cnt_env.cli.simulate` and
:func:`cnt_env.cli.measure_trace`, exactly as ``cnt-sim run`` does, and returns one
flat CSV row. Every point is resolved (and so validated) before anything runs.

* **Grid**: ``--param NAME --values a,b,...`` (or ``--range start:stop:n[:log]``), and
  optionally ``--param2``/``--values2``/``--range2``. NAME is any field of
  :class:`cnt_env.units.DimensionlessParams` (``Hbar``, ``Ibar``, ``vbar``, ``phi``,
  ``kappa_c_bar``, ``delta_bar``, ``ks_over_ev``, ``kt_over_kb``, ``sigma``,
  ``c_sigma``, ``r0_bar``) or a ``cnt-sim run`` flag name (``kappa-c``, ``delta``).
* **Seeds**: every point runs with ``--seed`` (deterministic) unless
  ``--seed-per-point``; ``--repeats N`` runs each point with N seeds ``seed + r``
  (spread from repeated points).
* **Parallel**: ``--jobs N`` worker processes (``spawn``: no numba state is shared),
  or ``--backend ray`` on a Ray cluster (the ``[ray]`` extra). ``--jobs 1`` runs in
  this process.
* **Resumable**: each finished point is appended to ``--out`` (CSV) at once. A point
  whose (config hash, swept values, seed) is already in the CSV is not run again; the
  hash covers every setting but the swept groups and the seed (column
  ``config_hash``). A point that fails is recorded with its ``failure`` text; it is
  not retried unless ``--retry-failed``.
* **Outputs**: the CSV, its resolved config ``<csv>.json``, and plots in ``--plots``
  (default: next to the CSV): ``<stem>_curves.png`` (amplitude and wavelength against
  the swept parameter) and, for a 2-D grid, ``<stem>_phase.png`` (pattern class over
  the grid).

Exit codes as ``cnt-sim run``: 0, 1 when a point failed (the sweep still finishes and
records it), 2 on bad input (before any simulation).
"""

from __future__ import annotations

import argparse
import csv
import dataclasses
import hashlib
import json
import math
import multiprocessing
import os
import sys
import time
from collections import Counter, defaultdict
from collections.abc import Callable, Iterable, Mapping, Sequence
from concurrent.futures import FIRST_COMPLETED, Future, ProcessPoolExecutor, wait
from concurrent.futures.process import BrokenProcessPool
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from cnt_env import cli, units
from cnt_env.io import to_jsonable

__all__ = [
    "RESULT_COLUMNS",
    "SWEEPABLE",
    "SweepPlan",
    "SweepPoint",
    "add_parser",
    "cmd_sweep",
    "plot_sweep",
    "read_rows",
    "resolve_param",
    "resolve_sweep",
    "run_point",
    "run_point_safe",
]

#: Groups a sweep can vary: every field of DimensionlessParams.
SWEEPABLE: tuple[str, ...] = tuple(f.name for f in dataclasses.fields(units.DimensionlessParams))
# `cnt-sim run` flag names (argparse dests) of the groups, and their fields.
_RUN_DEST_OF: dict[str, str] = {field: dest for dest, field in cli.GROUP_FIELDS.items()}

#: Result columns of the CSV, after the swept parameters and the seed.
RESULT_COLUMNS: tuple[str, ...] = (
    "pattern",
    "amplitude",
    "peak_to_peak",
    "wavelength",
    "coil_radius",
    "n_uturns",
    "n_loops",
    "n_cycles",
    "amplitude_cv",
    "wavelength_cv",
    "amplitude_p16",
    "amplitude_p84",
    "wavelength_p16",
    "wavelength_p84",
    "deposited_length",
    "sim_time",
    "steps",
    "newton_iterations",
    "wall_time_s",
    "failure",
)
_INT_COLUMNS = frozenset({"seed", "n_uturns", "n_loops", "n_cycles", "steps", "newton_iterations"})
_TEXT_COLUMNS = frozenset({"pattern", "failure", "config_hash"})

DEFAULT_OUT = "sweep.csv"
BACKENDS = ("local", "ray")
RAY_HINT = (
    "--backend ray needs Ray, which is not installed: install the extra "
    "(pip install 'cnt-env[ray]', or pip install 'ray[default]')"
)

# Colours of the pattern classes in every plot (patterns.PATTERNS, then the sweep's own).
PATTERN_COLORS: dict[str, str] = {
    "coil": "tab:blue",
    "serpentine-coil": "tab:purple",
    "periodic-serpentine": "tab:green",
    "irregular-serpentine": "tab:orange",
    "straight": "tab:olive",
    "unknown": "tab:brown",
    "not measured": "0.75",
    "failed": "tab:red",
    "not run": "white",
}


# --------------------------------------------------------------------------- grid


def resolve_param(name: str) -> str:
    """The DimensionlessParams field a sweep parameter name means.

    Accepts the field names (any case, ``-`` for ``_``) and the ``cnt-sim run``
    flag names (``kappa-c`` -> ``kappa_c_bar``, ``delta`` -> ``delta_bar``). Raises
    :class:`cnt_env.cli.CliError` for an unknown name.
    """
    key = name.strip().lstrip("-").replace("-", "_").lower()
    table = {field.lower(): field for field in SWEEPABLE}
    table.update({dest.lower(): field for dest, field in cli.GROUP_FIELDS.items()})
    if key not in table:
        raise cli.CliError(
            f"unknown sweep parameter {name!r}; choose a dimensionless group: "
            + ", ".join(SWEEPABLE)
            + " (or kappa-c, delta)"
        )
    return table[key]


def parse_values(text: str, flag: str) -> list[float]:
    """``a,b,c`` as floats (NaN and inf parse: the point validation rejects them by name)."""
    tokens = [t.strip() for t in text.split(",")]
    if not tokens or any(t == "" for t in tokens):
        raise cli.CliError(f"{flag} {text!r}: give comma-separated numbers, e.g. 0.01,0.02")
    values = []
    for token in tokens:
        try:
            values.append(float(token))
        except ValueError as exc:
            raise cli.CliError(f"{flag}: {token!r} is not a number (in {text!r})") from exc
    return values


def parse_range(text: str, flag: str) -> list[float]:
    """``start:stop:n`` (n values, both ends included) or ``start:stop:n:log`` (geometric)."""
    parts = [p.strip() for p in text.split(":")]
    log = len(parts) == 4 and parts[3].lower() == "log"
    if len(parts) != 3 and not log:
        raise cli.CliError(f"{flag} {text!r}: give start:stop:n or start:stop:n:log")
    try:
        start, stop = float(parts[0]), float(parts[1])
        n = int(parts[2])
    except ValueError as exc:
        raise cli.CliError(f"{flag} {text!r}: start and stop are numbers, n an integer") from exc
    if n < 1:
        raise cli.CliError(f"{flag} {text!r}: n must be >= 1")
    if not (math.isfinite(start) and math.isfinite(stop)):
        raise cli.CliError(f"{flag} {text!r}: start and stop must be finite")
    if log:
        if start <= 0.0 or stop <= 0.0:
            raise cli.CliError(f"{flag} {text!r}: a log range needs start, stop > 0")
        grid = np.geomspace(start, stop, n)
    else:
        grid = np.linspace(start, stop, n)
    return [float(v) for v in grid]


def _axis(args: argparse.Namespace, suffix: str) -> tuple[str, list[float]] | None:
    """(field, values) of one grid axis, from --param{suffix} and --values/--range{suffix}."""
    name = getattr(args, f"param{suffix}")
    values, span = getattr(args, f"values{suffix}"), getattr(args, f"range{suffix}")
    flags = f"--values{suffix} or --range{suffix}"
    if name is None:
        if values is not None or span is not None:
            raise cli.CliError(f"{flags} given without --param{suffix}")
        return None
    field = resolve_param(name)
    if (values is None) == (span is None):
        raise cli.CliError(f"--param{suffix} {name} needs exactly one of {flags}")
    grid = (
        parse_values(values, f"--values{suffix}")
        if values is not None
        else parse_range(span, f"--range{suffix}")
    )
    return field, grid


# --------------------------------------------------------------------------- points


@dataclass(frozen=True)
class SweepPoint:
    """One simulation of a sweep: picklable, shipped to a worker process or Ray task.

    ``values`` are the swept groups as ``(field, value)`` pairs in grid order;
    ``run`` the fully resolved ``cnt-sim run`` of this point (its seed included);
    ``trace_path`` where the worker saves the trace (and a PNG), or None.
    """

    index: int
    values: tuple[tuple[str, float], ...]
    run: cli.RunSpec
    config_hash: str
    trace_path: str | None = None

    @property
    def seed(self) -> int:
        return self.run.seed

    def key(self) -> tuple:
        return point_key(self.config_hash, [v for _, v in self.values], self.seed)

    def label(self) -> str:
        text = " ".join(f"{k}={v:.6g}" for k, v in self.values)
        return f"{text} seed={self.seed}"


def point_key(config_hash: str, values: Sequence[float], seed: int) -> tuple:
    """What identifies a finished point in the CSV (floats are written exactly)."""
    return (config_hash, *(float(v) for v in values), int(seed))


def _point_run(args: argparse.Namespace, values: Sequence[tuple[str, float]], seed: int):
    """``cnt-sim run``'s RunSpec with the swept groups set (run flags where there are)."""
    ns = argparse.Namespace(**vars(args))
    ns.seed = seed
    extra = {}
    for field, value in values:
        dest = _RUN_DEST_OF.get(field)
        if dest is not None:
            setattr(ns, dest, value)
        else:
            extra[field] = value
    spec = cli.resolve_run(ns)
    if extra:
        try:
            params = dataclasses.replace(spec.params, **extra)
            sim_config = dataclasses.replace(spec.sim_config, params=params)
        except ValueError as exc:  # ParameterError, DepositionConfig's checks
            raise cli.CliError(str(exc)) from exc
        spec = dataclasses.replace(spec, params=params, sim_config=sim_config)
    return spec


def config_hash(spec: cli.RunSpec, swept: Sequence[str], args: argparse.Namespace) -> str:
    """Hash of everything that defines a sweep's points apart from the swept groups and
    the seed: the other groups, the solver and measurement options, the deposit length.
    Options that follow from a swept group (the default dt from Hbar, the substrate and
    its start-up radius from kappa_c) enter as given on the command line."""
    params = {k: v for k, v in spec.params.as_dict().items() if k not in swept}
    config = spec.config_dict()
    for derived in ("seed", "substrate", "initial_radius", "dt"):
        config.pop(derived, None)
    given = {"substrate": args.substrate, "initial_radius": args.initial_radius, "dt": args.dt}
    blob = json.dumps(
        to_jsonable({"params": params, "config": config, "given": given, "swept": list(swept)}),
        sort_keys=True,
    )
    return hashlib.sha256(blob.encode()).hexdigest()[:16]


@dataclass(frozen=True)
class SweepPlan:
    """A validated sweep: its grid, every point (resolved), and where outputs go."""

    params: tuple[str, ...]
    grids: tuple[tuple[float, ...], ...]
    points: tuple[SweepPoint, ...]
    config_hash: str
    csv_path: Path
    plots_dir: Path | None
    traces_dir: Path | None
    resolved: dict[str, Any]

    @property
    def columns(self) -> list[str]:
        return [*self.params, "seed", *RESULT_COLUMNS, "config_hash"]


def _seeds(args: argparse.Namespace, grid_index: int) -> list[int]:
    base = args.seed + (grid_index * args.repeats if args.seed_per_point else 0)
    return [base + r for r in range(args.repeats)]


def resolve_sweep(args: argparse.Namespace) -> SweepPlan:
    """Validate every input and every point of ``cnt-sim sweep``; raises CliError (exit 2)."""
    axes = [a for a in (_axis(args, ""), _axis(args, "2")) if a is not None]
    if not axes:
        raise cli.CliError("give the swept parameter: --param NAME --values a,b,...")
    if len(axes) == 2 and axes[0][0] == axes[1][0]:
        raise cli.CliError(f"--param and --param2 are both {axes[0][0]}")
    if args.jobs < 1:
        raise cli.CliError(f"--jobs must be >= 1, got {args.jobs}")
    if args.repeats < 1:
        raise cli.CliError(f"--repeats must be >= 1, got {args.repeats}")
    if args.seed < 0:
        raise cli.CliError(f"--seed must be >= 0, got {args.seed}")
    swept = tuple(field for field, _ in axes)
    if "kappa_c_bar" in swept and args.substrate == "flat":
        raise cli.CliError("--substrate flat has no critical curvature to sweep (kappa_c_bar)")
    for field in swept:
        dest = _RUN_DEST_OF.get(field)
        if dest is not None and getattr(args, dest) is not None:
            print(
                f"{cli.PROG}: warning: --{dest.replace('_', '-')} is swept: "
                "the grid's values replace it",
                file=sys.stderr,
            )

    grid_values: list[tuple[float, ...]] = [()]
    for _, values in axes:
        grid_values = [(*g, v) for g in grid_values for v in values]
    specs: list[tuple[tuple[tuple[str, float], ...], cli.RunSpec]] = []
    total = len(grid_values) * args.repeats
    for gi, combo in enumerate(grid_values):
        values = tuple(zip(swept, combo, strict=True))
        for seed in _seeds(args, gi):
            try:
                spec = _point_run(args, values, seed)
            except cli.CliError as exc:
                where = ", ".join(f"{k}={v!r}" for k, v in values)
                raise cli.CliError(
                    f"point {len(specs) + 1} of {total} ({where}): {exc}", exc.code
                ) from exc
            specs.append((values, spec))

    digest = config_hash(specs[0][1], swept, args)
    csv_path = Path(args.out)
    if csv_path.is_dir():
        raise cli.CliError(f"--out {args.out} is a directory; pass a CSV file name")
    plots_dir = None if args.no_plots else Path(args.plots or csv_path.parent or ".")
    traces_dir = Path(args.traces) if args.traces else None
    for path, flag in (
        (csv_path.parent, "--out"),
        (plots_dir, "--plots"),
        (traces_dir, "--traces"),
    ):
        if path is None:
            continue
        try:
            path.mkdir(parents=True, exist_ok=True)
        except OSError as exc:
            raise cli.CliError(f"{flag}: cannot create {path}: {exc}") from exc

    points = []
    for i, (values, spec) in enumerate(specs):
        trace_path = None
        if traces_dir is not None:
            name = "_".join(f"{k}={v:.6g}" for k, v in values) + f"_seed{spec.seed}.npz"
            trace_path = str(traces_dir / name)
        points.append(SweepPoint(i, values, spec, digest, trace_path))

    first = specs[0][1]
    config = first.config_dict()
    config.pop("seed")
    resolved = {
        "version": cli.package_version(),
        "argv": list(getattr(args, "argv", None) or []),
        "sweep": {
            "params": list(swept),
            "values": [list(values) for _, values in axes],
            "repeats": args.repeats,
            "seed": args.seed,
            "seed_per_point": args.seed_per_point,
            "n_points": len(points),
            "backend": args.backend,
            "jobs": args.jobs,
            "ray_address": args.ray_address,
        },
        "config_hash": digest,
        "params": first.params.as_dict(),
        "params_swept": list(swept),
        "config": config,
        "columns": [*swept, "seed", *RESULT_COLUMNS, "config_hash"],
        "plots": None if plots_dir is None else str(plots_dir),
        "traces": None if traces_dir is None else str(traces_dir),
    }
    return SweepPlan(
        params=swept,
        grids=tuple(tuple(values) for _, values in axes),
        points=tuple(points),
        config_hash=digest,
        csv_path=csv_path,
        plots_dir=plots_dir,
        traces_dir=traces_dir,
        resolved=resolved,
    )


# --------------------------------------------------------------------------- one point


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
    ``point.run.deposit_length`` L_vb (:func:`cnt_env.cli.simulate`), measures the
    trace (:func:`cnt_env.cli.measure_trace`) and flattens
    :func:`cnt_env.cli.result_dict`. A trace too short to measure gives an empty
    ``pattern`` and ``failure`` "not measured: ...". Raises SimulationError when the
    solver fails. With ``point.trace_path`` the trace and its figure are saved too.
    """
    spec = point.run
    sim, stats = cli.simulate(spec.sim_config, spec.deposit_length, spec.seed)
    trace = sim.trace()
    measurement = cli.measure_trace(trace, spec.measure_options, spec.substrate, spec.params.phi)
    params, config = spec.params.as_dict(), spec.config_dict()
    result = cli.result_dict(measurement, stats, params, config)
    m = result["measure"]
    row = _row_base(point)
    for key in ("pattern", "amplitude", "wavelength", "coil_radius", "deposited_length"):
        row[key] = result[key]
    for key in ("sim_time", "steps", "newton_iterations", "wall_time_s"):
        row[key] = result[key]
    for key in ("peak_to_peak", "n_uturns", "n_loops", "n_cycles", "amplitude_cv"):
        row[key] = m.get(key, math.nan)
    row["wavelength_cv"] = m.get("wavelength_cv", math.nan)
    for key in ("amplitude", "wavelength"):
        lo, hi = m.get(f"{key}_spread", (math.nan, math.nan))
        row[f"{key}_p16"], row[f"{key}_p84"] = lo, hi
    row["pattern"] = result["pattern"] or ""
    if m.get("error"):
        row["failure"] = f"not measured: {m['error']}"
    if point.trace_path is not None:
        from cnt_env.io import save_trace
        from cnt_env.plotting import plot_run

        suspended = sim.suspended_nodes.copy()
        path = Path(point.trace_path)
        save_trace(path, trace, params, config, stats, suspended, version=result["version"])
        plot_run(
            trace,
            suspended,
            measurement,
            path.with_suffix(".png"),
            title=f"{point.label()}: {result['pattern']}",
        )
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


# --------------------------------------------------------------------------- CSV


def _format_cell(value: Any) -> str:
    if value is None:
        return ""
    if isinstance(value, (bool, np.bool_)):
        return str(bool(value))
    if isinstance(value, (int, np.integer)):
        return str(int(value))
    if isinstance(value, (float, np.floating)):
        v = float(value)
        return repr(v) if math.isfinite(v) else ""
    return str(value)


def _parse_cell(column: str, text: str) -> Any:
    if column in _TEXT_COLUMNS:
        return text
    if text == "":
        return math.nan
    try:
        value = float(text)
    except ValueError:
        return text
    if column in _INT_COLUMNS and value.is_integer():
        return int(value)
    return value


def read_rows(path: Path) -> tuple[list[str] | None, list[dict[str, Any]]]:
    """Header and rows of a sweep CSV (numbers parsed; incomplete lines dropped)."""
    if not path.exists() or path.stat().st_size == 0:
        return None, []
    with path.open(newline="") as f:
        reader = csv.reader(f)
        header = next(reader, None)
        if not header:
            return None, []
        rows = []
        for record in reader:
            if len(record) != len(header):
                continue  # a line cut short by a crash
            rows.append({c: _parse_cell(c, t) for c, t in zip(header, record, strict=True)})
    return header, rows


class CsvSink:
    """Appends rows to the sweep CSV, one flushed line per finished point."""

    def __init__(self, path: Path, columns: Sequence[str]) -> None:
        self.path = path
        header, _ = read_rows(path)
        if header is not None and set(header) != set(columns):
            raise cli.CliError(
                f"--out {path} holds a different sweep (columns {', '.join(header)}); "
                "pass another --out or remove it"
            )
        self.columns = list(header or columns)
        needs_newline = False
        if header is not None:
            with path.open("rb") as f:
                f.seek(-1, os.SEEK_END)
                needs_newline = f.read(1) != b"\n"
        self._file = path.open("a", newline="")
        if needs_newline:
            self._file.write("\n")
        self._writer = csv.writer(self._file)
        if header is None:
            self._writer.writerow(self.columns)
            self._file.flush()

    def write(self, row: Mapping[str, Any]) -> None:
        self._writer.writerow([_format_cell(row.get(c)) for c in self.columns])
        self._file.flush()
        os.fsync(self._file.fileno())

    def close(self) -> None:
        self._file.close()


def finished_rows(
    rows: Iterable[Mapping[str, Any]], params: Sequence[str], retry_failed: bool
) -> dict[tuple, Mapping[str, Any]]:
    """Rows that count as done, by point key (the last row of a key wins)."""
    done: dict[tuple, Mapping[str, Any]] = {}
    for row in rows:
        try:
            key = point_key(row["config_hash"], [row[p] for p in params], row["seed"])
        except (KeyError, TypeError, ValueError):
            continue
        failed = bool(row.get("failure")) and not str(row["failure"]).startswith("not measured")
        if retry_failed and failed:
            done.pop(key, None)
            continue
        done[key] = row
    return done


# --------------------------------------------------------------------------- backends

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
                    raise cli.CliError(
                        f"a worker process died ({exc}); the finished points are in the "
                        "CSV: run the sweep again to resume",
                        cli.EXIT_FAILED,
                    ) from exc
                except Exception as exc:  # e.g. a point that cannot be pickled
                    row = failure_row(point, exc, time.perf_counter() - started[future])
                on_result(point, row)
    except BaseException:
        # interrupted or broken: drop the queued points, do not wait for running ones
        pool.shutdown(wait=False, cancel_futures=True)
        raise
    pool.shutdown(wait=True)


def _import_ray():
    try:
        import ray
    except ImportError as exc:
        raise cli.CliError(RAY_HINT) from exc
    return ray


def _run_ray(
    points: Sequence[SweepPoint], jobs: int, address: str | None, on_result: ResultCallback
) -> None:
    """:func:`run_point_safe` as Ray tasks: on ``address``'s cluster, or on a local
    instance of ``jobs`` CPUs (started here and shut down afterwards)."""
    ray = _import_ray()
    import cnt_env

    started_here = not ray.is_initialized()
    if started_here:
        package_root = str(Path(cnt_env.__file__).resolve().parent.parent)
        if address is None:
            # local instance: the workers import cnt_env from this source tree
            path = os.pathsep.join(p for p in (package_root, os.environ.get("PYTHONPATH")) if p)
            runtime_env: dict[str, Any] = {"env_vars": {"PYTHONPATH": path}}
            ray.init(
                num_cpus=jobs,
                include_dashboard=False,
                log_to_driver=False,
                runtime_env=runtime_env,
            )
        else:
            # a cluster: ship this cnt_env package to its workers
            ray.init(address=address, log_to_driver=False, runtime_env={"py_modules": [cnt_env]})
    try:
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
    finally:
        if started_here:
            ray.shutdown()


# --------------------------------------------------------------------------- plots


def _float(value: Any) -> float:
    try:
        return float(value)
    except (TypeError, ValueError):
        return math.nan


def row_class(row: Mapping[str, Any] | None) -> str:
    """The pattern class a plot shows for a row (or "failed", "not measured", "not run")."""
    if row is None:
        return "not run"
    if row.get("pattern"):
        return str(row["pattern"])
    failure = str(row.get("failure") or "")
    return "not measured" if failure.startswith("not measured") or not failure else "failed"


def _use_log(values: Sequence[float]) -> bool:
    finite = [v for v in values if math.isfinite(v)]
    return bool(finite) and min(finite) > 0.0 and max(finite) / min(finite) >= 20.0


def _class_handles(classes: Iterable[str]) -> list[Any]:
    from matplotlib.patches import Patch

    order = list(PATTERN_COLORS)
    present = sorted(set(classes), key=lambda c: order.index(c) if c in order else len(order))
    return [
        Patch(facecolor=PATTERN_COLORS.get(c, "0.5"), edgecolor="0.3", label=c) for c in present
    ]


def _plot_curves(rows: Sequence[Mapping[str, Any]], params: Sequence[str], path: Path) -> Path:
    """Amplitude and wavelength against params[0]: markers coloured by pattern class,
    bars the within-run p16-p84 spread, the line the median over repeated points (or,
    on a 2-D grid, one line per value of params[1])."""
    from matplotlib.backends.backend_agg import FigureCanvasAgg
    from matplotlib.figure import Figure
    from matplotlib.lines import Line2D

    x_name = params[0]
    fig = Figure(figsize=(11.0, 4.6), layout="constrained")
    FigureCanvasAgg(fig)
    axes = fig.subplots(1, 2)
    groups: dict[float, list[Mapping[str, Any]]] = defaultdict(list)
    for row in rows:
        groups[_float(row[params[1]]) if len(params) > 1 else math.nan].append(row)
    two_d = len(params) > 1
    cmap = None
    if two_d:
        from matplotlib import colormaps

        cmap = colormaps["viridis"]
    keys = sorted(groups, key=lambda v: (math.isnan(v), v))
    for ax, quantity in zip(axes, ("amplitude", "wavelength"), strict=True):
        for gi, key in enumerate(keys):
            group = groups[key]
            line_color = cmap(gi / max(1, len(keys) - 1)) if cmap is not None else "0.4"
            by_x: dict[float, list[float]] = defaultdict(list)
            for row in group:
                x, y = _float(row[x_name]), _float(row.get(quantity))
                by_x[x].append(y)
                if not (math.isfinite(x) and math.isfinite(y)):
                    continue
                lo, hi = _float(row.get(f"{quantity}_p16")), _float(row.get(f"{quantity}_p84"))
                if math.isfinite(lo) and math.isfinite(hi):
                    yerr = [[max(0.0, y - lo)], [max(0.0, hi - y)]]
                    ax.errorbar(
                        [x], [y], yerr=yerr, fmt="none", ecolor="0.6", elinewidth=0.8, capsize=2
                    )
                ax.plot(
                    [x],
                    [y],
                    "o",
                    ms=6,
                    color=PATTERN_COLORS.get(row_class(row), "0.5"),
                    mec=line_color if two_d else "0.2",
                    mew=1.2 if two_d else 0.6,
                    zorder=3,
                )
            xs = sorted(x for x in by_x if math.isfinite(x))
            med = [
                float(np.median([y for y in by_x[x] if math.isfinite(y)]))
                if any(math.isfinite(y) for y in by_x[x])
                else math.nan
                for x in xs
            ]
            ax.plot(xs, med, "-", lw=1.0, color=line_color, zorder=2)
        if _use_log([_float(r[x_name]) for r in rows]):
            ax.set_xscale("log")
        ax.set_xlabel(x_name)
        ax.set_ylabel(f"{quantity} (L_vb)")
        ax.set_title(f"{quantity} (bars: p16-p84 over the trace)")
        ax.grid(alpha=0.3)
    handles = _class_handles(row_class(r) for r in rows)
    if two_d:
        handles += [
            Line2D([], [], color=cmap(i / max(1, len(keys) - 1)), label=f"{params[1]} = {k:.4g}")
            for i, k in enumerate(keys)
        ]
    axes[1].legend(handles=handles, loc="best", fontsize="small")
    fig.suptitle(f"sweep over {' x '.join(params)}: serpentine amplitude and wavelength")
    fig.savefig(path, format="png", dpi=120)
    return path


def _plot_phase(
    rows: Sequence[Mapping[str, Any]],
    params: Sequence[str],
    grids: Sequence[Sequence[float]],
    path: Path,
) -> Path:
    """Pattern class over the 2-D grid (the most common class over repeated points)."""
    from matplotlib.backends.backend_agg import FigureCanvasAgg
    from matplotlib.colors import ListedColormap
    from matplotlib.figure import Figure

    xs = sorted(set(grids[0]))
    ys = sorted(set(grids[1]))
    cells: dict[tuple[float, float], Counter] = defaultdict(Counter)
    for row in rows:
        cells[(_float(row[params[0]]), _float(row[params[1]]))][row_class(row)] += 1
    order = list(PATTERN_COLORS)
    grid_class = [
        [cells[(x, y)].most_common(1)[0][0] if cells[(x, y)] else "not run" for x in xs] for y in ys
    ]
    present = sorted(
        {c for line in grid_class for c in line},
        key=lambda c: order.index(c) if c in order else len(order),
    )
    index = {c: i for i, c in enumerate(present)}
    data = np.array([[index[c] for c in line] for line in grid_class], dtype=float)
    cmap = ListedColormap([PATTERN_COLORS.get(c, "0.5") for c in present])

    fig = Figure(figsize=(7.5, 5.5), layout="constrained")
    FigureCanvasAgg(fig)
    ax = fig.subplots()
    ax.pcolormesh(
        np.arange(len(xs) + 1) - 0.5,
        np.arange(len(ys) + 1) - 0.5,
        data,
        cmap=cmap,
        vmin=-0.5,
        vmax=len(present) - 0.5,
        edgecolors="0.3",
        linewidth=0.5,
    )
    for j, y in enumerate(ys):
        for i, x in enumerate(xs):
            group = [r for r in rows if _float(r[params[0]]) == x and _float(r[params[1]]) == y]
            amps = [_float(r.get("amplitude")) for r in group]
            amps = [a for a in amps if math.isfinite(a)]
            if amps:
                ax.text(i, j, f"A={np.median(amps):.3g}", ha="center", va="center", fontsize=7)
    ax.set_xticks(range(len(xs)), [f"{v:.4g}" for v in xs], rotation=45, ha="right")
    ax.set_yticks(range(len(ys)), [f"{v:.4g}" for v in ys])
    ax.set_xlabel(params[0])
    ax.set_ylabel(params[1])
    ax.set_title(f"pattern class over {params[0]} x {params[1]} (A: amplitude, L_vb)")
    ax.legend(
        handles=_class_handles(present),
        loc="upper left",
        bbox_to_anchor=(1.01, 1.0),
        fontsize="small",
    )
    fig.savefig(path, format="png", dpi=120)
    return path


def plot_sweep(
    rows: Sequence[Mapping[str, Any]],
    params: Sequence[str],
    grids: Sequence[Sequence[float]],
    outdir: Path,
    stem: str = "sweep",
) -> list[Path]:
    """Write the sweep's figures to ``outdir``: ``<stem>_curves.png`` always and
    ``<stem>_phase.png`` for a 2-D grid. matplotlib is imported here, on Agg."""
    outdir.mkdir(parents=True, exist_ok=True)
    written = [_plot_curves(rows, params, outdir / f"{stem}_curves.png")]
    if len(params) > 1:
        written.append(_plot_phase(rows, params, grids, outdir / f"{stem}_phase.png"))
    return written


# --------------------------------------------------------------------------- command


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


def execute(plan: SweepPlan, args: argparse.Namespace) -> dict[str, Any]:
    """Run the plan's unfinished points, appending each row to the CSV as it comes."""
    sink = CsvSink(plan.csv_path, plan.columns)
    try:
        _, existing = read_rows(plan.csv_path)
        done = finished_rows(existing, plan.params, args.retry_failed)
        todo = [p for p in plan.points if p.key() not in done]
        rows: dict[tuple, Mapping[str, Any]] = {
            p.key(): done[p.key()] for p in plan.points if p.key() in done
        }
        n_skipped = len(plan.points) - len(todo)
        show_bar = not args.json and sys.stderr.isatty() and bool(todo)
        bar = None
        if show_bar:
            from tqdm import tqdm

            bar = tqdm(total=len(todo), file=sys.stderr, desc="sweep", unit="point")
        elif not args.json and n_skipped:
            print(
                f"{cli.PROG} sweep: {n_skipped} points already in {plan.csv_path}", file=sys.stderr
            )
        counter = {"done": 0}

        def on_result(point: SweepPoint, row: dict[str, Any]) -> None:
            sink.write(row)
            rows[point.key()] = row
            counter["done"] += 1
            if bar is not None:
                bar.update(1)
                bar.set_postfix_str(f"{point.label()}: {row_class(row)}")
            elif not args.json:
                print(_point_line(point, row, counter["done"], len(todo)), file=sys.stderr)

        start = time.perf_counter()
        try:
            if todo:
                if args.backend == "ray":
                    _run_ray(todo, args.jobs, args.ray_address, on_result)
                elif args.jobs == 1 or len(todo) == 1:
                    _run_serial(todo, on_result)
                else:
                    _run_processes(todo, args.jobs, on_result)
        finally:
            if bar is not None:
                bar.close()
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
    }


def cmd_sweep(args: argparse.Namespace) -> int:
    if args.backend == "ray":
        _import_ray()  # a missing extra is a usage error, found before any work
    plan = resolve_sweep(args)
    config_json = cli.write_config_json(plan.csv_path, plan.resolved)
    outcome = execute(plan, args)

    written: list[Path] = []
    if plan.plots_dir is not None:
        _, all_rows = read_rows(plan.csv_path)
        mine = list(
            finished_rows(
                [r for r in all_rows if r.get("config_hash") == plan.config_hash],
                plan.params,
                retry_failed=False,
            ).values()
        )
        try:
            written = plot_sweep(mine, plan.params, plan.grids, plan.plots_dir, plan.csv_path.stem)
        except OSError as exc:
            raise cli.CliError(f"cannot write the plots: {exc}", cli.EXIT_FAILED) from exc

    rows = outcome["rows"]
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
        "version": cli.package_version(),
        "rows": rows,
    }
    if args.json:
        print(json.dumps(to_jsonable(summary), allow_nan=False))
    else:
        print(
            f"{cli.PROG} sweep: {outcome['n_points']} points over {' x '.join(plan.params)} "
            f"({outcome['n_run']} run, {outcome['n_skipped']} already done, "
            f"{len(failed)} failed) in {outcome['wall_time_s']:.1f} s"
        )
        print(format_table(rows, plan.params))
        print(f"wrote {plan.csv_path} (config: {config_json})")
        for path in written:
            print(f"wrote {path}")
    return cli.EXIT_FAILED if failed else cli.EXIT_OK


# --------------------------------------------------------------------------- parser


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
    cli.add_group_arguments(g)
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
    cli.add_model_arguments(m)
    m.add_argument("--transient", type=float, metavar="L", help="arc dropped before measuring")

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

    o = p.add_argument_group("outputs")
    o.add_argument("--out", default=DEFAULT_OUT, metavar="SWEEP.csv", help="results CSV")
    o.add_argument("--plots", metavar="DIR", help="plot directory (default: the CSV's)")
    o.add_argument("--no-plots", action="store_true", help="write no plots")
    o.add_argument("--traces", metavar="DIR", help="also save each point's trace and figure")
    o.add_argument("--json", action="store_true", help="print one JSON summary on stdout")
    # cnt-sim run's SI options are not offered: the sweep varies dimensionless groups
    p.set_defaults(func=cmd_sweep, **dict.fromkeys(cli.SI_FIELDS))
    return p

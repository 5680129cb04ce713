"""A sweep's grid and plan: parsing the axes, resolving (and so validating) every point.

Typed inputs only (:class:`SweepOptions`, :class:`cnt_env.runs.RunOptions`); the
command line builds them in ``cnt_env.cli.sweep``. Errors are
:class:`cnt_env.runs.RunInputError` naming the flag.
"""

from __future__ import annotations

import dataclasses
import math
from collections.abc import Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from cnt_env import runs, units
from cnt_env.io import OutputError, check_output_path, config_hash, package_version
from cnt_env.presets import SETTLED_FRACTION

#: Groups a sweep can vary: every field of DimensionlessParams.
SWEEPABLE: tuple[str, ...] = tuple(f.name for f in dataclasses.fields(units.DimensionlessParams))

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
    "settled_amplitude_cv",
    "settled_wavelength_cv",
    "settled_loop_events",
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
#: Result columns added after sweep CSVs were first written (the serpentine classes'
#: settled-pattern measures, patterns.classify). A CSV whose header lacks only these is
#: resumed with its own header (store.CsvSink), so its new rows leave them out.
LATER_RESULT_COLUMNS: frozenset[str] = frozenset(
    {"settled_amplitude_cv", "settled_wavelength_cv", "settled_loop_events"}
)
DEFAULT_OUT = "sweep.csv"
BACKENDS = ("local", "ray")
#: Default of the sweep-size limit (``--max-points``): grid points times repeats.
MAX_POINTS = 10_000
#: Highest --max-points accepted: an axis is built in memory up to the limit before the
#: grid's size is checked (a --range of 1e9 points under --max-points 1e9, drawn by the
#: slow CLI fuzz, grew to 24 GB), and a million runs of seconds to minutes each is
#: beyond any sweep this tool makes.
MAX_POINTS_CEILING = 1_000_000

InputError = runs.RunInputError


def resolve_param(name: str) -> str:
    """The DimensionlessParams field a sweep parameter name means.

    Accepts the field names (any case, ``-`` for ``_``) and the ``cnt-sim run``
    flag names (``kappa-c`` -> ``kappa_c_bar``, ``delta`` -> ``delta_bar``). Raises
    :class:`cnt_env.runs.RunInputError` for an unknown name.
    """
    key = name.strip().lstrip("-").replace("-", "_").lower()
    table = {f.lower(): f for f in SWEEPABLE}
    table.update({dest.lower(): f for dest, f in runs.GROUP_FIELDS.items()})
    if key not in table:
        raise InputError(
            f"unknown sweep parameter {name[:80]!r}; choose a dimensionless group: "
            + ", ".join(SWEEPABLE)
            + " (or kappa-c, delta)"
        )
    return table[key]


def parse_values(text: str, flag: str) -> list[float]:
    """``a,b,c`` as floats (NaN and inf parse: the point validation rejects them by name)."""
    tokens = [t.strip() for t in text.split(",")]
    if not tokens or any(t == "" for t in tokens):
        raise InputError(f"{flag} {text[:80]!r}: give comma-separated numbers, e.g. 0.01,0.02")
    values = []
    for token in tokens:
        try:
            values.append(float(token))
        except ValueError as exc:
            raise InputError(f"{flag}: {token[:40]!r} is not a number (in {text[:80]!r})") from exc
    return values


def parse_range(text: str, flag: str, max_n: int = MAX_POINTS) -> list[float]:
    """``start:stop:n`` (n values, both ends included) or ``start:stop:n:log`` (geometric)."""
    parts = [p.strip() for p in text.split(":")]
    log = len(parts) == 4 and parts[3].lower() == "log"
    if len(parts) != 3 and not log:
        raise InputError(f"{flag} {text[:80]!r}: give start:stop:n or start:stop:n:log")
    try:
        start, stop = float(parts[0]), float(parts[1])
        n = int(parts[2])
    except ValueError as exc:
        raise InputError(f"{flag} {text[:80]!r}: start and stop are numbers, n an integer") from exc
    if n < 1:
        raise InputError(f"{flag} {text!r}: n must be >= 1")
    if n > max_n:
        raise InputError(f"{flag} {text!r}: n = {n} is over the --max-points limit {max_n}")
    if not (math.isfinite(start) and math.isfinite(stop)):
        raise InputError(f"{flag} {text!r}: start and stop must be finite")
    if log:
        if start <= 0.0 or stop <= 0.0:
            raise InputError(f"{flag} {text!r}: a log range needs start, stop > 0")
        grid = np.geomspace(start, stop, n)
    else:
        grid = np.linspace(start, stop, n)
    return [float(v) for v in grid]


@dataclass(frozen=True)
class Axis:
    """One grid axis as given: ``param`` and exactly one of ``values`` (``a,b,...``) or
    ``span`` (``start:stop:n[:log]``); ``suffix`` is ``""`` or ``"2"`` (for messages)."""

    param: str | None = None
    values: str | None = None
    span: str | None = None
    suffix: str = ""

    def resolve(self, max_n: int) -> tuple[str, list[float]] | None:
        s = self.suffix
        flags = f"--values{s} or --range{s}"
        if self.param is None:
            if self.values is not None or self.span is not None:
                raise InputError(f"{flags} given without --param{s}")
            return None
        name = resolve_param(self.param)
        if (self.values is None) == (self.span is None):
            raise InputError(f"--param{s} {self.param[:80]} needs exactly one of {flags}")
        if self.values is not None:
            grid = parse_values(self.values, f"--values{s}")
        else:
            assert self.span is not None
            grid = parse_range(self.span, f"--range{s}", max_n)
        return name, grid


@dataclass(frozen=True)
class SweepOptions:
    """The inputs of a sweep: the base run, the axes, seeds, execution and outputs."""

    run: runs.RunOptions = field(default_factory=runs.RunOptions)
    axes: tuple[Axis, ...] = ()
    repeats: int = 1
    seed_per_point: bool = False
    jobs: int = 1
    backend: str = "local"
    ray_address: str | None = None
    retry_failed: bool = False
    out: str = DEFAULT_OUT
    plots: str | None = None
    no_plots: bool = False
    traces: str | None = None
    max_points: int = MAX_POINTS
    argv: tuple[str, ...] = ()


@dataclass(frozen=True)
class SweepPoint:
    """One simulation of a sweep: picklable, shipped to a worker process or Ray task.

    ``values`` are the swept groups as ``(field, value)`` pairs in grid order;
    ``run`` the fully resolved run of this point (its seed included);
    ``trace_path`` where the worker saves the trace (and a PNG), or None.
    """

    index: int
    values: tuple[tuple[str, float], ...]
    run: runs.RunSpec
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


_RUN_FIELDS = frozenset(runs.GROUP_FIELDS.values())


def point_options(
    base: runs.RunOptions, values: Sequence[tuple[str, float]], seed: int
) -> runs.RunOptions:
    """The base run with the swept groups set (as run flags where there are) and ``seed``."""
    groups = dict(base.groups)
    extra = {}
    for name, value in values:
        if name in _RUN_FIELDS:
            groups[name] = value
        else:
            extra[name] = value
    return dataclasses.replace(base, groups=groups, extra_groups=extra, seed=seed)


#: Run-config fields added after sweeps were recorded, and their defaults: a field at its
#: default is left out of the hash, so that a sweep recorded before it existed resumes.
LATER_CONFIG_FIELDS: dict[str, Any] = {
    "friction": 0.0,
    "settled_fraction": SETTLED_FRACTION,
    "flow_profile": "uniform",
}


def sweep_hash(spec: runs.RunSpec, swept: Sequence[str], base: runs.RunOptions) -> str:
    """Hash of everything that defines a sweep's points apart from the swept groups and
    the seed: the other groups, the solver and measurement options, the deposit length.
    Options that follow from a swept group (the default dt from Hbar, the substrate and
    its start-up radius from kappa_c) enter as given on the command line."""
    params = {k: v for k, v in spec.params.as_dict().items() if k not in swept}
    config = spec.config_dict()
    for derived in ("seed", "substrate", "initial_radius", "dt"):
        config.pop(derived, None)
    for key, default in LATER_CONFIG_FIELDS.items():
        if config.get(key) == default:
            config.pop(key)
    given = {"substrate": base.substrate, "initial_radius": base.initial_radius, "dt": base.dt}
    return config_hash({"params": params, "config": config, "given": given, "swept": list(swept)})


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
    options: SweepOptions = field(default_factory=SweepOptions)

    @property
    def columns(self) -> list[str]:
        return [*self.params, "seed", *RESULT_COLUMNS, "config_hash"]


def _check_int(flag: str, value: Any, low: int) -> None:
    try:
        units.check_int(flag, value, low=low)
    except units.ParameterError as exc:
        raise InputError(str(exc)) from exc


def resolve_sweep(opts: SweepOptions, warn: Any = None) -> SweepPlan:
    """Validate every input and every point of a sweep; raises RunInputError."""
    _check_int("--max-points", opts.max_points, 1)
    if opts.max_points > MAX_POINTS_CEILING:
        raise InputError(
            f"--max-points {opts.max_points} is over the ceiling of {MAX_POINTS_CEILING} runs"
        )
    axes = [a for a in (ax.resolve(opts.max_points) for ax in opts.axes) if a is not None]
    if not axes:
        raise InputError("give the swept parameter: --param NAME --values a,b,...")
    if len(axes) == 2 and axes[0][0] == axes[1][0]:
        raise InputError(f"--param and --param2 are both {axes[0][0]}")
    _check_int("--jobs", opts.jobs, 1)
    _check_int("--repeats", opts.repeats, 1)
    _check_int("--seed", opts.run.seed, 0)
    if opts.backend not in BACKENDS:
        raise InputError(f"--backend must be one of {', '.join(BACKENDS)}, got {opts.backend!r}")
    total = math.prod(len(v) for _, v in axes) * opts.repeats
    if total > opts.max_points:
        raise InputError(
            f"--max-points: this sweep has {total} runs (grid points x --repeats), over the "
            f"limit of {opts.max_points}; shrink the grid or raise --max-points"
        )
    swept = tuple(name for name, _ in axes)
    if "kappa_c_bar" in swept and opts.run.substrate == "flat":
        raise InputError("--substrate flat has no critical curvature to sweep (kappa_c_bar)")
    base = opts.run
    for name in swept:
        dest = {f: d for d, f in runs.GROUP_FIELDS.items()}.get(name)
        if dest is not None and base.groups.get(name) is not None and warn is not None:
            warn(f"--{dest.replace('_', '-')} is swept: the grid's values replace it")
        if dest is not None:  # the grid's values replace the base's
            base = dataclasses.replace(base, groups={**base.groups, name: None})

    try:
        csv_path = check_output_path(opts.out, "--out")
        check_output_path(f"{opts.out}.json", "--out")
    except OutputError as exc:
        raise InputError(str(exc)) from exc

    grid_values: list[tuple[float, ...]] = [()]
    for _, values in axes:
        grid_values = [(*g, v) for g in grid_values for v in values]
    specs: list[tuple[tuple[tuple[str, float], ...], runs.RunSpec]] = []
    for gi, combo in enumerate(grid_values):
        values = tuple(zip(swept, combo, strict=True))
        first = opts.run.seed + (gi * opts.repeats if opts.seed_per_point else 0)
        for seed in range(first, first + opts.repeats):
            try:
                spec = runs.resolve(point_options(base, values, seed), warn=None)
            except runs.RunInputError as exc:
                where = ", ".join(f"{k}={v!r}" for k, v in values)
                raise InputError(f"point {len(specs) + 1} of {total} ({where}): {exc}") from exc
            specs.append((values, spec))

    kappa_given = "kappa_c_bar" in swept or opts.run.groups.get("kappa_c_bar") is not None
    note = runs.kappa_c_steps_note(base.preset, base.substrate, kappa_given)
    if note is not None and warn is not None:  # once, after every point resolved
        warn(note)
    digest = sweep_hash(specs[0][1], swept, base)
    plots_dir = None if opts.no_plots else Path(opts.plots or csv_path.parent or ".")
    traces_dir = Path(opts.traces) if opts.traces else None
    for path, flag in ((plots_dir, "--plots"), (traces_dir, "--traces")):
        if path is None:
            continue
        if path.is_symlink() or (path.exists() and not path.is_dir()):
            raise InputError(f"{flag} {path} is not a directory")
        try:
            path.mkdir(parents=True, exist_ok=True)
        except OSError as exc:
            raise InputError(f"{flag}: cannot create {path}: {exc.strerror or exc}") from exc

    points = []
    for i, (values, spec) in enumerate(specs):
        trace_path = None
        if traces_dir is not None:
            name = "_".join(f"{k}={v:.6g}" for k, v in values) + f"_seed{spec.seed}.npz"
            trace_path = str(traces_dir / name)
        points.append(SweepPoint(i, values, spec, digest, trace_path))

    first_spec = specs[0][1]
    config = first_spec.config_dict()
    config.pop("seed")
    resolved = {
        "version": package_version(),
        "argv": list(opts.argv),
        "sweep": {
            "params": list(swept),
            "values": [list(values) for _, values in axes],
            "repeats": opts.repeats,
            "seed": opts.run.seed,
            "seed_per_point": opts.seed_per_point,
            "n_points": len(points),
            "backend": opts.backend,
            "jobs": opts.jobs,
            "ray_address": opts.ray_address,
        },
        "config_hash": digest,
        "params": first_spec.params.as_dict(),
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
        options=opts,
    )

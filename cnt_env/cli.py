"""The ``cnt-sim`` command line: thin subcommands over importable functions.

``main(argv=None)`` is the console-script entry point (also ``python -m cnt_env``)
and returns the exit code: 0 on success, 1 when a simulation or measurement fails,
2 on bad input (a usage error, an unphysical parameter, an unreadable trace file).

* ``cnt-sim run``: one deposition (:func:`resolve_run`, :func:`simulate`,
  :func:`measure_trace`); ``--json`` prints one JSON object and nothing else on
  stdout; ``--out`` saves the trace (``cnt_env.io``), ``--png`` a figure
  (``cnt_env.plotting``), each with its resolved config next to it (``<file>.json``).
* ``cnt-sim measure TRACE``: the same measurements for a saved trace.
* ``cnt-sim demo``: a short coil run that writes ``runs/demo/coil.png``.
* ``cnt-sim replay FILE --rrd OUT.rrd``: a saved trace (``run --out``) or a saved
  episode (``cnt_env.replay.save_episode``) as a rerun recording (``cnt_env.replay``);
  ``cnt-sim run --rrd`` records a run as it goes. rerun is an optional extra.
* ``cnt-sim sweep``: a grid of runs in parallel, resumable, with plots (``cnt_env.sweep``).

The simulator and matplotlib are imported only by the commands that need them, so
``cnt-sim --version`` and argument errors are instant.
"""

from __future__ import annotations

import argparse
import dataclasses
import json
import math
import re
import sys
import time
from collections.abc import Callable, Iterator, Mapping, Sequence
from contextlib import contextmanager
from dataclasses import dataclass
from importlib.metadata import PackageNotFoundError
from importlib.metadata import version as _dist_version
from pathlib import Path
from typing import TYPE_CHECKING, Any

from cnt_env import units
from cnt_env.io import TraceFileError, load_trace, save_trace, to_jsonable
from cnt_env.presets import (
    DEFAULT_KAPPA_C,
    DEMO_DEPOSIT,
    INITIAL_RADIUS,
    MESH,
    RUN_DEPOSIT,
    RUN_TRANSIENT,
)

if TYPE_CHECKING:
    from cnt_env.patterns import MeasureOptions
    from cnt_env.sim.deposition import DepositionConfig, DepositionSim

DIST_NAME = "cnt-env"
PROG = "cnt-sim"

EXIT_OK = 0
EXIT_FAILED = 1  # the simulation or the measurement failed
EXIT_USAGE = 2  # bad input: argparse's code too

#: Trace length (L_vb) a run deposits when --deposit is not given. Coil: clean circles
#: follow a start-up of 200-500 L_vb (docs/model.md §6). Serpentine: about 10 cycles of
#: ~70 L_vb each (amplitude ~30) after the transient, for the periodicity test (§7).
#: start-up length dropped before measuring, per preset (coils are clean after 200-300
#: L_vb at the validated mesh, serpentines after ~150: benchmarks/RESULTS.md)

# Choices mirrored from forces.DRAG_LAWS, deposition.CONTACT_MODES and
# substrate.SLIDING_OPTIONS, so that parsing does not import numba. The simulator
# validates them again when it is built.
DRAG_LAWS = ("linear", "printed")
CONTACT_MODES = ("event", "project")
SLIDING_OPTIONS = ("B", "C")
#: start-up contact arc radius R_i (docs/model.md §4: ~0.5 um, 6.4 L_vb flat, 3.9 stepped)

# Dimensionless groups settable on the command line: argparse dest -> field.
GROUP_FIELDS: dict[str, str] = {
    "Hbar": "Hbar",
    "Ibar": "Ibar",
    "vbar": "vbar",
    "phi": "phi",
    "kappa_c": "kappa_c_bar",
    "delta": "delta_bar",
}
# Groups the SI values determine: ignored (with a warning) when SI values are given.
SI_DERIVED_GROUPS = ("Hbar", "Ibar", "vbar")
# SI values settable on the command line: argparse dest -> PhysicalParams field.
SI_FIELDS: dict[str, str] = {
    "kb": "k_b",
    "ev": "e_v",
    "rho": "rho",
    "mu": "mu",
    "H": "H",
    "v": "v",
}
# Parameter names in validation messages -> the flag that sets them.
_FLAGS: dict[str, str] = {
    **{field: "--" + dest.replace("_", "-") for dest, field in GROUP_FIELDS.items()},
    **{field: "--" + dest for dest, field in SI_FIELDS.items()},
    "phi": "--phi",
    "transient_length": "--transient",
    "dt": "--dt",
    "initial_radius": "--initial-radius",
}
_PARAM_IN_MESSAGE = re.compile(r"\b(?:PhysicalParams|DimensionlessParams|MeasureOptions)\.(\w+)")


class CliError(Exception):
    """Reported as ``cnt-sim: error: <message>`` with exit code ``code``."""

    def __init__(self, message: str, code: int = EXIT_USAGE) -> None:
        super().__init__(message)
        self.code = code


def package_version() -> str:
    """The installed distribution's version, or the source tree's when not installed."""
    try:
        return _dist_version(DIST_NAME)
    except PackageNotFoundError:
        from cnt_env import __version__

        return __version__


def _warn(message: str) -> None:
    print(f"{PROG}: warning: {message}", file=sys.stderr)


def _invalid(exc: Exception) -> CliError:
    """A validation error, prefixed with the flag of the parameter it names."""
    message = str(exc)
    match = _PARAM_IN_MESSAGE.search(message)
    name = match.group(1) if match else message.split(" ", 1)[0]
    flag = _FLAGS.get(name)
    return CliError(f"{flag}: {message}" if flag else message)


# --------------------------------------------------------------------------- run: inputs


def resolve_params(
    preset: str,
    groups: Mapping[str, float] | None = None,
    si: Mapping[str, float] | None = None,
) -> tuple[units.DimensionlessParams, units.PhysicalParams | None, list[str]]:
    """The dimensionless groups of a run.

    ``groups`` overrides fields of ``units.paper_groups(preset)`` (``Hbar``,
    ``Ibar``, ``vbar``, ``phi``, ``kappa_c_bar``, ``delta_bar``). When ``si``
    gives any SI value (``PhysicalParams`` fields ``k_b``, ``e_v``, ``rho``,
    ``mu``, ``H``, ``v``), SI wins: the preset's SI values (``units.preset``)
    with those replaced are converted by ``to_dimensionless()``; k_t follows k_b
    (the presets have k_t = k_b), delta is ``DEFAULT_DELTA_BAR`` L_vb of the new
    L_vb, and of the groups only ``phi``, ``kappa_c_bar`` and ``delta_bar`` still
    apply (the others are returned as ignored).

    Returns ``(params, physical or None, ignored group names)``. Raises
    ``units.ParameterError`` naming the first invalid parameter.
    """
    groups = {k: v for k, v in (groups or {}).items() if v is not None}
    si = {k: v for k, v in (si or {}).items() if v is not None}
    if not si:
        return units.paper_groups(preset, **groups), None, []
    base = units.preset(preset)
    changes: dict[str, Any] = dict(si)
    if "k_b" in changes:
        # keep the preset's k_t / k_b; PhysicalParams validates k_b itself
        ratio = base.k_t / base.k_b
        kb = changes["k_b"]
        changes["k_t"] = ratio * kb if isinstance(kb, (int, float)) and kb > 0 else base.k_t
    if "phi" in groups:
        changes["phi"] = groups["phi"]
    physical = dataclasses.replace(base, delta=None, **changes)
    params = physical.to_dimensionless()
    late = {k: groups[k] for k in ("kappa_c_bar", "delta_bar") if k in groups}
    if late:
        params = dataclasses.replace(params, **late)
    ignored = [k for k in SI_DERIVED_GROUPS if k in groups]
    return params, physical, ignored


def apply_substrate(params: units.DimensionlessParams, substrate: str | None):
    """``--substrate`` overrides the preset's: flat drops kappa_c, stepped sets the paper's
    kappa_c = 0.2 unless the preset or --kappa-c already gives one."""
    if substrate == "flat" and params.is_stepped:
        return dataclasses.replace(params, kappa_c_bar=None)
    if substrate == "stepped" and not params.is_stepped:
        return dataclasses.replace(params, kappa_c_bar=DEFAULT_KAPPA_C)
    return params


@dataclass(frozen=True)
class RunSpec:
    """A validated ``cnt-sim run``: everything needed before any simulation work."""

    preset: str
    substrate: str
    params: units.DimensionlessParams
    physical: units.PhysicalParams | None
    sim_config: DepositionConfig
    deposit_length: float
    seed: int
    measure_options: MeasureOptions

    def config_dict(self) -> dict[str, Any]:
        """The run's configuration apart from the groups (saved and printed as ``config``)."""
        c = self.sim_config
        return {
            "preset": self.preset,
            "substrate": self.substrate,
            "deposit_length": self.deposit_length,
            "dt": c.time_step,
            "dt_factor": None if c.dt is not None else c.dt_factor,
            "drag_law": c.drag_law,
            "sliding": c.sliding,
            "coarse_delta": c.coarse_delta,
            "fine_length": c.fine_length,
            "contact_mode": c.contact.mode,
            "seed": self.seed,
            "initial_radius": c.initial_radius,
            "perturbation": c.perturbation,
            "transient_length": self.measure_options.transient_length,
            "si": None if self.physical is None else dataclasses.asdict(self.physical),
        }


def resolve_run(args: argparse.Namespace) -> RunSpec:
    """Validate every input of ``cnt-sim run``; raises :class:`CliError` (exit 2)."""
    groups = {field: getattr(args, dest) for dest, field in GROUP_FIELDS.items()}
    si = {field: getattr(args, dest) for dest, field in SI_FIELDS.items()}
    try:
        params, physical, ignored = resolve_params(args.preset, groups, si)
    except units.ParameterError as exc:
        raise _invalid(exc) from exc
    if ignored:
        flags = ", ".join(_FLAGS[k] for k in ignored)
        _warn(f"SI values given, so {flags} {'is' if len(ignored) == 1 else 'are'} ignored")
    try:
        params = apply_substrate(params, args.substrate)
    except units.ParameterError as exc:
        raise _invalid(exc) from exc

    deposit = RUN_DEPOSIT[args.preset] if args.deposit is None else args.deposit
    if not (math.isfinite(deposit) and deposit > 0.0):
        raise CliError(f"--deposit must be a finite trace length > 0 in L_vb, got {deposit!r}")
    if args.seed < 0:
        raise CliError(f"--seed must be >= 0, got {args.seed}")
    transient = RUN_TRANSIENT[args.preset] if args.transient is None else args.transient
    measure_options = measure_options_for(transient)

    from cnt_env.sim.deposition import ContactOptions, DepositionConfig

    mesh = MESH[args.preset]
    try:
        if args.delta is None:  # the preset's validated mesh
            params = dataclasses.replace(params, delta_bar=mesh["delta_bar"])
        coarse = args.coarse_delta
        if coarse is None and args.delta is None:
            coarse = mesh["coarse_delta"]
        contact = ContactOptions(mode=args.contact_mode)
        radius = args.initial_radius
        if radius is None:
            radius = INITIAL_RADIUS["stepped" if params.is_stepped else "flat"]
        sim_config = DepositionConfig(
            params=params, dt=args.dt, drag_law=args.drag_law, contact=contact,
            initial_radius=radius, sliding=args.sliding, coarse_delta=coarse,
            fine_length=args.fine_length,
        )  # fmt: skip
    except ValueError as exc:
        raise _invalid(exc) from exc
    return RunSpec(
        preset=args.preset,
        substrate="stepped" if params.is_stepped else "flat",
        params=params,
        physical=physical,
        sim_config=sim_config,
        deposit_length=float(deposit),
        seed=int(args.seed),
        measure_options=measure_options,
    )


def measure_options_for(transient: float | None) -> MeasureOptions:
    """Measurement options with ``transient`` L_vb dropped (None: the default)."""
    from cnt_env.patterns import MeasureOptions

    try:
        if transient is None:
            return MeasureOptions()
        return MeasureOptions(transient_length=transient)
    except ValueError as exc:
        raise _invalid(exc) from exc


# --------------------------------------------------------------------------- run: work

ProgressCallback = Callable[[float, float], None]


@contextmanager
def progress_bar(enabled: bool, total: float, min_interval: float = 0.1) -> Iterator[Any]:
    """A ``progress(done, total)`` callback drawing a tqdm bar on stderr, or None.

    The simulator calls it after every step (tens of thousands per run), so the bar
    is refreshed at most every ``min_interval`` seconds.
    """
    if not enabled:
        yield None
        return
    from tqdm import tqdm

    bar = tqdm(
        total=total,
        file=sys.stderr,
        desc="depositing",
        bar_format="{desc}: {percentage:3.0f}%|{bar}| {n:.1f}/{total:.0f} L_vb "
        "[{elapsed}<{remaining}]",
    )
    last = -math.inf

    def update(done: float, total: float) -> None:
        nonlocal last
        now = time.monotonic()
        if now - last >= min_interval or done >= total:
            bar.n = done
            bar.refresh()
            last = now

    try:
        yield update
    finally:
        bar.close()


def simulate(
    config: DepositionConfig,
    deposit_length: float,
    seed: int = 0,
    progress: ProgressCallback | None = None,
) -> tuple[DepositionSim, dict[str, Any]]:
    """Run one deposition until ``deposit_length`` L_vb of trace is laid.

    Returns the simulator and its ``stats()`` plus ``wall_time_s``. Raises
    ``SimulationError`` when the solver fails.
    """
    from cnt_env.sim.deposition import DepositionSim

    start = time.perf_counter()
    sim = DepositionSim(config, seed=seed)
    sim.run(deposit_length, progress=progress)
    stats = dict(sim.stats())
    stats["wall_time_s"] = time.perf_counter() - start
    return sim, stats


def measure_trace(
    trace: Any, options: MeasureOptions, substrate: str, phi: float = 0.0
) -> dict[str, Any]:
    """``patterns.measure`` of a trace; a trace too short to measure gives
    ``pattern`` None and the reason in ``error`` instead of raising."""
    from cnt_env.patterns import measure

    try:
        return measure(trace, options, substrate, flow_direction=(math.cos(phi), math.sin(phi)))
    except ValueError as exc:
        return {
            "pattern": None,
            "substrate": substrate,
            "transient_length": options.transient_length,
            "error": str(exc),
        }


def result_dict(
    measurement: Mapping[str, Any],
    stats: Mapping[str, Any],
    params: Mapping[str, Any],
    config: Mapping[str, Any],
) -> dict[str, Any]:
    """The report of a run (``--json``), lengths in L_vb, times in mu L_vb^2 / e_v."""
    nan = math.nan
    return {
        "pattern": measurement.get("pattern"),
        "coil_radius": measurement.get("coil_radius", nan),
        "amplitude": measurement.get("amplitude", nan),
        "wavelength": measurement.get("wavelength", nan),
        "deposited_length": stats.get("deposited_length"),
        "sim_time": stats.get("time"),
        "steps": stats.get("steps"),
        "newton_iterations": stats.get("newton_iterations"),
        "wall_time_s": stats.get("wall_time_s"),
        "params": dict(params),
        "coil_radius_spread": measurement.get("coil_radius_spread", [nan, nan]),
        "measure": dict(measurement),
        "config": dict(config),
        "version": package_version(),
    }


def _fmt(value: Any, spec: str = ".4g") -> str:
    if value is None or (isinstance(value, float) and not math.isfinite(value)):
        return "-"
    return format(value, spec)


def format_summary(result: Mapping[str, Any], written: Sequence[Path] = ()) -> str:
    """The human-readable report of a run or a measurement."""
    p, c, m = result["params"], result["config"], result["measure"]
    lines = [
        f"{PROG} {result['version']}: {c.get('preset', '?')} preset, "
        f"{c.get('substrate', 'flat')} substrate",
        f"  Hbar={_fmt(p['Hbar'])} Ibar={_fmt(p['Ibar'])} vbar={_fmt(p['vbar'])} "
        f"phi={_fmt(p['phi'])} delta_bar={_fmt(p['delta_bar'])} dt={_fmt(c.get('dt'))} "
        f"drag={c.get('drag_law')} contact={c.get('contact_mode')} sliding={c.get('sliding')}",
        f"deposited {_fmt(result['deposited_length'], '.1f')} L_vb in {result['steps']} steps "
        f"({result['newton_iterations']} Newton iterations), "
        f"t = {_fmt(result['sim_time'])} tau, wall {_fmt(result['wall_time_s'], '.1f')} s",
    ]
    if m.get("error"):
        lines.append(f"pattern: not measured ({m['error']})")
    else:
        lines.append(
            f"pattern: {result['pattern']} (measured {_fmt(m.get('measured_length'), '.1f')} "
            f"L_vb after a transient of {_fmt(m.get('transient_length'), '.1f')})"
        )
        lo, hi = result["coil_radius_spread"]
        windows = f"{m.get('coil_n_windows')} windows, {m.get('coil_n_rejected')} rejected"
        if _fmt(result["coil_radius"]) == "-":
            lines.append(f"coil radius: none (no accepted one-turn window; {windows})")
        else:
            lines.append(
                f"coil radius: {_fmt(result['coil_radius'])} L_vb "
                f"(p16-p84 {_fmt(lo)}-{_fmt(hi)}, {windows})"
            )
        serpentine = c.get("substrate") == "stepped" or "serpentine" in str(result["pattern"])
        if serpentine:  # on a flat substrate the U-turn measures only see a coil's wobble
            lines.append(
                f"amplitude: {_fmt(result['amplitude'])} L_vb, "
                f"wavelength: {_fmt(result['wavelength'])} L_vb, {m.get('n_cycles')} cycles"
            )
    lines += [f"wrote {path} (config: {path}.json)" for path in written]
    return "\n".join(lines)


def _print_json(result: Mapping[str, Any]) -> None:
    print(json.dumps(to_jsonable(result), allow_nan=False))


def _output_path(value: str | None, flag: str) -> Path | None:
    """Check an output path before any work, creating its directory."""
    if value is None:
        return None
    path = Path(value)
    if path.is_dir():
        raise CliError(f"{flag} {value} is a directory; pass a file name")
    try:
        path.parent.mkdir(parents=True, exist_ok=True)
    except OSError as exc:
        raise CliError(f"{flag} {value}: cannot create its directory: {exc}") from exc
    return path


def write_config_json(path: Path, resolved: Mapping[str, Any]) -> Path:
    """Write the resolved config next to an output: ``<path>.json``
    (docs/architecture.md rule 12)."""
    out = Path(f"{path}.json")
    text = json.dumps(to_jsonable({**resolved, "output": str(path)}), indent=2, allow_nan=False)
    out.write_text(text + "\n")
    return out


def _argv(args: argparse.Namespace) -> list[str]:
    return list(getattr(args, "argv", None) or [])


def cmd_run(args: argparse.Namespace) -> int:
    spec = resolve_run(args)
    out = _output_path(args.out, "--out")
    png = _output_path(args.png, "--png")
    if out is not None and png is not None and out.resolve() == png.resolve():
        raise CliError("--out and --png name the same file")
    rrd = _output_path(getattr(args, "rrd", None), "--rrd")
    if rrd is not None and any(p is not None and p.resolve() == rrd.resolve() for p in (out, png)):
        raise CliError("--rrd names the same file as --out or --png")
    if rrd is not None:
        _require_rerun()

    from cnt_env.sim.stepper import SimulationError

    show_bar = not args.json and sys.stderr.isatty()
    try:
        with progress_bar(show_bar, spec.deposit_length) as progress:
            if rrd is None:
                sim, stats = simulate(spec.sim_config, spec.deposit_length, spec.seed, progress)
            else:  # the same run, sampled into a rerun recording as it goes
                from cnt_env.replay import record_run

                sim, stats = record_run(spec.sim_config, spec.deposit_length, rrd,
                                        seed=spec.seed, progress=progress,
                                        run_config=spec.config_dict())  # fmt: skip
    except SimulationError as exc:
        raise CliError(str(exc), EXIT_FAILED) from exc
    trace, suspended = sim.trace(), sim.suspended_nodes.copy()
    measurement = measure_trace(trace, spec.measure_options, spec.substrate, spec.params.phi)
    if measurement.get("error"):
        _warn(f"trace not measured: {measurement['error']}")

    params, config = spec.params.as_dict(), spec.config_dict()
    result = result_dict(measurement, stats, params, config)
    resolved = {
        "version": result["version"],
        "argv": _argv(args),
        "params": params,
        "config": config,
    }
    written = []
    try:
        if out is not None:
            save_trace(out, trace, params, config, stats, suspended, version=result["version"])
            write_config_json(out, resolved)
            written.append(out)
        if png is not None:
            from cnt_env.plotting import plot_run

            plot_run(trace, suspended, measurement, png)
            write_config_json(png, resolved)
            written.append(png)
        if rrd is not None:  # written by record_run
            write_config_json(rrd, resolved)
            written.append(rrd)
    except OSError as exc:
        raise CliError(f"cannot write output: {exc}", EXIT_FAILED) from exc

    if args.json:
        _print_json(result)
    else:
        print(format_summary(result, written))
    return EXIT_OK


# --------------------------------------------------------------------------- measure


def cmd_measure(args: argparse.Namespace) -> int:
    png = _output_path(args.png, "--png")
    try:
        saved = load_trace(args.trace)
    except TraceFileError as exc:
        raise CliError(str(exc)) from exc
    config, params = saved["config"], saved["params"]
    transient = config.get("transient_length") if args.transient is None else args.transient
    options = measure_options_for(transient)
    substrate = config.get("substrate") or "flat"
    measurement = measure_trace(saved["trace"], options, substrate, params.get("phi") or 0.0)
    result = result_dict(measurement, saved["stats"], params, config)
    result["file"] = str(args.trace)
    result["trace_version"] = saved["version"]
    written = []
    if png is not None:
        from cnt_env.plotting import plot_run

        plot_run(saved["trace"], saved["suspended"], measurement, png)
        resolved = {
            "version": result["version"],
            "argv": _argv(args),
            "source": str(args.trace),
            "transient_length": options.transient_length,
            "params": params,
            "config": config,
        }
        write_config_json(png, resolved)
        written.append(png)
    if args.json:
        _print_json(result)
    else:
        print(f"{args.trace}:")
        print(format_summary(result, written))
    if measurement.get("error"):
        print(f"{PROG}: error: trace not measured: {measurement['error']}", file=sys.stderr)
        return EXIT_FAILED
    return EXIT_OK


# --------------------------------------------------------------------------- replay


def _require_rerun() -> None:
    """Fail before any work when the optional rerun extra is missing."""
    from cnt_env.replay import import_rerun

    try:
        import_rerun()
    except ImportError as exc:
        raise CliError(str(exc), EXIT_FAILED) from exc


def cmd_replay(args: argparse.Namespace) -> int:
    """A saved trace or episode as a rerun recording (the kind from its ``format``)."""
    from cnt_env import replay
    from cnt_env.io import TRACE_FORMAT

    rrd = _output_path(args.rrd, "--rrd")
    assert rrd is not None
    _require_rerun()
    try:
        kind = replay.file_format(args.file)
    except replay.EpisodeFileError as exc:
        raise CliError(str(exc)) from exc
    try:
        if kind == replay.EPISODE_FORMAT:
            rid = replay.record_episode(args.file, rrd, recording_id=args.recording_id)
        elif kind == TRACE_FORMAT:
            saved = load_trace(args.file)
            rid = replay.record_simulation(saved, rrd, recording_id=args.recording_id)
        else:
            raise CliError(
                f"{args.file} is neither a cnt_env trace (`cnt-sim run --out`) nor a "
                f"cnt_env episode file (format {kind!r})"
            )
    except (TraceFileError, replay.EpisodeFileError) as exc:
        raise CliError(str(exc)) from exc
    except OSError as exc:
        raise CliError(f"cannot write {rrd}: {exc}", EXIT_FAILED) from exc
    result = {"file": str(args.file), "kind": kind, "rrd": str(rrd), "recording_id": rid}
    if args.json:
        _print_json(result)
    else:
        print(f"wrote {rrd} (recording {rid}, from the {kind} file {args.file}); "
              f"open it with `rerun {rrd}`")  # fmt: skip
    return EXIT_OK


# --------------------------------------------------------------------------- demo


def cmd_demo(args: argparse.Namespace) -> int:
    """The main job (``make demo``): a short coil deposition with a figure."""
    outdir = Path(args.outdir)
    print(f"{PROG} {package_version()}: demo, {args.deposit:g} L_vb of coil deposition")
    run_argv = [
        "run",
        "--preset",
        "coil",
        "--deposit",
        repr(args.deposit),
        "--out",
        str(outdir / "coil.npz"),
        "--png",
        str(outdir / "coil.png"),
    ]
    return main(run_argv)


# --------------------------------------------------------------------------- parser


def add_group_arguments(g: Any) -> None:
    """The dimensionless-group flags shared by ``run`` and ``sweep`` (GROUP_FIELDS)."""
    g.add_argument("--Hbar", type=float, help="rod height H / L_vb")
    g.add_argument("--Ibar", type=float, help="mass per length rho e_v^2 / (k_b mu^2)")
    g.add_argument("--vbar", type=float, help="flow speed v mu H / e_v (>= 0)")
    g.add_argument("--phi", type=float, help="flow direction in the x-z plane from +x [rad]")
    g.add_argument(
        "--kappa-c",
        dest="kappa_c",
        type=float,
        help="critical curvature kappa_c L_vb (stepped substrate)",
    )
    g.add_argument(
        "--delta",
        type=float,
        help="discretisation length delta / L_vb (default: the preset's validated mesh, "
        "coil 0.125 graded to 1, serpentine 1)",
    )
    g.add_argument(
        "--dt",
        type=float,
        help="time step in mu L_vb^2 / e_v (default: DepositionConfig.dt_factor Hbar)",
    )


def add_model_arguments(m: Any) -> None:
    """The model and solver flags shared by ``run`` and ``sweep`` (see resolve_run)."""
    m.add_argument("--drag-law", choices=DRAG_LAWS, default="linear")
    m.add_argument(
        "--sliding",
        choices=SLIDING_OPTIONS,
        default="B",
        help="stepped substrate: B fixed in x, C free in x until snapped",
    )
    m.add_argument(
        "--coarse-delta",
        type=float,
        default=None,
        help="graded mesh: inject edges of this length, split near the contact",
    )
    m.add_argument(
        "--fine-length",
        type=float,
        default=20.0,
        help="graded mesh: arc length above the contact kept at --delta",
    )
    m.add_argument("--contact-mode", choices=CONTACT_MODES, default="event")
    m.add_argument(
        "--initial-radius",
        type=float,
        metavar="R",
        help="radius of the start-up contact arc, L_vb (default: 6.4 flat, 3.9 stepped)",
    )


def _add_run_arguments(run: argparse.ArgumentParser) -> None:
    run.add_argument(
        "--preset",
        choices=units.PRESETS,
        default="coil",
        help="the paper's dimensionless groups (default: coil)",
    )
    run.add_argument(
        "--substrate",
        choices=("flat", "stepped"),
        default=None,
        help="flat sticky or stepped (default: the preset's)",
    )

    g = run.add_argument_group("dimensionless groups (override the preset; lengths in L_vb)")
    add_group_arguments(g)
    g.add_argument(
        "--deposit",
        type=float,
        metavar="LENGTH",
        help="trace length to deposit, L_vb (default: "
        + ", ".join(f"{k} {v:g}" for k, v in RUN_DEPOSIT.items())
        + ")",
    )

    si = run.add_argument_group(
        "SI values (replace the preset's SI values; when given, they win over --Hbar/--Ibar/--vbar)"
    )
    si.add_argument("--kb", type=float, metavar="N_M2", help="bending stiffness k_b [N m^2]")
    si.add_argument("--ev", type=float, metavar="J_PER_M", help="vdW adhesion energy e_v [J/m]")
    si.add_argument("--rho", type=float, metavar="KG_PER_M", help="mass per length [kg/m]")
    si.add_argument("--mu", type=float, metavar="PA_S", help="drag coefficient mu [Pa s]")
    si.add_argument("--H", type=float, metavar="M", help="rod height H [m]")
    si.add_argument("--v", type=float, metavar="M_PER_S", help="flow speed v [m/s]")

    m = run.add_argument_group("model and solver options")
    m.add_argument("--seed", type=int, default=0, help="seed of the start-up noise (default 0)")
    add_model_arguments(m)
    m.add_argument(
        "--transient",
        type=float,
        metavar="L",
        help="start-up arc length dropped before measuring, L_vb (default: "
        + ", ".join(f"{k} {v:g}" for k, v in RUN_TRANSIENT.items())
        + ")",
    )

    o = run.add_argument_group("outputs (each gets its resolved config as <file>.json)")
    o.add_argument("--out", metavar="TRACE.npz", help="save the trace (cnt_env.io format)")
    o.add_argument("--png", metavar="FIG.png", help="plot the trace and the suspended rod")
    o.add_argument(
        "--rrd",
        metavar="RUN.rrd",
        help="record the run for the rerun viewer (needs the rerun extra)",
    )
    o.add_argument(
        "--json", action="store_true", help="print one JSON object on stdout and nothing else"
    )


def build_parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(
        prog=PROG,
        description="Carbon-nanotube deposition simulator (discrete elastic rods).",
    )
    parser.add_argument("--version", action="version", version=f"{PROG} {package_version()}")
    sub = parser.add_subparsers(dest="command", metavar="COMMAND", required=True)

    run = sub.add_parser(
        "run",
        help="run one deposition",
        allow_abbrev=False,
        description="Run one deposition and measure its trace.",
    )
    _add_run_arguments(run)
    run.set_defaults(func=cmd_run)

    measure = sub.add_parser(
        "measure",
        help="measure a saved trace",
        allow_abbrev=False,
        description="Measure a trace saved by `cnt-sim run --out`.",
    )
    measure.add_argument("trace", help="trace file (.npz) written by `cnt-sim run --out`")
    measure.add_argument(
        "--transient",
        type=float,
        metavar="L",
        help="start-up arc length dropped, L_vb (default: the run's)",
    )
    measure.add_argument("--png", metavar="FIG.png", help="plot the trace")
    measure.add_argument(
        "--json", action="store_true", help="print one JSON object on stdout and nothing else"
    )
    measure.set_defaults(func=cmd_measure)

    replay = sub.add_parser(
        "replay",
        help="turn a saved trace or episode into a rerun recording",
        allow_abbrev=False,
        description="Write a rerun recording (.rrd) of a trace saved by `cnt-sim run --out` "
        "or of an episode saved by cnt_env.replay.save_episode; open it with `rerun FILE.rrd`. "
        'Needs the rerun extra: pip install -e ".[rerun]".',
    )
    replay.add_argument("file", help="trace.npz or episode.npz (told apart by their format)")
    replay.add_argument("--rrd", required=True, metavar="OUT.rrd", help="recording to write")
    replay.add_argument("--recording-id", default=None, help="default: the file's own")
    replay.add_argument(
        "--json", action="store_true", help="print one JSON object on stdout and nothing else"
    )
    replay.set_defaults(func=cmd_replay)

    demo = sub.add_parser("demo", help="run the main job: a small coil deposition")
    demo.add_argument(
        "--deposit",
        type=float,
        default=DEMO_DEPOSIT,
        metavar="LENGTH",
        help=f"trace length, L_vb (default {DEMO_DEPOSIT:g})",
    )
    demo.add_argument("--outdir", default="runs/demo", help="output directory (runs/demo)")
    demo.set_defaults(func=cmd_demo)

    from cnt_env import sweep  # imports this module: deferred to avoid a cycle

    sweep.add_parser(sub)
    return parser


def main(argv: Sequence[str] | None = None) -> int:
    """Entry point of ``cnt-sim``; returns the process exit code (argparse's too)."""
    parser = build_parser()
    argv = list(sys.argv[1:] if argv is None else argv)
    try:
        args = parser.parse_args(argv)
    except SystemExit as exc:  # --help, --version, usage errors
        return exc.code if isinstance(exc.code, int) else EXIT_USAGE
    args.argv = argv
    try:
        return int(args.func(args))
    except CliError as exc:
        print(f"{PROG}: error: {exc}", file=sys.stderr)
        return exc.code
    except KeyboardInterrupt:
        print(f"{PROG}: interrupted", file=sys.stderr)
        return 130


if __name__ == "__main__":
    raise SystemExit(main())

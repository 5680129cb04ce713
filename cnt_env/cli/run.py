"""``cnt-sim run``, ``measure`` and ``demo``: argparse and formatting over
:mod:`cnt_env.runs` (docs/cli.md).

``run`` validates every input (:func:`cnt_env.runs.resolve`) and every output path
(:class:`cnt_env.io.OutputSet`) before any work, runs under the named limits, and writes
its outputs (trace, png, rrd, each with ``<file>.json``) as a unit at the end.
"""

from __future__ import annotations

import argparse
import math
import re
import sys
from collections.abc import Mapping, Sequence
from pathlib import Path
from typing import Any

from cnt_env import runs, units
from cnt_env.cli.common import (
    EXIT_FAILED,
    EXIT_OK,
    PROG,
    CliError,
    add_group_arguments,
    add_limit_arguments,
    add_model_arguments,
    add_settled_argument,
    print_json,
    progress_bar,
    require_rerun,
    warn,
)
from cnt_env.io import OutputSet, TraceFileError, config_json_text, load_trace, save_trace
from cnt_env.presets import RUN_DEPOSIT, RUN_TRANSIENT


def run_options(args: argparse.Namespace) -> runs.RunOptions:
    """The typed inputs of a run (or of a sweep's base run) from parsed flags."""
    return runs.RunOptions(
        preset=args.preset,
        substrate=args.substrate,
        groups={f: getattr(args, dest) for dest, f in runs.GROUP_FIELDS.items()},
        si={f: getattr(args, dest, None) for dest, f in runs.SI_FIELDS.items()},
        deposit=args.deposit,
        seed=args.seed,
        transient=args.transient,
        settled_fraction=args.settled_fraction,
        dt=args.dt,
        drag_law=args.drag_law,
        sliding=args.sliding,
        friction=args.friction,
        flow_profile=args.flow_profile,
        coarse_delta=args.coarse_delta,
        fine_length=args.fine_length,
        contact_mode=args.contact_mode,
        adhesion=args.adhesion,
        cohesive_range=args.cohesive_range,
        initial_radius=args.initial_radius,
        limits=runs.Limits(
            max_nodes=args.max_nodes,
            max_steps_per_length=args.max_steps,
            max_wall_time=args.max_wall_time,
        ),
    )


def _flag_hint(message: str) -> str:
    """A measurement message with its Python option names replaced by the CLI flag."""
    return re.sub(r"MeasureOptions\.(\w+)", lambda m: runs.FLAGS.get(m[1], m[0]), message)


def argv_of(args: argparse.Namespace) -> list[str]:
    return list(getattr(args, "argv", None) or [])


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
        f"drag={c.get('drag_law')} contact={c.get('contact_mode')} "
        f"adhesion={c.get('adhesion', 'eq1')} sliding={c.get('sliding')}",
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


def stage_output(outputs: OutputSet, value: str | None, flag: str) -> Path | None:
    """Check an output and its ``<file>.json`` and stage both (temporary files in their
    folder) before any work; None when not asked for. A ``--png`` is a PNG by name too
    (``fig.jpg`` held PNG bytes)."""
    if value is None:
        return None
    path = outputs.check(value, flag)
    if flag == "--png" and path.suffix.lower() != ".png":
        raise CliError(f"--png {value}: the figure is a PNG: name it <file>.png")
    outputs.check(f"{path}.json", flag)
    outputs.add(path, flag, checked=True)
    outputs.add(f"{path}.json", flag, checked=True)
    return path


def cmd_run(args: argparse.Namespace) -> int:
    outputs = OutputSet(inputs={"the --config file": getattr(args, "config", None)})
    try:
        return _run(args, outputs)
    finally:
        outputs.discard()  # after a commit: nothing left to discard


def _run(args: argparse.Namespace, outputs: OutputSet) -> int:
    spec = runs.resolve(run_options(args), warn=warn)
    out = stage_output(outputs, args.out, "--out")
    png = stage_output(outputs, args.png, "--png")
    rrd = stage_output(outputs, getattr(args, "rrd", None), "--rrd")
    runner = None
    if rrd is not None:
        from cnt_env.replay import record_run

        require_rerun()
        rrd_tmp = outputs.temp_for(rrd)

        def runner(config, length, seed, progress):  # the same run, recorded as it goes
            return record_run(config, length, rrd_tmp, seed=seed, progress=progress,
                              run_config=spec.config_dict())  # fmt: skip

    from cnt_env.sim.stepper import SimulationError

    show_bar = not args.json and sys.stderr.isatty()
    try:
        with progress_bar(show_bar, spec.deposit_length) as progress:
            result = runs.simulate(spec, progress, runner=runner)
    except SimulationError as exc:
        raise CliError(str(exc), EXIT_FAILED) from exc
    measurement = result.measurement
    if measurement.get("error"):
        warn(f"trace not measured: {_flag_hint(measurement['error'])}")

    report = result.report()
    params, config = report["params"], report["config"]
    resolved = {"version": report["version"], "argv": argv_of(args), "params": params,
                "config": config}  # fmt: skip
    written = []
    try:
        if out is not None:
            tmp = outputs.temp_for(out)
            save_trace(tmp, result.trace, params, config, result.stats, result.suspended,
                       version=report["version"])  # fmt: skip
            written.append(out)
        if png is not None:
            from cnt_env.plotting import plot_run

            plot_run(result.trace, result.suspended, measurement,
                     outputs.temp_for(png))  # fmt: skip
            written.append(png)
        if rrd is not None:  # written by record_run
            written.append(rrd)
        for path in written:
            outputs.temp_for(f"{path}.json").write_text(config_json_text(path, resolved))
        outputs.commit()
    except OSError as exc:
        raise CliError(f"cannot write output: {exc}", EXIT_FAILED) from exc

    if args.json:
        print_json(report)
    else:
        print(format_summary(report, written))
    return EXIT_OK


def cmd_measure(args: argparse.Namespace) -> int:
    outputs = OutputSet(inputs={"the trace measured": args.trace})
    try:
        return _measure(args, outputs)
    finally:
        outputs.discard()  # after a commit: nothing left to discard


def _measure(args: argparse.Namespace, outputs: OutputSet) -> int:
    png = stage_output(outputs, args.png, "--png")
    try:
        saved = load_trace(args.trace)
    except TraceFileError as exc:
        raise CliError(str(exc)) from exc
    config, params = saved["config"], saved["params"]
    transient = config.get("transient_length") if args.transient is None else args.transient
    settled = args.settled_fraction
    if settled is None:
        settled = config.get("settled_fraction")  # None in a trace from before the flag
    options = runs.measure_options_for(transient, settled)
    substrate = config.get("substrate") if config.get("substrate") in runs.SUBSTRATES else "flat"
    measurement = runs.measure(saved["trace"], options, substrate, params.get("phi") or 0.0)
    result = runs.result_dict(measurement, saved["stats"], params, config)
    result["file"] = str(args.trace)
    result["trace_version"] = saved["version"]
    written = []
    if png is not None:
        from cnt_env.plotting import plot_run

        resolved = {
            "version": result["version"],
            "argv": argv_of(args),
            "source": str(args.trace),
            "transient_length": options.transient_length,
            "settled_fraction": options.settled_fraction,
            "params": params,
            "config": config,
        }
        try:
            with outputs:
                plot_run(saved["trace"], saved["suspended"], measurement,
                         outputs.temp_for(png))  # fmt: skip
                outputs.temp_for(f"{png}.json").write_text(config_json_text(png, resolved))
        except OSError as exc:
            raise CliError(f"cannot write output: {exc}", EXIT_FAILED) from exc
        written.append(png)
    if args.json:
        print_json(result)
    else:
        print(f"{args.trace}:")
        print(format_summary(result, written))
    if measurement.get("error"):
        print(f"{PROG}: error: trace not measured: {_flag_hint(measurement['error'])}",
              file=sys.stderr)  # fmt: skip
        return EXIT_FAILED
    return EXIT_OK


#: Keys of a ``cnt-sim run --config`` file -> the flag (argparse dest) they set. The
#: ``config`` and ``params`` sections of the ``<out>.json`` a run writes use the names on
#: the left too, so that file round-trips.
CONFIG_KEYS: dict[str, str] = {
    "preset": "preset", "substrate": "substrate", "seed": "seed", "dt": "dt",
    "deposit": "deposit", "deposit_length": "deposit",
    "transient": "transient", "transient_length": "transient",
    "settled_fraction": "settled_fraction",
    "drag_law": "drag_law", "sliding": "sliding", "friction": "friction",
    "flow_profile": "flow_profile", "coarse_delta": "coarse_delta",
    "fine_length": "fine_length", "contact_mode": "contact_mode",
    "adhesion": "adhesion", "cohesive_range": "cohesive_range",
    "initial_radius": "initial_radius", "max_nodes": "max_nodes", "max_steps": "max_steps",
    "max_wall_time": "max_wall_time",
    **{dest: dest for dest in runs.GROUP_FIELDS},
    **{field: dest for dest, field in runs.GROUP_FIELDS.items()},
    **{dest: dest for dest in runs.SI_FIELDS},
}  # fmt: skip


def load_run_config(path: str) -> dict[str, Any]:
    """The flag values (argparse dests) of a ``--config`` file: YAML or JSON, either a
    flat mapping of :data:`CONFIG_KEYS` (dashes or underscores) or the ``<out>.json`` a
    run writes (its ``config`` and ``params`` sections; the other keys are ignored)."""
    import yaml

    try:
        data = yaml.safe_load(Path(path).read_text())
    except (OSError, UnicodeDecodeError, yaml.YAMLError) as exc:
        raise CliError(f"--config {path}: cannot read it as YAML or JSON ({exc})") from exc
    if not isinstance(data, dict):
        raise CliError(f"--config {path}: expected a mapping of settings, got "
                       f"{type(data).__name__}")  # fmt: skip
    if isinstance(data.get("config"), dict):  # a run's <out>.json
        saved, params = data["config"], data.get("params") or {}
        flat = {k: v for k, v in saved.items() if k in CONFIG_KEYS}
        if "coarse_delta" in saved and saved["coarse_delta"] is None:
            flat["coarse_delta"] = 0.0  # the run was uniform: keep it so (0 = uniform)
        if saved.get("dt_factor") is not None:  # dt came from the default factor, not --dt
            flat.pop("dt", None)
        si = saved.get("si")
        if isinstance(si, dict):  # SI values given: they set the derived groups
            fields = {f: d for d, f in runs.SI_FIELDS.items()}
            flat.update({fields[k]: v for k, v in si.items() if k in fields})
        for dest, field in runs.GROUP_FIELDS.items():
            if field in params and not (isinstance(si, dict) and dest in runs.SI_DERIVED_GROUPS):
                flat[dest] = params[field]
    else:
        flat = {str(k).replace("-", "_"): v for k, v in data.items()}
        unknown = sorted(set(flat) - set(CONFIG_KEYS))
        if unknown:
            raise CliError(f"--config {path}: unknown settings {unknown}; use the names of "
                           f"the run flags: {sorted(CONFIG_KEYS)}")  # fmt: skip
    return {CONFIG_KEYS[k]: v for k, v in flat.items() if v is not None}


def add_run_arguments(run: argparse.ArgumentParser) -> None:
    """The flags of ``cnt-sim run``."""
    run.add_argument(
        "--config",
        metavar="FILE.yaml",
        help="settings from a YAML or JSON file (flag names as keys, or the <out>.json of "
        "an earlier run); flags given on the command line win",
    )
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
    add_settled_argument(m)

    add_limit_arguments(run.add_argument_group("limits (docs/cli.md)"))

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

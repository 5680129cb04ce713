"""One deposition run as a typed library: what ``cnt-sim run`` and every sweep point do.

* :class:`RunOptions`: the inputs of a run (preset, dimensionless groups, SI values,
  model and solver options, deposit and transient lengths, seed), frozen and typed;
  :func:`resolve_run` takes them as keyword arguments.
* :func:`resolve` validates them into a :class:`RunSpec` (the groups, the
  ``DepositionConfig`` and the measurement options), before any simulation work.
* :func:`simulate` runs a spec under its :class:`Limits` and measures the trace
  (:class:`RunResult`); :func:`measure` measures any trace.

Per-preset defaults come from :mod:`cnt_env.presets` only. Bad input raises
:class:`RunInputError` whose message starts with the ``cnt-sim`` flag of the parameter
(``--Hbar: ...``); a run stopped by a limit raises :class:`RunLimitError`.
The simulator and the pattern measures are imported by the functions that need them, so
that argument errors stay instant (docs/architecture.md).
"""

from __future__ import annotations

import dataclasses
import math
import re
import sys
import time
from collections.abc import Callable, Mapping
from dataclasses import dataclass, field
from typing import TYPE_CHECKING, Any

from cnt_env import units
from cnt_env.io import package_version
from cnt_env.presets import (
    DEFAULT_KAPPA_C,
    FLOW_PROFILES,
    INITIAL_RADIUS,
    MESH,
    MODEL,
    RUN_DEPOSIT,
    RUN_TRANSIENT,
    graded_coarse,
)

if TYPE_CHECKING:
    import numpy as np

    from cnt_env.patterns import MeasureOptions
    from cnt_env.sim.deposition import DepositionConfig, DepositionSim

__all__ = [
    "GROUP_FIELDS",
    "SI_FIELDS",
    "Limits",
    "RunInputError",
    "RunLimitError",
    "RunOptions",
    "RunResult",
    "RunSpec",
    "apply_substrate",
    "deposit",
    "measure",
    "resolve",
    "resolve_params",
    "resolve_run",
    "result_dict",
    "simulate",
]

# Choices mirrored from forces.DRAG_LAWS, deposition.CONTACT_MODES and
# substrate.SLIDING_OPTIONS, so that validation does not import numba. The simulator
# validates them again when it is built.
DRAG_LAWS = ("linear", "printed")
CONTACT_MODES = ("event", "project")
ADHESION_MODELS = ("eq1", "cohesive")  # forces.ADHESION_MODELS
SLIDING_OPTIONS = ("B", "C", "none")
SUBSTRATES = ("flat", "stepped")

# Dimensionless groups settable on the command line: flag name (argparse dest) -> field.
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
# SI values settable on the command line: flag name -> PhysicalParams field.
SI_FIELDS: dict[str, str] = {"kb": "k_b", "ev": "e_v", "rho": "rho", "mu": "mu", "H": "H", "v": "v"}
#: Parameter names in validation messages -> the ``cnt-sim`` flag that sets them.
FLAGS: dict[str, str] = {
    **{f: "--" + dest.replace("_", "-") for dest, f in GROUP_FIELDS.items()},
    **{f: "--" + dest for dest, f in SI_FIELDS.items()},
    "phi": "--phi",
    "transient_length": "--transient",
    "settled_fraction": "--settled-fraction",
    "dt": "--dt",
    "initial_radius": "--initial-radius",
    "coarse_delta": "--coarse-delta",
    "fine_length": "--fine-length",
}
_PARAM_IN_MESSAGE = re.compile(r"\b(?:PhysicalParams|DimensionlessParams|MeasureOptions)\.(\w+)")

#: The model's meaningful range of the groups a user sets (docs/model.md §2): beyond it
#: floating point loses the rod (H̄ so large that y + 1 == y) or the run cannot deposit.
GROUP_RANGE: dict[str, tuple[float, float]] = {
    "Hbar": (0.0, 1e7),
    "Ibar": (0.0, 1e9),
    "vbar": (0.0, 1e6),
    "phi": (-1e6, 1e6),
    "kappa_c_bar": (1e-9, 1e6),
    "delta_bar": (1e-4, 1e6),
}


class RunInputError(ValueError):
    """An input of a run is invalid; the message starts with the flag that sets it."""


class RunLimitError(RuntimeError):
    """A run was stopped by one of its :class:`Limits` (the message names the limit)."""


@dataclass(frozen=True)
class Limits:
    """Named limits of one run; each has a default and a ``cnt-sim run`` flag.

    ``max_nodes``: nodes in the simulation (the start-up rod plus the trace);
    ``max_steps_per_length``: physics steps allowed while less than 1 L_vb is deposited
    (a run that lays nothing stops with a clear error); ``max_wall_time``: seconds of
    wall time (default a day; None: no limit).
    """

    max_nodes: int = 2_000_000
    max_steps_per_length: int = 200_000
    max_wall_time: float | None = 86_400.0

    def __post_init__(self) -> None:
        try:
            units.check_int("--max-nodes", self.max_nodes, low=1)
            units.check_int("--max-steps", self.max_steps_per_length, low=1)
            if self.max_wall_time is not None:
                units.check_number("--max-wall-time", self.max_wall_time, low=0.0,
                                   low_open=True, unit="s")  # fmt: skip
        except units.ParameterError as exc:
            raise RunInputError(str(exc)) from exc


def invalid(exc: Exception) -> RunInputError:
    """A validation error, prefixed with the flag of the parameter it names."""
    message = str(exc)
    match = _PARAM_IN_MESSAGE.search(message)
    name = match.group(1) if match else message.split(" ", 1)[0]
    flag = FLAGS.get(name)
    return RunInputError(f"{flag}: {message}" if flag else message)


def _warn_stderr(message: str) -> None:
    print(f"cnt-sim: warning: {message}", file=sys.stderr)


# --------------------------------------------------------------------------- inputs


def resolve_params(
    preset: str,
    groups: Mapping[str, float | None] | None = None,
    si: Mapping[str, float | None] | None = None,
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
    try:
        params = physical.to_dimensionless()
    except (ZeroDivisionError, OverflowError) as exc:
        given = ", ".join(f"{FLAGS[k]} {v!r}" for k, v in si.items())
        raise units.ParameterError(
            f"the SI values ({given}) give dimensionless groups outside floating point "
            f"({exc}); give values of the paper's orders of magnitude"
        ) from exc
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


def kappa_c_steps_note(preset: str, substrate: str | None, kappa_c_given: bool) -> str | None:
    """The note for ``--kappa-c`` on a flat preset without ``--substrate``: the critical
    curvature turns the steps on (``DimensionlessParams.is_stepped``), which a user who
    meant to tune the coil would not expect; ``--substrate stepped`` says it and silences
    it. None when there is nothing to say."""
    if not kappa_c_given or substrate is not None or units.paper_groups(preset).is_stepped:
        return None
    return (
        f"--kappa-c on the {preset} preset (a flat substrate) turns the steps on: the run is "
        "on the stepped substrate; add --substrate stepped to say so"
    )


def check_group_range(params: units.DimensionlessParams, si: Mapping[str, Any] | None = None
                      ) -> None:  # fmt: skip
    """Reject groups outside :data:`GROUP_RANGE` (the model's meaningful range); ``si``:
    the SI values the groups came from, named in the message (the user typed those)."""
    for name, (lo, hi) in GROUP_RANGE.items():
        value = getattr(params, name)
        if value is not None and not lo <= value <= hi:
            flag = FLAGS.get(name, name)
            given = {k: v for k, v in (si or {}).items() if v is not None}
            source = ("; it follows from the SI values given ("
                      + ", ".join(f"--{k} {v:g}" for k, v in given.items())
                      + "): check their units (--help)") if given else ""  # fmt: skip
            raise RunInputError(
                f"{flag} = {value!r} is outside the model's meaningful range [{lo:g}, {hi:g}] "
                f"(beyond it the simulation loses precision or cannot deposit){source}"
            )


def estimated_nodes(config: DepositionConfig, deposit_length: float) -> float:
    """Nodes a run needs: the start-up rod (arc and vertical part, docs/model.md §4) plus
    the deposited trace at ``delta_bar`` (a float: inf when a huge ``--deposit`` over a
    small delta overflows, which the node limit then refuses)."""
    p = config.params
    coarse = config.coarse_delta or p.delta_bar
    rod = (
        0.5 * math.pi * config.initial_radius / p.delta_bar
        + min(config.fine_length, p.Hbar) / p.delta_bar
        + p.Hbar / coarse
    )
    n = rod + deposit_length / p.delta_bar
    return float(math.floor(n) + 4) if math.isfinite(n) else math.inf


@dataclass(frozen=True)
class RunOptions:
    """The inputs of one run, as ``cnt-sim run`` takes them (None: the preset's default).

    ``groups`` maps DimensionlessParams fields (``Hbar``, ``Ibar``, ``vbar``, ``phi``,
    ``kappa_c_bar``, ``delta_bar``) to values, ``si`` PhysicalParams fields (``k_b``,
    ``e_v``, ``rho``, ``mu``, ``H``, ``v``); ``extra_groups`` sets any other field after
    the mesh is chosen (a sweep's swept groups). ``coarse_delta`` None and ``fine_length``
    None take the preset's graded rod (``presets.MESH``); ``coarse_delta`` 0 is a uniform
    rod at delta_bar.
    """

    preset: str = "coil"
    substrate: str | None = None
    groups: Mapping[str, float | None] = field(default_factory=dict)
    si: Mapping[str, float | None] = field(default_factory=dict)
    extra_groups: Mapping[str, float] = field(default_factory=dict)
    deposit: float | None = None
    seed: int = 0
    transient: float | None = None
    settled_fraction: float | None = None
    dt: float | None = None
    drag_law: str = MODEL["drag_law"]
    sliding: str = MODEL["sliding"]
    friction: float = MODEL["friction"]
    flow_profile: str = MODEL["flow_profile"]
    coarse_delta: float | None = None
    fine_length: float | None = None
    contact_mode: str = "event"
    adhesion: str | None = None  # None: deposition.ContactOptions's default
    cohesive_range: float | None = None
    initial_radius: float | None = None
    limits: Limits = field(default_factory=Limits)


@dataclass(frozen=True)
class RunSpec:
    """A validated run: everything needed before any simulation work."""

    preset: str
    substrate: str
    params: units.DimensionlessParams
    physical: units.PhysicalParams | None
    sim_config: DepositionConfig
    deposit_length: float
    seed: int
    measure_options: MeasureOptions
    limits: Limits = field(default_factory=Limits)

    def config_dict(self) -> dict[str, Any]:
        """The run's configuration apart from the groups (saved and printed as ``config``)."""
        c = self.sim_config
        return {
            "preset": self.preset,
            "substrate": self.substrate,
            "deposit_length": self.deposit_length,
            "dt": c.time_step,
            "dt_factor": None if c.dt is not None else c.dt_factor,
            "dt_hbar_cap": None if c.dt is not None else c.step_hbar_cap,
            "drag_law": c.drag_law,
            "sliding": c.sliding,
            "friction": c.friction,
            "flow_profile": c.flow_profile,
            "coarse_delta": c.coarse_delta,
            "fine_length": c.fine_length,
            "residual_tol": c.newton.residual_tol,
            "contact_mode": c.contact.mode,
            "adhesion": c.contact.adhesion,
            "cohesive_range": c.contact.cohesive_range,
            "seed": self.seed,
            "initial_radius": c.initial_radius,
            "perturbation": c.perturbation,
            "transient_length": self.measure_options.transient_length,
            "settled_fraction": self.measure_options.settled_fraction,
            "si": None if self.physical is None else dataclasses.asdict(self.physical),
        }


def resolve_run(preset: str = "coil", **options: Any) -> RunSpec:
    """Validate a run given as keyword arguments (the fields of :class:`RunOptions`)."""
    try:
        opts = RunOptions(preset=preset, **options)
    except TypeError as exc:
        raise RunInputError(str(exc)) from exc
    return resolve(opts)


def _choice(flag: str, value: Any, choices: tuple[str, ...]) -> None:
    if value not in choices:
        raise RunInputError(f"{flag} must be one of {', '.join(choices)}, got {value!r}")


def resolve(opts: RunOptions, warn: Callable[[str], None] | None = _warn_stderr) -> RunSpec:
    """Validate every input of a run; raises :class:`RunInputError` naming the flag."""
    _choice("--preset", opts.preset, units.PRESETS)
    if opts.substrate is not None:
        _choice("--substrate", opts.substrate, SUBSTRATES)
    _choice("--drag-law", opts.drag_law, DRAG_LAWS)
    _choice("--sliding", opts.sliding, SLIDING_OPTIONS)
    _choice("--flow-profile", opts.flow_profile, FLOW_PROFILES)
    _choice("--contact-mode", opts.contact_mode, CONTACT_MODES)
    contact: dict[str, Any] = {"mode": opts.contact_mode}
    if opts.adhesion is not None:
        _choice("--adhesion", opts.adhesion, ADHESION_MODELS)
        contact["adhesion"] = opts.adhesion
    if opts.cohesive_range is not None:
        try:
            contact["cohesive_range"] = units.check_number(
                "--cohesive-range", opts.cohesive_range, low=0.0, low_open=True,
                unit="(range of the cohesive adhesion in L_vb)")  # fmt: skip
        except units.ParameterError as exc:
            raise RunInputError(str(exc)) from exc
    groups = dict(opts.groups)
    if groups.get("kappa_c_bar") is not None and opts.substrate == "flat":
        raise RunInputError(
            "--kappa-c sets the critical curvature of a stepped substrate: it has no "
            "meaning with --substrate flat; drop one of them"
        )
    try:
        params, physical, ignored = resolve_params(opts.preset, groups, opts.si)
    except units.ParameterError as exc:
        raise invalid(exc) from exc
    if ignored and warn is not None:
        flags = ", ".join(FLAGS[k] for k in ignored)
        warn(f"SI values given, so {flags} {'is' if len(ignored) == 1 else 'are'} ignored")
    try:
        params = apply_substrate(params, opts.substrate)
    except units.ParameterError as exc:
        raise invalid(exc) from exc

    length = RUN_DEPOSIT[opts.preset] if opts.deposit is None else opts.deposit
    try:
        length = units.check_number("--deposit", length, low=0.0, low_open=True,
                                    unit="(trace length in L_vb)")  # fmt: skip
        units.check_int("--seed", opts.seed, low=0)
        friction = units.check_number(
            "--friction", opts.friction, low=0.0, unit="(friction per unit length, in mu)"
        )
    except units.ParameterError as exc:
        raise RunInputError(str(exc)) from exc
    if friction != 0.0 and not params.is_stepped:
        raise RunInputError(
            "--friction resists the sliding of deposited nodes along the steps: the flat "
            "sticky substrate holds them fixed, so it has no meaning there; drop it or use "
            "a stepped substrate"
        )
    transient = RUN_TRANSIENT[opts.preset] if opts.transient is None else opts.transient
    measure_options = measure_options_for(transient, opts.settled_fraction)

    from cnt_env.sim.deposition import ContactOptions, DepositionConfig

    mesh = MESH[opts.preset]
    try:
        if groups.get("delta_bar") is None:  # the preset's validated mesh
            params = dataclasses.replace(params, delta_bar=mesh["delta_bar"])
        radius = opts.initial_radius
        if radius is None:
            radius = INITIAL_RADIUS["stepped" if params.is_stepped else "flat"]
        if opts.extra_groups:
            params = dataclasses.replace(params, **opts.extra_groups)
    except (ValueError, TypeError) as exc:
        raise invalid(exc) from exc
    # before the graded mesh (coarse / delta) and the config's node-count guard, to name
    # the flag (a denormal --delta once overflowed there)
    check_group_range(params, opts.si)
    if physical is not None and warn is not None:
        # the preset's SI values round the paper's groups: say what the run now uses
        ref = units.paper_groups(opts.preset)
        pairs = [(g, getattr(params, g), getattr(ref, g)) for g in ("Hbar", "Ibar", "vbar")]
        moved = [f"{g} {a:.4g} (preset {b:.4g})" for g, a, b in pairs
                 if not math.isclose(a, b, rel_tol=1e-6)]  # fmt: skip
        if moved:
            warn(
                "SI values given: the groups follow from them and the preset's other SI "
                "values: " + ", ".join(moved)
            )
    coarse = opts.coarse_delta  # None: the preset's graded rod; 0: uniform
    if coarse is None:
        coarse = graded_coarse(mesh["coarse_delta"], params.delta_bar)
    elif coarse == 0:
        coarse = None
    try:
        sim_config = DepositionConfig(
            params=params, dt=opts.dt, drag_law=opts.drag_law,
            contact=ContactOptions(**contact), initial_radius=radius,
            sliding=opts.sliding, friction=friction, flow_profile=opts.flow_profile,
            coarse_delta=coarse,
            fine_length=mesh["fine_length"] if opts.fine_length is None else opts.fine_length,
        )  # fmt: skip
    except (ValueError, TypeError) as exc:
        raise invalid(exc) from exc
    n_nodes = estimated_nodes(sim_config, float(length))
    if n_nodes > opts.limits.max_nodes:
        raise RunInputError(
            f"--max-nodes: this run needs about {n_nodes:.3g} nodes (Hbar / delta plus "
            f"deposit / delta), over the limit of {opts.limits.max_nodes}; lower --Hbar or "
            "--deposit, coarsen --delta, or raise --max-nodes"
        )
    note = kappa_c_steps_note(opts.preset, opts.substrate, groups.get("kappa_c_bar") is not None)
    if note is not None and warn is not None:  # once the run is known to be valid
        warn(note)
    return RunSpec(
        preset=opts.preset,
        substrate="stepped" if params.is_stepped else "flat",
        params=params,
        physical=physical,
        sim_config=sim_config,
        deposit_length=float(length),
        seed=int(opts.seed),
        measure_options=measure_options,
        limits=opts.limits,
    )


def measure_options_for(
    transient: float | None, settled_fraction: float | None = None
) -> MeasureOptions:
    """Measurement options with ``transient`` L_vb dropped and the classes judged on the
    last ``settled_fraction`` of the U-turns (None: the defaults)."""
    from cnt_env.patterns import MeasureOptions

    given = {"transient_length": transient, "settled_fraction": settled_fraction}
    try:
        return MeasureOptions(**{k: v for k, v in given.items() if v is not None})
    except ValueError as exc:
        raise invalid(exc) from exc


# --------------------------------------------------------------------------- work

ProgressCallback = Callable[[float, float], None]


def guarded_progress(limits: Limits, progress: ProgressCallback | None = None) -> ProgressCallback:
    """A ``progress(done, total)`` callback that enforces ``limits`` (called after every
    step) and then calls ``progress``; raises :class:`RunLimitError`."""
    start = time.monotonic()
    state = {"mark": 0.0, "steps": 0, "calls": 0}

    def check(done: float, total: float) -> None:
        state["steps"] += 1
        state["calls"] += 1
        if done >= state["mark"] + 1.0 or done >= total:
            state["mark"], state["steps"] = done, 0
        elif state["steps"] > limits.max_steps_per_length:
            raise RunLimitError(
                f"--max-steps: {limits.max_steps_per_length} physics steps laid less than "
                f"1 L_vb of trace (deposited {done:.1f} of {total:g} L_vb): the run makes no "
                "progress with these parameters (e.g. a very large --Ibar); change them or "
                "raise --max-steps"
            )
        if limits.max_wall_time is not None and state["calls"] % 16 == 0:
            if time.monotonic() - start > limits.max_wall_time:
                raise RunLimitError(
                    f"--max-wall-time: the run took over {limits.max_wall_time:g} s "
                    f"(deposited {done:.1f} of {total:g} L_vb); raise --max-wall-time"
                )
        if progress is not None:
            progress(done, total)

    return check


def deposit(
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


def measure(
    trace: Any, options: MeasureOptions, substrate: str, phi: float = 0.0
) -> dict[str, Any]:
    """``patterns.measure`` of a trace; a trace too short to measure gives
    ``pattern`` None and the reason in ``error`` instead of raising."""
    from cnt_env.patterns import measure as measure_pattern

    try:
        return measure_pattern(
            trace, options, substrate, flow_direction=(math.cos(phi), math.sin(phi))
        )
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


@dataclass
class RunResult:
    """A finished run: its spec, trace ((n, 3)), suspended rod ((m, 3)), solver stats and
    measurement; :meth:`report` is the ``--json`` object."""

    spec: RunSpec
    trace: np.ndarray
    suspended: np.ndarray
    stats: dict[str, Any]
    measurement: dict[str, Any]

    def report(self) -> dict[str, Any]:
        return result_dict(
            self.measurement, self.stats, self.spec.params.as_dict(), self.spec.config_dict()
        )


def simulate(
    spec: RunSpec,
    progress: ProgressCallback | None = None,
    *,
    runner: Callable[..., tuple[DepositionSim, dict[str, Any]]] | None = None,
) -> RunResult:
    """Run ``spec`` under its limits and measure the trace. ``runner(config, length, seed,
    progress)`` replaces :func:`deposit` (e.g. a run recorded for rerun). Raises
    ``SimulationError`` when the solver fails, :class:`RunLimitError` at a limit."""
    guard = guarded_progress(spec.limits, progress)
    sim, stats = (runner or deposit)(spec.sim_config, spec.deposit_length, spec.seed, guard)
    trace, suspended = sim.trace(), sim.suspended_nodes.copy()
    measurement = measure(trace, spec.measure_options, spec.substrate, spec.params.phi)
    return RunResult(spec, trace, suspended, stats, measurement)

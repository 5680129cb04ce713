"""``cnt_env.runs``: one run as a typed library (no argparse), its defaults from
``cnt_env.presets`` only, its validation naming the flag, and its limits."""

from __future__ import annotations

import dataclasses
import math

import numpy as np
import pytest

from cnt_env import presets, runs, units


def test_resolve_run_takes_typed_keywords_and_uses_the_presets() -> None:
    spec = runs.resolve_run("serpentine", groups={"vbar": 0.05}, seed=3, deposit=10.0)
    assert spec.preset == "serpentine" and spec.substrate == "stepped" and spec.seed == 3
    assert spec.params.vbar == 0.05 and spec.deposit_length == 10.0
    mesh = presets.MESH["serpentine"]
    assert spec.params.delta_bar == mesh["delta_bar"]
    assert spec.sim_config.coarse_delta == mesh["coarse_delta"]
    assert spec.sim_config.initial_radius == presets.INITIAL_RADIUS["stepped"]
    assert spec.measure_options.transient_length == presets.RUN_TRANSIENT["serpentine"]
    default = runs.resolve_run()
    assert default.deposit_length == presets.RUN_DEPOSIT["coil"]
    assert default.params.delta_bar == presets.MESH["coil"]["delta_bar"]
    stepped = runs.resolve_run(substrate="stepped")
    assert stepped.params.kappa_c_bar == presets.DEFAULT_KAPPA_C
    with pytest.raises(runs.RunInputError):
        runs.resolve_run(nonsense=1)


def test_run_options_is_frozen_and_resolve_matches_resolve_run() -> None:
    opts = runs.RunOptions(preset="coil", groups={"Hbar": 40.0}, deposit=5.0)
    with pytest.raises(dataclasses.FrozenInstanceError):
        opts.seed = 2  # type: ignore[misc]
    assert runs.resolve(opts) == runs.resolve_run("coil", groups={"Hbar": 40.0}, deposit=5.0)


def test_kappa_c_on_the_coil_preset_says_it_turns_the_steps_on() -> None:
    """--kappa-c makes a flat preset stepped (is_stepped): said once, unless --substrate
    stepped already says it or the preset is stepped."""
    notes: list[str] = []
    spec = runs.resolve(runs.RunOptions(groups={"kappa_c_bar": 0.1}), warn=notes.append)
    assert spec.substrate == "stepped" and spec.params.kappa_c_bar == 0.1
    assert len(notes) == 1 and "--kappa-c" in notes[0] and "--substrate stepped" in notes[0]
    for quiet in (
        runs.RunOptions(groups={"kappa_c_bar": 0.1}, substrate="stepped"),
        runs.RunOptions(preset="serpentine", groups={"kappa_c_bar": 0.1}),
        runs.RunOptions(),
    ):
        notes.clear()
        runs.resolve(quiet, warn=notes.append)
        assert notes == []


@pytest.mark.parametrize(
    ("kwargs", "flag"),
    [
        ({"groups": {"Hbar": float("nan")}}, "--Hbar"),
        ({"groups": {"Hbar": 1e300}}, "--Hbar"),
        ({"groups": {"Ibar": 1e300}}, "--Ibar"),
        ({"groups": {"kappa_c_bar": 0.0}}, "--kappa-c"),
        ({"groups": {"kappa_c_bar": 0.2}, "substrate": "flat"}, "--kappa-c"),
        ({"groups": {"delta_bar": 1e-9}}, "--delta"),
        ({"deposit": -1.0}, "--deposit"),
        ({"deposit": 1e12}, "--max-nodes"),
        ({"seed": -1}, "--seed"),
        ({"seed": True}, "--seed"),
        ({"drag_law": "x"}, "--drag-law"),
        ({"sliding": "A"}, "--sliding"),
        ({"preset": "serpentine", "friction": -1.0}, "--friction"),
        ({"preset": "serpentine", "friction": float("inf")}, "--friction"),
        ({"friction": 1.0}, "--friction"),  # the coil preset's flat sticky substrate
        ({"preset": "x"}, "--preset"),
        ({"transient": -5.0}, "--transient"),
        ({"flow_profile": "parabolic"}, "--flow-profile"),
    ],
)
def test_invalid_input_names_the_flag(kwargs: dict, flag: str) -> None:
    opts = runs.RunOptions(**kwargs)
    with pytest.raises(runs.RunInputError) as info:
        runs.resolve(opts, warn=None)
    assert flag in str(info.value)


def test_limits_are_validated_and_named() -> None:
    for kwargs, flag in [
        ({"max_nodes": 0}, "--max-nodes"),
        ({"max_steps_per_length": 1.5}, "--max-steps"),
        ({"max_wall_time": float("inf")}, "--max-wall-time"),
        ({"max_wall_time": 0.0}, "--max-wall-time"),
    ]:
        with pytest.raises(runs.RunInputError, match=flag):
            runs.Limits(**kwargs)


def test_progress_guard_stops_a_run_without_progress() -> None:
    guard = runs.guarded_progress(runs.Limits(max_steps_per_length=5))
    for _ in range(5):
        guard(0.5, 10.0)
    with pytest.raises(runs.RunLimitError, match="--max-steps"):
        guard(0.6, 10.0)
    guard = runs.guarded_progress(runs.Limits(max_steps_per_length=5))
    for i in range(50):  # 1 L_vb every 4 steps: progress, never stopped
        guard(i / 4.0, 100.0)


def test_simulate_runs_the_spec_under_its_limits_and_measures() -> None:
    spec = runs.resolve_run("coil", groups={"Hbar": 40.0, "delta_bar": 1.0}, deposit=5.0,
                            transient=0.0)  # fmt: skip
    seen = {}

    class Sim:
        suspended_nodes = np.zeros((3, 3))

        def trace(self) -> np.ndarray:
            return np.column_stack([np.arange(6.0), np.zeros(6), np.zeros(6)])

    def runner(config, length, seed, progress):
        seen.update(config=config, length=length, seed=seed)
        progress(length, length)
        return Sim(), {"deposited_length": length, "steps": 1}

    result = runs.simulate(spec, runner=runner)
    assert seen == {"config": spec.sim_config, "length": 5.0, "seed": 0}
    report = result.report()
    assert report["deposited_length"] == 5.0 and report["config"]["preset"] == "coil"
    assert report["params"] == spec.params.as_dict()
    # a 5 L_vb straight trace: measured, and reported as too short to classify
    assert "error" not in result.measurement
    assert result.measurement["pattern"] == "too_short"


def test_estimated_nodes_counts_rod_and_trace() -> None:
    graded = runs.resolve_run("serpentine", deposit=100.0)  # the preset's graded rod
    uniform = runs.resolve_run("serpentine", deposit=100.0, coarse_delta=0.0)
    assert uniform.sim_config.coarse_delta is None and graded.sim_config.coarse_delta == 4.0
    H, d = graded.params.Hbar, graded.params.delta_bar
    assert d == uniform.params.delta_bar
    # the start-up quarter arc (R_i = 3.9), the fine 20 L_vb, the rest of Hbar, the trace
    assert runs.estimated_nodes(uniform.sim_config, 100.0) == int(
        0.5 * math.pi * 3.9 / d + 20 / d + H / d + 100 / d) + 4  # fmt: skip
    assert runs.estimated_nodes(graded.sim_config, 100.0) == int(
        0.5 * math.pi * 3.9 / d + 20 / d + H / 4 + 100 / d) + 4  # fmt: skip


def test_graded_mesh_follows_delta_and_zero_means_uniform() -> None:
    """The preset's coarse edge (4 L_vb) is snapped to a whole multiple of delta_bar and
    dropped when under 2 delta_bar; an explicit coarse_delta is kept as given."""
    for delta, coarse in ((1.0, 4.0), (0.5, 4.0), (1.5, 4.5), (0.3, 3.9)):
        spec = runs.resolve_run("serpentine", groups={"delta_bar": delta}, deposit=10.0)
        assert spec.sim_config.coarse_delta == (None if coarse is None else pytest.approx(coarse))
        assert presets.graded_coarse(4.0, delta) == spec.sim_config.coarse_delta
    assert presets.graded_coarse(4.0, 2.5) == 5.0 and presets.graded_coarse(4.0, 3.0) is None
    assert runs.resolve_run("coil", coarse_delta=2.0).sim_config.coarse_delta == 2.0
    assert runs.resolve_run("coil", fine_length=10.0).sim_config.fine_length == 10.0
    with pytest.raises(runs.RunInputError, match="coarse_delta"):
        runs.resolve_run("coil", coarse_delta=1.5)


def test_check_number_is_the_one_validator() -> None:
    assert units.check_number("--x", 2, low=0.0, low_open=True) == 2.0
    for bad in (0.0, float("nan"), "1", True):
        with pytest.raises(units.ParameterError, match=r"^--x"):
            units.check_number("--x", bad, low=0.0, low_open=True)
    with pytest.raises(units.ParameterError, match=r"^--n"):
        units.check_int("--n", -1)


def test_wall_time_is_checked_while_the_run_progresses() -> None:
    guard = runs.guarded_progress(runs.Limits(max_wall_time=1e-9))
    with pytest.raises(runs.RunLimitError, match="--max-wall-time"):
        for i in range(64):  # 1 L_vb per step: always progressing
            guard(float(i + 1), 1000.0)


def test_validation_choices_mirror_the_simulators() -> None:
    """runs.py keeps numba-free copies of the simulator's choices for the CLI; they must
    name exactly what the simulator accepts (``--sliding none`` was refused once)."""
    from cnt_env.sim import deposition, forces, substrate

    assert set(runs.DRAG_LAWS) == set(forces.DRAG_LAWS)
    assert set(runs.ADHESION_MODELS) == set(forces.ADHESION_MODELS)
    assert set(runs.CONTACT_MODES) == set(deposition.CONTACT_MODES)
    assert set(runs.SLIDING_OPTIONS) == set(substrate.SLIDING_OPTIONS)


def test_friction_reaches_the_simulator_and_its_record() -> None:
    """--friction is DepositionConfig.friction, recorded in the run's config; at its
    default it leaves a sweep's hash as before the option existed, so old sweeps resume."""
    from cnt_env.sweep import grid

    base = runs.RunOptions(preset="serpentine", deposit=5.0)
    rough = dataclasses.replace(base, friction=2.5)
    spec, rough_spec = runs.resolve(base), runs.resolve(rough)
    assert spec.sim_config.friction == 0.0 and rough_spec.sim_config.friction == 2.5
    assert rough_spec.config_dict()["friction"] == 2.5
    without = {k: v for k, v in spec.config_dict().items() if k != "friction"}
    assert without == {k: v for k, v in rough_spec.config_dict().items() if k != "friction"}
    assert grid.sweep_hash(spec, ["vbar"], base) != grid.sweep_hash(rough_spec, ["vbar"], rough)


def test_the_flow_profile_reaches_the_drag_and_its_record() -> None:
    """--flow-profile linear is DepositionConfig.flow_profile, a drag shear of 1/Hbar
    (the set flow at the rod's top), recorded in the run's config; the default is the
    paper's uniform flow and keeps a sweep's hash."""
    from cnt_env.sim.deposition import DepositionSim
    from cnt_env.sweep import grid

    base = runs.RunOptions(preset="serpentine", deposit=5.0, groups={"Hbar": 40.0})
    layer = dataclasses.replace(base, flow_profile="linear")
    spec, layer_spec = runs.resolve(base), runs.resolve(layer)
    assert spec.config_dict()["flow_profile"] == "uniform"
    assert layer_spec.config_dict()["flow_profile"] == "linear"
    assert DepositionSim(spec.sim_config).rod.drag.shear == 0.0
    assert DepositionSim(layer_spec.sim_config).rod.drag.shear == pytest.approx(1.0 / 40.0)
    assert grid.LATER_CONFIG_FIELDS["flow_profile"] == spec.sim_config.flow_profile
    assert grid.sweep_hash(spec, ["vbar"], base) != grid.sweep_hash(layer_spec, ["vbar"], layer)


def test_the_settled_fraction_reaches_the_measure_and_its_record() -> None:
    """--settled-fraction is MeasureOptions.settled_fraction, recorded in the run's
    config; a sweep at the default keeps its hash (an old sweep resumes), another one is
    a different sweep."""
    from cnt_env.patterns import MeasureOptions
    from cnt_env.sweep import grid

    base = runs.RunOptions(preset="serpentine", deposit=5.0)
    whole = dataclasses.replace(base, settled_fraction=1.0)
    spec, whole_spec = runs.resolve(base), runs.resolve(whole)
    default = MeasureOptions.settled_fraction
    assert spec.measure_options.settled_fraction == default
    assert spec.config_dict()["settled_fraction"] == default
    assert whole_spec.config_dict()["settled_fraction"] == 1.0
    assert grid.LATER_CONFIG_FIELDS["settled_fraction"] == default
    assert grid.sweep_hash(spec, ["vbar"], base) != grid.sweep_hash(whole_spec, ["vbar"], whole)
    with pytest.raises(runs.RunInputError, match=r"^--settled-fraction"):
        runs.resolve(dataclasses.replace(base, settled_fraction=0.0))


def test_a_committed_sweep_keeps_its_hash() -> None:
    """The sweep recorded in benchmarks/results/kappa_phase resolves today to the hash in
    its rows, so ``cnt-sim sweep`` resumes it: an option added to the run config since
    (such as --friction) must leave the hash of runs that do not use it unchanged."""
    import json
    from pathlib import Path

    from cnt_env.cli import app
    from cnt_env.cli.sweep import sweep_options
    from cnt_env.sweep import grid

    record = Path(__file__).parents[1] / "benchmarks/results/kappa_phase/sweep.csv.json"
    saved = json.loads(record.read_text())
    plan = grid.resolve_sweep(sweep_options(app.build_parser().parse_args(saved["argv"])))
    assert plan.config_hash == saved["config_hash"]

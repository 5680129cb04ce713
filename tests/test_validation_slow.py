"""Paper-scale physics validations (docs/model.md §6). Slow: minutes each, so they run with
``make test-all`` (``pytest -m slow``), not in CI. The full convergence studies, with
their recorded numbers, are ``benchmarks/validation.py`` (benchmarks/RESULTS.md)."""

from __future__ import annotations

import pytest

from cnt_env.patterns import MeasureOptions, measure
from cnt_env.presets import RUN_DEPOSIT, RUN_TRANSIENT
from cnt_env.sim.deposition import DepositionSim, default_config

pytestmark = pytest.mark.slow


def test_coil_baseline_radius_within_3_percent_of_the_paper() -> None:
    """Default coil configuration (presets.MODEL and MESH), as ``cnt-sim run`` measures it
    (presets.RUN_DEPOSIT and RUN_TRANSIENT: 1500 L_vb, 900 dropped): R0 within 3% of
    7.64 L_vb, issue 12's goal (7.48 measured, benchmarks/RESULTS.md, issue 12)."""
    sim = DepositionSim(default_config("coil"), seed=0)
    sim.run(RUN_DEPOSIT["coil"])
    m = measure(sim.trace(), MeasureOptions(transient_length=RUN_TRANSIENT["coil"]))
    assert m["pattern"] == "coil"
    assert m["coil_radius"] == pytest.approx(7.64, rel=0.03)
    # physical sanity: the vdW pull releases e_v per deposited length
    assert sim.vdw_work / sim.deposited_length == pytest.approx(1.0, abs=0.01)


@pytest.fixture(scope="module")
def serpentine_baseline() -> dict:
    sim = DepositionSim(default_config("serpentine"), seed=0)
    sim.run(1500.0)
    return measure(sim.trace(), MeasureOptions(transient_length=150.0), substrate="stepped")


def test_serpentine_baseline_keeps_its_recorded_figures(serpentine_baseline: dict) -> None:
    """The shipped model's serpentine baseline as recorded (1500 L_vb, seed 0: A 33.62,
    lambda_x 10.20, benchmarks/results/reproduce_C_fine; regular but under the 10 cycles
    that call a trace periodic; the surrogate, printed drag at delta_bar 1, gives 41.27 /
    8.77): a change of the model's physics or defaults shows here first."""
    m = serpentine_baseline
    assert m["pattern"] in ("too_short", "periodic-serpentine")
    assert m["amplitude_cv"] < 0.1 and m["wavelength_cv"] < 0.1
    assert m["amplitude"] == pytest.approx(33.62, rel=0.01)
    assert m["wavelength"] == pytest.approx(10.20, rel=0.01)


def test_serpentine_wavelength_is_the_drift_of_one_cycle() -> None:
    """Kinematics of a serpentine across the steps: one cycle lays ~4 A of trace in
    4 A / V while the pattern drifts with the flow, so lambda = 4 A vbar / V (V: the
    deposition speed after the transient, times Hbar). Over 24 runs (both drag laws, delta
    0.2-1, vbar 0.019-0.12, kappa_c 0.1-0.2) the ratio is 1.03 +- 0.05, 0.96-1.13
    (benchmarks/validation.py serpentine, RESULTS.md issue 12, "The delta study"): the
    wavelength is set by the amplitude and the deposition speed."""
    sim = DepositionSim(default_config("serpentine"), seed=0)
    sim.run(150.0)
    mid = sim.stats()
    sim.run(1350.0)
    end = sim.stats()
    m = measure(sim.trace(), MeasureOptions(transient_length=150.0), substrate="stepped")
    v_dep = (end["deposited_length"] - mid["deposited_length"]) / (end["time"] - mid["time"])
    ratio = m["wavelength"] * v_dep * sim.params.Hbar / (4.0 * m["amplitude"] * sim.params.vbar)
    assert ratio == pytest.approx(1.0, abs=0.1)


@pytest.mark.xfail(strict=True, reason="the shipped model's baseline is A 33.6 and "
                   "lambda 10.2, over the paper's 26-33 and 6-8 (RESULTS.md issue 12)")  # fmt: skip
def test_serpentine_baseline_amplitude_and_wavelength(serpentine_baseline: dict) -> None:
    """The paper's serpentine baseline (Hbar 155, Ibar 300, kappa_c 0.2, vbar 0.037):
    periodic serpentines with amplitude in 26-33 and wavelength in 6-8 L_vb. A known miss
    (strict xfail: it reports when the model comes to meet it)."""
    m = serpentine_baseline
    assert m["pattern"] == "periodic-serpentine"
    assert 26.0 <= m["amplitude"] <= 33.0
    assert 6.0 <= m["wavelength"] <= 8.0

"""Paper-scale physics validations (docs/model.md §6). Slow: minutes each, so they run with
``make test-all`` (``pytest -m slow``), not in CI. The full convergence studies, with
their recorded numbers, are ``benchmarks/validation.py`` (benchmarks/RESULTS.md)."""

from __future__ import annotations

import pytest

from cnt_env.patterns import MeasureOptions, measure
from cnt_env.sim.deposition import DepositionSim, default_config

pytestmark = pytest.mark.slow


def test_coil_baseline_radius_within_5_percent_of_the_paper() -> None:
    """Default coil configuration (delta = 0.125 graded): R0 within 5% of 7.64 L_vb."""
    sim = DepositionSim(default_config("coil"), seed=0)
    sim.run(700.0)
    m = measure(sim.trace(), MeasureOptions(transient_length=300.0))
    assert m["pattern"] == "coil"
    assert m["coil_radius"] == pytest.approx(7.64, rel=0.05)
    # physical sanity: the vdW pull releases e_v per deposited length
    assert sim.vdw_work / sim.deposited_length == pytest.approx(1.0, abs=0.01)


def test_serpentine_baseline_amplitude_and_wavelength() -> None:
    """Serpentine baseline (Hbar 155, Ibar 300, kappa_c 0.2, vbar 0.037): periodic
    serpentines with amplitude in 26-33 and wavelength in 6-8 L_vb."""
    sim = DepositionSim(default_config("serpentine"), seed=0)
    sim.run(1500.0)
    m = measure(sim.trace(), MeasureOptions(transient_length=150.0), substrate="stepped")
    assert m["pattern"] == "periodic-serpentine"
    assert 26.0 <= m["amplitude"] <= 33.0
    assert 6.0 <= m["wavelength"] <= 8.0

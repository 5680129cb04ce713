"""benchmarks/flow_noise.py: its AR(1) flow fluctuation against the closed forms, and a
zero fluctuation that leaves the table's run bit for bit."""

from __future__ import annotations

import math

import numpy as np
import pytest

from benchmarks import flow_noise, reproduce  # the repo root is on pytest's pythonpath

N_SAMPLES = 200_000
N_SE = 5.0  # tolerances: this many standard errors of the estimate (closed forms below)


@pytest.mark.parametrize("corr", [5.0, 20.0])
def test_ar1_is_stationary_with_unit_variance_and_exponential_correlation(corr) -> None:
    """Var x = 1 and corr(x_k, x_{k+m}) = a^m = exp(-m every / corr), the discrete OU
    process. Standard errors of an AR(1) of N samples: the mean sqrt((1+a)/((1-a)N)), the
    variance sqrt(2(1+a^2)/((1-a^2)N)), the lag-m correlation <= that of the variance."""
    every = 2.0
    a = math.exp(-every / corr)
    se_mean = math.sqrt((1 + a) / ((1 - a) * N_SAMPLES))
    se_var = math.sqrt(2 * (1 + a * a) / ((1 - a * a) * N_SAMPLES))
    x = flow_noise.ar1(np.random.default_rng(3), N_SAMPLES, every, corr)
    assert np.mean(x) == pytest.approx(0.0, abs=N_SE * se_mean)
    assert np.var(x) == pytest.approx(1.0, abs=N_SE * se_var)
    for m in (1, 5):
        rho = np.corrcoef(x[:-m], x[m:])[0, 1]
        assert rho == pytest.approx(a**m, abs=N_SE * se_var)


def test_ar1_is_seeded_and_rejects_bad_scales() -> None:
    a = flow_noise.ar1(np.random.default_rng(7), 50, 2.0, 20.0)
    b = flow_noise.ar1(np.random.default_rng(7), 50, 2.0, 20.0)
    np.testing.assert_array_equal(a, b)
    with pytest.raises(ValueError, match="must be > 0"):
        flow_noise.ar1(np.random.default_rng(0), 5, 2.0, 0.0)


def test_no_fluctuation_lays_the_tables_point_bit_for_bit() -> None:
    """Refreshing the flow every EVERY L_vb at sigma 0 stops and resumes the run between
    steps and nothing else: the trace is the table's (reproduce.py's point) exactly, so a
    fluctuation's effect is measured against the committed table."""
    from cnt_env.sim.deposition import DepositionSim

    deposit = 30.0
    cfg = reproduce.point_config(reproduce._point("vbar", reproduce.SERP, vbar=0.037),
                                 "default", None)  # fmt: skip
    plain = DepositionSim(cfg, seed=0)
    plain.run(deposit)
    rec = flow_noise.run_point(0.037, 0.0, 20.0, 0, deposit)
    assert rec["error"] is None
    assert rec["deposition_speed"] == plain.deposited_length / plain.time * cfg.params.Hbar
    noisy = flow_noise.run_point(0.037, 0.15, 20.0, 0, deposit)
    assert noisy["deposition_speed"] != rec["deposition_speed"]

"""Stepped-substrate options (docs/model.md §5): the substrate friction and snap penalty
(forces.add_substrate, finite-difference checked), the snap variants, and bad input."""

from __future__ import annotations

import numpy as np
import pytest

from cnt_env.rod.banded import KL, KU, LDAB
from cnt_env.sim.deposition import DepositionConfig, DepositionSim
from cnt_env.sim.forces import add_substrate
from cnt_env.sim.substrate import SNAP_OPTIONS, Stepped
from cnt_env.units import paper_groups

H_FD = 1e-7


def _force_and_jac(q, q_old, dt, fr, st, an):
    n = q.size
    f = np.zeros(n)
    ab = np.zeros((LDAB, n))
    add_substrate(q, q_old, dt, n, fr, st, an, f, ab, True)
    dense = np.zeros((n, n))
    for i in range(n):
        for j in range(max(0, i - KL), min(n, i + KU + 1)):
            dense[i, j] = ab[KL + KU + i - j, j]
    return f, dense


@pytest.mark.parametrize("seed", range(3))
def test_substrate_terms_jacobian_matches_finite_differences(seed: int) -> None:
    rng = np.random.default_rng(seed)
    n = 23
    q = rng.normal(size=n)
    q_old = q - 0.05 * rng.normal(size=n)
    fr = np.where(rng.random(n) < 0.5, rng.random(n) * 3.0, 0.0)
    st = np.where(rng.random(n) < 0.5, rng.random(n) * 1e3, 0.0)
    an = rng.normal(size=n)
    dt = 0.07
    f, jac = _force_and_jac(q, q_old, dt, fr, st, an)
    cols = []
    for k in range(n):
        qp, qm = q.copy(), q.copy()
        qp[k] += H_FD
        qm[k] -= H_FD
        cols.append(
            (
                _force_and_jac(qp, q_old, dt, fr, st, an)[0]
                - _force_and_jac(qm, q_old, dt, fr, st, an)[0]
            )
            / (2 * H_FD)
        )
    fd = np.array(cols).T
    assert np.max(np.abs(jac + fd)) < 1e-6 * np.max(np.abs(jac))  # band holds -dF/dq
    # the forces themselves: friction opposes the velocity, the spring pulls to the anchor
    np.testing.assert_allclose(f, -fr * (q - q_old) / dt - st * (q - an), rtol=1e-12)


def test_zero_coefficients_add_nothing() -> None:
    q = np.arange(7.0)
    f, jac = _force_and_jac(q, q - 1.0, 0.1, np.zeros(7), np.zeros(7), np.ones(7))
    assert not f.any() and not jac.any()


@pytest.mark.parametrize(
    ("field", "value"),
    [("friction", -1.0), ("friction", float("nan")), ("snap", "teleport"),
     ("snap_stiffness", 0.0), ("sliding", "D"), ("snap_length", 0.0),
     ("snap_length", float("inf"))],
)  # fmt: skip
def test_bad_options_raise_naming_the_parameter(field: str, value) -> None:
    with pytest.raises(ValueError, match=field):
        Stepped(kappa_c=0.2, **{field: value})
    params = paper_groups("serpentine", Hbar=30.0, Ibar=100.0)
    with pytest.raises(ValueError, match=field):
        DepositionConfig(params=params, initial_radius=3.9, **{field: value})


def _small(**kw) -> DepositionSim:
    params = paper_groups("serpentine", Hbar=30.0, Ibar=100.0, vbar=0.05)
    return DepositionSim(DepositionConfig(params=params, initial_radius=3.9, **kw), seed=2)


@pytest.mark.parametrize("snap", SNAP_OPTIONS)
def test_snap_variants_run_and_snap(snap: str) -> None:
    sim = _small(snap=snap, friction=1.0, tail_length=30.0)
    sim.run(25.0)
    assert sim.snaps > 0
    trace = sim.trace()
    np.testing.assert_array_equal(trace[:, 1], 0.0)
    gaps = np.linalg.norm(np.diff(trace, axis=0), axis=1)
    np.testing.assert_allclose(gaps, 1.0, rtol=5e-2)
    if snap == "penalty":  # snapped nodes are held by the spring, not by a fixed x
        assert np.any(sim.rod.sub_stiffness[: 4 * sim.n_deposited : 4] > 0)


def test_friction_changes_the_trace_and_is_deterministic() -> None:
    a, b, c = _small(friction=5.0), _small(friction=5.0), _small()
    for s in (a, b, c):
        s.run(20.0)
    np.testing.assert_array_equal(a.trace(), b.trace())
    n = min(len(a.trace()), len(c.trace()))
    assert not np.array_equal(a.trace()[:n], c.trace()[:n])
    # friction is set on the sliding (z) DOF of deposited nodes only
    k = 4 * np.arange(1, a.n_deposited)
    assert np.all(a.rod.sub_friction[k + 2] > 0)
    assert not a.rod.sub_friction[4 * a.n_deposited + 4 :].any()


@pytest.mark.parametrize(("clamp", "z_fixed"), [("xyz", 1), ("xy", 0)])
def test_tail_clamp(clamp: str, z_fixed: int) -> None:
    """The oldest retained node is clamped in x, y and, unless tail_clamp is "xy", z."""
    sim = _small(tail_clamp=clamp, tail_length=8.0)
    sim.run(20.0)
    assert sim.n_trace > sim.n_deposited  # the far tail has left the solve
    assert sim.rod.fixed[0] == 1 and sim.rod.fixed[1] == 1
    assert sim.rod.fixed[2] == z_fixed


def test_no_sliding_fixes_deposited_nodes() -> None:
    sim = _small(sliding="none")
    sim.run(15.0)
    k = 4 * np.arange(sim.n_deposited)
    assert np.all(sim.rod.fixed[k] == 1) and np.all(sim.rod.fixed[k + 2] == 1)


def test_the_snap_rule_takes_the_edge_length_or_a_fixed_snap_length() -> None:
    """|e_x| < kappa_c l |e_z|: with l the edge's length (default) a straight edge 5 deg off
    the steps is outside the window on a mesh of 0.2 (kappa_c delta = 0.04 rad) and inside
    it on the paper's mesh of 1 (0.2 rad); snap_length = 1 gives the paper's window on
    the fine mesh. The option reaches the simulator's substrate."""
    from cnt_env.sim.substrate import _next_to_snap

    psi = np.radians(5.0)
    for delta, default_snaps in ((0.2, False), (1.0, True)):
        q = np.zeros(4 * 3 - 1)
        q[4], q[6] = delta * np.sin(psi), delta * np.cos(psi)  # edge 0, 5 deg off z
        q[8], q[10] = q[4] + delta, q[6]  # edge 1 along x: never snaps
        rest, snapped = np.full(2, delta), np.zeros(2, dtype=np.bool_)
        assert (_next_to_snap(q, rest, snapped, 0, 2, 0.2, 0.0) == 0) is default_snaps
        assert _next_to_snap(q, rest, snapped, 0, 2, 0.2, 1.0) == 0
        assert _next_to_snap(q, rest, snapped, 0, 2, 0.2, 0.1) == -1
    assert _small(snap_length=1.0).substrate.snap_length == 1.0

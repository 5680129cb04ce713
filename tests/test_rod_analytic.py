"""Analytic cases for the DER core and the Newton stepper (docs/model.md §8, rung 2)."""

from __future__ import annotations

import numpy as np
import pytest

from cnt_env.sim.stepper import DragParams, NewtonOptions, Rod, RodMaterial, SimulationError


def straight_nodes(n_edges: int, length: float = 1.0, axis: int = 0) -> np.ndarray:
    nodes = np.zeros((n_edges + 1, 3))
    nodes[:, axis] = np.linspace(0.0, length, n_edges + 1)
    return nodes


@pytest.mark.parametrize("n_edges", [50, 100])
def test_cantilever_tip_load_matches_euler_bernoulli(n_edges: int) -> None:
    """Small tip load on a clamped rod: w = F L^3 / (3 k_b) within 1%.

    The DER clamp fixes edge 0 (both its nodes and its theta); the material frame of an
    edge lives at its midpoint, so the free length is L = total - delta/2. (Measured
    from the node, the error is 3% at N = 50 and falls as 1/N; from the midpoint it is
    1e-4 and falls as 1/N^2.)
    """
    total, k_b, load = 1.0, 1.0, 1e-4
    rod = Rod(straight_nodes(n_edges, total),
              RodMaterial(k_s=1e6, k_b=k_b, k_t=k_b, rho=1e-3, r0=1e-3))  # fmt: skip
    rod.fix_node(0)
    rod.fix_node(1)
    rod.fix_theta(0)
    rod.ext_force[4 * n_edges + 1] = -load
    for _ in range(3):  # dt >> relaxation time: each step is a static solve
        rod.step(1e3)
    free_length = total - 0.5 * total / n_edges
    w_eb = load * free_length**3 / (3 * k_b)
    assert -rod.nodes[-1, 1] == pytest.approx(w_eb, rel=1e-2)
    assert rod.nodes[-1, 2] == pytest.approx(0.0, abs=1e-14)


def test_uniform_stretch_gives_ks_strain() -> None:
    k_s, strain, n_edges = 250.0, 1e-3, 10
    rod = Rod(straight_nodes(n_edges), RodMaterial(k_s=k_s, k_b=1.0, k_t=1.0, rho=1.0, r0=0.1))
    rod.q[0 : rod.n_dof : 4] *= 1.0 + strain
    f = rod.elastic_force()
    fx = f[0 : rod.n_dof : 4]
    assert fx[0] == pytest.approx(k_s * strain, rel=1e-12)
    assert fx[-1] == pytest.approx(-k_s * strain, rel=1e-12)
    np.testing.assert_allclose(fx[1:-1], 0.0, atol=1e-12 * k_s * strain)
    # and a static tip load F stretches it by F / k_s
    rod2 = Rod(straight_nodes(n_edges), RodMaterial(k_s=k_s, k_b=1.0, k_t=1.0, rho=1.0, r0=0.1))
    rod2.fix_node(0)
    rod2.fix_theta(0)
    rod2.ext_force[4 * n_edges] = k_s * strain
    for _ in range(3):
        rod2.step(1e4)
    assert rod2.nodes[-1, 0] - 1.0 == pytest.approx(strain / (1 + 0) * 1.0, rel=1e-9)


def test_twisted_straight_rod_gives_kt_torque() -> None:
    k_t, tau, n_edges, length = 0.7, 0.3, 12, 2.0
    rod = Rod(straight_nodes(n_edges, length),
              RodMaterial(k_s=1e3, k_b=1.0, k_t=k_t, rho=1.0, r0=0.1))  # fmt: skip
    delta = length / n_edges
    rod.thetas[:] = tau * delta * np.arange(n_edges)  # twist per unit length tau
    f = rod.elastic_force()
    torque = f[3 : rod.n_dof : 4]
    assert torque[0] == pytest.approx(k_t * tau, rel=1e-12)
    assert torque[-1] == pytest.approx(-k_t * tau, rel=1e-12)
    np.testing.assert_allclose(torque[1:-1], 0.0, atol=1e-12)
    # a straight twisted rod feels no positional force
    np.testing.assert_allclose(np.delete(f, np.s_[3::4]), 0.0, atol=1e-12)


def test_bent_rod_released_with_damping_loses_energy_monotonically() -> None:
    n_edges = 30
    s = np.linspace(0, 1.0, n_edges + 1)
    radius = 0.5
    nodes = np.stack(
        [radius * np.sin(s / radius), radius * (1 - np.cos(s / radius)), 0.02 * s**2], axis=1
    )
    rest = np.full(n_edges, 1.0 / n_edges)
    rod = Rod(nodes, RodMaterial(k_s=1e3, k_b=1.0, k_t=0.5, rho=1.0, r0=0.01),
              drag=DragParams(mu=1.0), rest_lengths=rest)  # fmt: skip
    energies = [rod.elastic_energy() + rod.kinetic_energy()]
    for _ in range(200):
        rod.step(2e-3)
        energies.append(rod.elastic_energy() + rod.kinetic_energy())
    e = np.array(energies)
    assert np.all(np.diff(e) <= 1e-12 * e[0]), "energy increased during damped relaxation"
    assert e[-1] < 0.5 * e[0], "the rod hardly relaxed: the test would not catch a gain"


@pytest.mark.parametrize("direction", ["axial", "normal"])
def test_terminal_velocity_under_linear_drag(direction: str) -> None:
    """A free straight rod pulled by F in still gas reaches F/(sigma mu L) along its axis
    and F/(C_sigma mu L) across it."""
    n_edges, length, pull = 20, 1.5, 0.8
    drag = DragParams(mu=1.3, sigma=1.0, c_sigma=2.29)
    rod = Rod(straight_nodes(n_edges, length),
              RodMaterial(k_s=1e3, k_b=1.0, k_t=1.0, rho=0.05, r0=0.01), drag=drag,
              options=NewtonOptions(residual_tol=1e-14))  # fmt: skip
    # (the default residual_tol = 1e-8 would bound the velocity error at ~1e-7 relative)
    axis = 0 if direction == "axial" else 1
    # distribute F like the drag (by Voronoi length) so the rod does not bend
    rod.ext_force[axis : rod.n_dof : 4] = pull * rod.voronoi_lengths[: rod.n_nodes] / length
    for _ in range(400):
        rod.step(5e-3)  # relaxation time rho/(C mu) ~ 0.02
    coef = drag.sigma if direction == "axial" else drag.c_sigma
    expected = pull / (coef * drag.mu * length)
    v = rod.node_velocities
    np.testing.assert_allclose(v[:, axis], expected, rtol=1e-9)
    np.testing.assert_allclose(np.delete(v, axis, axis=1), 0.0, atol=1e-12)


def test_failed_step_raises_simulation_error_not_nan() -> None:
    """An impossible step (1 Newton iteration allowed, no halving) fails cleanly."""
    rod = Rod(straight_nodes(10), RodMaterial(k_s=1e3, k_b=1.0, k_t=1.0, rho=1.0, r0=0.1),
              options=NewtonOptions(max_iter=1, max_halvings=0))  # fmt: skip
    rod.fix_node(0)
    rod.ext_force[4 * 10 + 1] = 5.0
    q_before = rod.q.copy()
    with pytest.raises(SimulationError, match="did not converge") as info:
        rod.step(1.0)
    assert np.all(np.isfinite(info.value.state["q"]))
    np.testing.assert_array_equal(rod.q, q_before)  # rewound


def test_halving_recovers_a_step_that_fails_at_full_dt() -> None:
    rod = Rod(straight_nodes(10), RodMaterial(k_s=1e3, k_b=1.0, k_t=1.0, rho=1.0, r0=0.1),
              options=NewtonOptions(max_iter=3))  # fmt: skip
    rod.fix_node(0)
    rod.ext_force[4 * 10 + 1] = 5.0
    rod.step(10.0)
    assert rod.halvings > 0
    assert rod.time == pytest.approx(10.0)
    assert np.all(np.isfinite(rod.q))


def test_bad_dt_rejected() -> None:
    rod = Rod(straight_nodes(3), RodMaterial(k_s=1.0, k_b=1.0, k_t=1.0, rho=1.0, r0=0.1))
    for bad in (0.0, -1.0, float("nan"), float("inf")):
        with pytest.raises(ValueError, match="dt"):
            rod.step(bad)


def test_split_edge_preserves_shape_energy_and_mass() -> None:
    """Splitting an edge of a bent, twisted, stretched rod into collinear sub-edges keeps
    the stretch energy and the total mass, puts zero curvature and twist at the new nodes,
    and leaves the other nodes where they were."""
    from cnt_env.rod.elastic import stretch_energy

    n_edges = 8
    s = np.linspace(0, 2.0, n_edges + 1)
    nodes = np.stack([np.sin(s), 1 - np.cos(s), 0.1 * s], axis=1)
    rest = 0.95 * np.linalg.norm(np.diff(nodes, axis=0), axis=1)  # pre-stretched
    rod = Rod(nodes, RodMaterial(k_s=1e3, k_b=1.0, k_t=0.5, rho=2.0, r0=0.01),
              rest_lengths=rest)  # fmt: skip
    rod.thetas[:] = 0.1 * np.arange(n_edges)
    mass_before = rod.mass[0 : rod.n_dof : 4].sum()
    e_s = stretch_energy(rod.q, rod.n_nodes, rod.rest_lengths, 1e3)
    rod.split_edge(3, 4)
    assert rod.n_nodes == n_edges + 1 + 3
    np.testing.assert_allclose(rod.mass[0 : rod.n_dof : 4].sum(), mass_before, rtol=1e-14)
    np.testing.assert_array_equal(rod.nodes[:4], nodes[:4])
    np.testing.assert_array_equal(rod.nodes[7:], nodes[4:])
    np.testing.assert_allclose(rod.rest_lengths[3:7], rest[3] / 4)
    e_s_after = stretch_energy(rod.q, rod.n_nodes, rod.rest_lengths, 1e3)
    assert e_s_after == pytest.approx(e_s, rel=1e-12)
    rod.elastic_energy()  # refreshes strains
    np.testing.assert_allclose(rod._kappa[4:7], 0.0, atol=1e-12)
    np.testing.assert_allclose(rod._twist[4:7], 0.0, atol=1e-12)
    rod.step(1e-3)
    assert np.all(np.isfinite(rod.q[: rod.n_dof]))


def test_predictor_retry_solves_from_the_step_start_before_halving() -> None:
    """NewtonOptions.predictor_retry: a nearly massless rod at rest in its straight
    equilibrium, given a wild stale velocity, so the predictor q + dt u starts far from
    the solution (which is q, the inertia being ~0). Without the retry Newton fails
    within max_iter from the predictor and the step is halved 10 times; with it the
    same equations are solved once more from q and converge: no halving. Off by default."""
    assert NewtonOptions().predictor_retry is False
    result = {}
    for retry in (False, True):
        rod = Rod(straight_nodes(10), RodMaterial(k_s=1e3, k_b=1.0, k_t=1.0, rho=1e-9, r0=0.1),
                  options=NewtonOptions(max_iter=4, predictor_retry=retry))  # fmt: skip
        rod.fix_node(0)
        rod.fix_node(1)
        rod.fix_theta(0)
        rod.u[1 : rod.n_dof : 4] = 20.0 * np.sin(np.arange(11))
        rod.step(0.05)
        result[retry] = rod
        assert np.max(np.abs(rod.nodes[:, 1])) < 1e-6  # back at the equilibrium
    assert result[False].halvings > 0
    assert result[True].halvings == 0 and result[True].steps == 1


def _spinning_rod(max_rotation_deg: float) -> Rod:
    """A free straight rod (4 edges along x, centre at the origin) spinning about z at
    omega = 1: a step dt turns every edge by about dt rad (stiff stretching keeps it
    rigid)."""
    nodes = straight_nodes(4, length=1.0) - [0.5, 0.0, 0.0]
    rod = Rod(nodes, RodMaterial(k_s=1e4, k_b=1.0, k_t=1.0, rho=1.0, r0=0.05),
              options=NewtonOptions(max_edge_rotation=np.radians(max_rotation_deg)))  # fmt: skip
    rod.u[0 : rod.n_dof : 4] = -nodes[:, 1]  # u = omega x r, omega = (0, 0, 1)
    rod.u[1 : rod.n_dof : 4] = nodes[:, 0]
    return rod


def test_max_edge_rotation_halves_a_step_that_turns_an_edge_too_far() -> None:
    """NewtonOptions.max_edge_rotation: a step that turns an edge by ~40 deg converges
    and is accepted with the check off; with a 20 deg limit it is rejected and halved
    until every accepted sub-step turns the edges by less than 20 deg. A step below the
    limit is bit-identical with and without the check. Off (0) by default."""
    assert NewtonOptions().max_edge_rotation == 0.0
    dt = np.radians(40.0)

    def angle(rod: Rod) -> float:
        e = rod.nodes[-1] - rod.nodes[0]
        return float(np.degrees(np.arctan2(e[1], e[0])))

    off, on = _spinning_rod(0.0), _spinning_rod(20.0)
    off.step(dt)
    assert off.halvings == 0 and 30.0 < angle(off) < 45.0
    on.step(dt)
    assert on.halvings >= 1 and on.steps >= 2  # accepted as sub-steps of <= 20 deg each
    assert 30.0 < angle(on) < 45.0  # the same motion, resolved
    small_off, small_on = _spinning_rod(0.0), _spinning_rod(20.0)
    small_off.step(np.radians(5.0))
    small_on.step(np.radians(5.0))
    assert small_on.halvings == 0
    assert np.array_equal(small_off.q, small_on.q) and np.array_equal(small_off.u, small_on.u)
    with pytest.raises(ValueError, match="max_edge_rotation"):
        NewtonOptions(max_edge_rotation=-0.1)

"""Finite-difference checks of the external forces' Jacobians (drag, vdW)."""

from __future__ import annotations

import numpy as np
import pytest

from cnt_env.rod.banded import KL, KU, LDAB
from cnt_env.sim.forces import (
    ADHESION_COHESIVE,
    add_adhesion,
    add_linear_drag,
    add_printed_drag,
    add_vdw,
    adhesion_energy,
    cohesive_energy,
    cohesive_pull,
)
from cnt_env.sim.stepper import Rod, RodMaterial
from tests.rodkit import random_rod

NO_FIXED = np.zeros(0, dtype=np.uint8)  # every Jacobian entry assembled

H_FD = 1e-7
JAC_RTOL = 1e-6


def _dense(ab: np.ndarray, n: int) -> np.ndarray:
    out = np.zeros((n, n))
    for i in range(n):
        for j in range(max(0, i - KL), min(n, i + KU + 1)):
            out[i, j] = ab[KL + KU + i - j, j]
    return out


def _force_and_jac(kernel, q, q_old, rest, dt, flow, drag_on, shear=0.0):
    n_nodes = (q.size + 1) // 4
    f = np.zeros(q.size)
    ab = np.zeros((LDAB, q.size))
    kernel(q, q_old, dt, n_nodes, rest, drag_on, flow, shear, 1.3, 1.0, 2.29, f, ab, True, NO_FIXED)
    return f, _dense(ab, q.size)


def _fd_jac(fun, q):
    cols = []
    for k in range(q.size):
        qp, qm = q.copy(), q.copy()
        qp[k] += H_FD
        qm[k] -= H_FD
        cols.append((fun(qp) - fun(qm)) / (2 * H_FD))
    return np.array(cols).T


def _setup(seed: int):
    rng = np.random.default_rng(seed)
    q, rest, _ = random_rod(rng, n_nodes=6)
    q_old = q - 0.05 * rng.normal(size=q.size)
    drag_on = np.ones(rest.size, dtype=np.uint8)
    drag_on[1] = 0
    return q, q_old, rest, 0.1, np.array([0.3, -0.1, 0.7]), drag_on


@pytest.mark.parametrize("seed", range(4))
def test_linear_drag_jacobian(seed: int) -> None:
    q, q_old, rest, dt, flow, on = _setup(seed)
    _, jac = _force_and_jac(add_linear_drag, q, q_old, rest, dt, flow, on)
    fd = _fd_jac(lambda x: _force_and_jac(add_linear_drag, x, q_old, rest, dt, flow, on)[0], q)
    # the band holds the residual Jacobian -dF/dq
    assert np.max(np.abs(jac + fd)) < JAC_RTOL * np.max(np.abs(jac))


@pytest.mark.parametrize("seed", range(4))
def test_printed_drag_jacobian(seed: int) -> None:
    """Exact in q: the velocity part and the tangent's q-dependence (geometric part)."""
    q, q_old, rest, dt, flow, on = _setup(seed)
    _, jac = _force_and_jac(add_printed_drag, q, q_old, rest, dt, flow, on)
    fd = _fd_jac(lambda x: _force_and_jac(add_printed_drag, x, q_old, rest, dt, flow, on)[0], q)
    assert np.max(np.abs(jac + fd)) < JAC_RTOL * np.max(np.abs(jac))


@pytest.mark.parametrize("seed", range(4))
def test_printed_drag_jacobian_in_a_strong_flow(seed: int) -> None:
    """|v_r| dt >> |e| (the env's regime): the geometric part dominates and is exact."""
    q, q_old, rest, _, _, on = _setup(seed)
    dt, flow = 30.0, np.array([0.13, 0.0, 0.05])
    _, jac = _force_and_jac(add_printed_drag, q, q_old, rest, dt, flow, on)
    fd = _fd_jac(lambda x: _force_and_jac(add_printed_drag, x, q_old, rest, dt, flow, on)[0], q)
    assert np.max(np.abs(jac + fd)) < JAC_RTOL * np.max(np.abs(jac))


def _lifted(q: np.ndarray, lift: float) -> np.ndarray:
    """q with every node raised by ``lift`` in y (the flow's profile reads the height)."""
    out = q.copy()
    out[1::4] += lift
    return out


@pytest.mark.parametrize("kernel", [add_linear_drag, add_printed_drag])
@pytest.mark.parametrize("seed", range(3))
def test_drag_jacobian_in_a_sheared_flow(kernel, seed: int) -> None:
    """The linear boundary layer (DragParams.shear): the flow depends on each edge's
    height, and J carries that column (forces._add_shear_columns) exactly. The rod is
    lifted clear of y = 0, where the profile is clamped; lifted less, the random rods of
    seeds 0 and 2 (they descend from y = 0) put their lowest edges below it, where the
    profile is 0 and so is the column."""
    q, q_old, rest, dt, flow, on = _setup(seed)
    shear = 0.4
    for lift in (5.0, 2.0):
        q1, q1_old = _lifted(q, lift), _lifted(q_old, lift)

        def force(x, q1_old=q1_old):
            return _force_and_jac(kernel, x, q1_old, rest, dt, flow, on, shear)[0]

        _, jac = _force_and_jac(kernel, q1, q1_old, rest, dt, flow, on, shear)
        fd = _fd_jac(force, q1)
        assert np.max(np.abs(jac + fd)) < JAC_RTOL * np.max(np.abs(jac))


def test_sheared_flow_is_the_uniform_flow_scaled_by_height() -> None:
    """A still rod along x at height y in a linear boundary layer of shear s feels the
    drag of a uniform flow s y times the set one: the profile v(y) = v s y, clamped at 0
    below the substrate."""
    rest = np.array([1.0])
    on = np.ones(1, dtype=np.uint8)
    flow = np.array([0.0, 0.0, 0.4])  # normal to the edge: F = C mu l v per edge
    for y in (3.0, 0.5, -0.5):
        q = np.array([0.0, y, 0.0, 0.0, 1.0, y, 0.0])
        for kernel in (add_linear_drag, add_printed_drag):
            f_shear, f_uniform = np.zeros(7), np.zeros(7)
            ab = np.zeros((LDAB, 7))
            kernel(q, q, 1.0, 2, rest, on, flow, 0.25, 1.3, 1.0, 2.29, f_shear, ab, False,
                   NO_FIXED)  # fmt: skip
            kernel(q, q, 1.0, 2, rest, on, flow * 0.25 * max(y, 0.0), 0.0, 1.3, 1.0, 2.29,
                   f_uniform, ab, False, NO_FIXED)  # fmt: skip
            np.testing.assert_allclose(f_shear, f_uniform, rtol=1e-12, atol=1e-15)
            assert f_shear[2] == pytest.approx(0.5 * 2.29 * 1.3 * 0.4 * 0.25 * max(y, 0.0))


@pytest.mark.parametrize("seed", range(2))
def test_printed_drag_z_only_edges_keep_their_z_entries(seed: int) -> None:
    """With nodes fixed in x and y only the z-z entries are assembled, and they are the
    full Jacobian's."""
    q, q_old, rest, dt, flow, on = _setup(seed)
    n = q.size
    fixed = np.zeros(n, dtype=np.uint8)
    fixed[0:2] = fixed[4:6] = fixed[8:10] = 1  # nodes 0-2 fixed in x, y
    full = np.zeros(n), np.zeros((LDAB, n))
    part = np.zeros(n), np.zeros((LDAB, n))
    for (f, ab), fx in ((full, NO_FIXED), (part, fixed)):
        add_printed_drag(
            q, q_old, dt, (n + 1) // 4, rest, on, flow, 0.0, 1.3, 1.0, 2.29, f, ab, True, fx
        )
    free = np.flatnonzero(fixed == 0)
    dense_full, dense_part = _dense(full[1], n), _dense(part[1], n)
    np.testing.assert_array_equal(dense_part[np.ix_(free, free)], dense_full[np.ix_(free, free)])


def test_printed_law_matches_linear_for_axial_and_normal_motion() -> None:
    n_nodes = 2
    rest = np.array([1.0])
    on = np.ones(1, dtype=np.uint8)
    q = np.array([0.0, 0.0, 0.0, 0.0, 1.0, 0.0, 0.0])  # edge along x
    for flow in (np.array([0.4, 0.0, 0.0]), np.array([0.0, 0.0, -0.4])):
        f_lin, f_pr = np.zeros(7), np.zeros(7)
        ab = np.zeros((LDAB, 7))
        args = (rest, on, flow, 0.0, 1.3, 1.0, 2.29)
        add_linear_drag(q, q, 1.0, n_nodes, *args, f_lin, ab, False, NO_FIXED)
        add_printed_drag(q, q, 1.0, n_nodes, *args, f_pr, ab, False, NO_FIXED)
        np.testing.assert_allclose(f_pr, f_lin, rtol=1e-12, atol=1e-15)


@pytest.mark.parametrize("y", [0.9, 0.3, 0.01, -0.2, 0.999])
def test_vdw_force_and_jacobian(y: float) -> None:
    delta, beta0, clamp, e_v = 1.0, 0.4, 0.05, 1.3
    vdw = np.array([2.0, beta0, delta, clamp, e_v])

    def fy(yy: float) -> tuple[float, float]:
        q = np.zeros(11)
        q[4 * 2 + 1] = yy
        f = np.zeros(11)
        ab = np.zeros((LDAB, 11))
        add_vdw(q, vdw, f, ab)
        return f[9], ab[KL + KU, 9]

    f, dfdy_res = fy(y)
    root = max(np.sqrt(delta**2 - y * y), clamp * delta)
    assert f == pytest.approx(-e_v * delta / beta0 / root, rel=1e-12)
    fd = (fy(y + 1e-7)[0] - fy(y - 1e-7)[0]) / 2e-7
    assert dfdy_res == pytest.approx(-fd, rel=1e-6, abs=1e-9)


def test_vdw_releases_ev_delta_from_beta0_to_zero() -> None:
    """Integrated from beta0 down to 0 the pull releases exactly e_v delta (paper eq. 1)."""
    from scipy.integrate import quad

    delta, beta0, e_v = 0.8, 0.6, 1.7
    vdw = np.array([0.0, beta0, delta, 0.05, e_v])

    def pull(y: float) -> float:
        q = np.array([0.0, y, 0.0])
        f = np.zeros(3)
        add_vdw(q, vdw, f, np.zeros((LDAB, 3)))
        return -f[1]

    work, _ = quad(pull, 0.0, delta * np.sin(beta0), epsabs=1e-13)
    assert work == pytest.approx(e_v * delta, rel=1e-9)


# ---- the cohesive adhesion (forces.cohesive_pull / add_cohesive, docs/model.md §4) ----
COH_H, COH_EV = 0.05, 1.3


@pytest.mark.parametrize("y", [0.049, 0.03, 0.011, 1e-4, -0.004])
def test_cohesive_pull_is_minus_energy_gradient_and_jacobian_matches_fd(y: float) -> None:
    w = 0.37
    f, dfdy = cohesive_pull(y, w, COH_H, COH_EV)
    e = lambda yy: cohesive_energy(yy, w, COH_H, COH_EV)  # noqa: E731
    assert f == pytest.approx(-(e(y + H_FD) - e(y - H_FD)) / (2 * H_FD), rel=1e-6)
    fd = (cohesive_pull(y + H_FD, w, COH_H, COH_EV)[0]
          - cohesive_pull(y - H_FD, w, COH_H, COH_EV)[0]) / (2 * H_FD)  # fmt: skip
    assert dfdy == pytest.approx(fd, rel=1e-6, abs=1e-9)


def test_cohesive_pull_releases_ev_per_length_and_enters_continuously() -> None:
    """From the edge of the range down to y = 0 a node releases e_v times the length it
    stands for; the pull is zero at y = h (no step load on entry) and outside."""
    from scipy.integrate import quad

    w = 0.21
    work, _ = quad(lambda y: -cohesive_pull(y, w, COH_H, COH_EV)[0], 0.0, COH_H, epsabs=1e-14)
    assert work == pytest.approx(COH_EV * w, rel=1e-10)
    assert cohesive_energy(0.0, w, COH_H, COH_EV) == pytest.approx(-COH_EV * w, rel=1e-14)
    assert cohesive_pull(COH_H * (1 - 1e-9), w, COH_H, COH_EV)[0] == pytest.approx(0, abs=1e-6)
    assert cohesive_pull(COH_H, w, COH_H, COH_EV) == (0.0, 0.0)
    assert cohesive_pull(3.0, w, COH_H, COH_EV) == (0.0, 0.0)


def test_add_cohesive_pulls_free_nodes_in_range_with_their_lengths() -> None:
    """Against finite differences of the summed energy: every node from the contact
    node up, below the range, weighted by half of each rest edge beside it; the nodes
    below the contact node (deposited) and above the range feel nothing."""
    n = 6
    rest = np.array([0.2, 0.2, 0.25, 0.3, 0.4])
    ys = [0.0, 0.01, 0.02, 0.035, 0.3, 0.01]  # node 5 (the top) in range again
    nodes = np.zeros((n, 3))
    nodes[:, 0] = np.concatenate([[0.0], np.cumsum(rest)])
    nodes[:, 1] = ys
    vor = Rod(nodes, RodMaterial(1.0, 1.0, 1.0, 1.0, 0.01), rest_lengths=rest).voronoi_lengths
    # half of each rest edge beside the node; the ends (0, the top) hold half their one edge
    np.testing.assert_allclose(vor[:n], [0.1, 0.2, 0.225, 0.275, 0.35, 0.2], rtol=1e-15)
    q = np.zeros(4 * n - 1)
    q[1::4] = ys
    vdw = np.array([1.0, 1.0, 1.0, 0.05, COH_EV, ADHESION_COHESIVE, COH_H])
    f = np.zeros(q.size)
    ab = np.zeros((LDAB, q.size))
    add_adhesion(q, n, vor, vdw, f, ab, True)
    for i in range(n):
        k = 4 * i + 1
        qp, qm = q.copy(), q.copy()
        qp[k] += H_FD
        qm[k] -= H_FD
        fd = -(adhesion_energy(qp, n, vor, vdw) - adhesion_energy(qm, n, vor, vdw)) / (2 * H_FD)
        assert f[k] == pytest.approx(fd, rel=1e-6, abs=1e-9), i
        expect = 0.0 if (i < 1 or ys[i] >= COH_H) else 2 * COH_EV * vor[i] / COH_H**2
        assert ab[KL + KU, k] == pytest.approx(-expect, rel=1e-12)
    assert f[1] == 0.0 and f[4 * 4 + 1] == 0.0  # deposited node 0; node 4 above the range
    np.testing.assert_array_equal(np.delete(f, np.arange(1, q.size, 4)), 0.0)  # y only


def test_add_adhesion_eq1_is_add_vdw_bit_for_bit() -> None:
    q = np.zeros(11)
    q[9] = 0.3
    vdw = np.array([2.0, 0.4, 1.0, 0.05, 1.3, 0.0, 0.05])  # VDW_MODEL 0: eq. 1
    f_a, f_b = np.zeros(11), np.zeros(11)
    ab_a, ab_b = np.zeros((LDAB, 11)), np.zeros((LDAB, 11))
    add_adhesion(q, 3, np.ones(2), vdw, f_a, ab_a, True)
    add_vdw(q, vdw, f_b, ab_b)
    np.testing.assert_array_equal(f_a, f_b)
    np.testing.assert_array_equal(ab_a, ab_b)
    f_c = np.zeros(11)
    add_adhesion(q, 3, np.ones(2), vdw, f_c, ab_a, False)  # residual only
    np.testing.assert_array_equal(f_c, f_b)

"""Finite-difference checks of every elastic force against its energy and every Hessian
against its force (docs/model.md §3, mandatory), on random 5-8 node rods.

Frames are time-parallel-transported from the frozen start-of-step state, which is the
configuration itself (as at the first Newton iterate). Central differences with step
h have truncation error O(h^2); the tolerances below sit well under the size of any
missing term (a wrong sign or factor gives relative errors of order 1).

The solver's Jacobian (``transport=True``, the default of the Newton solve) is instead
the exact Jacobian of the force as computed, also away from the frozen state, where the
transported reference frame turns about each tangent: -dF/dq to round-off.

What "the Hessian" is, precisely. The DER force formulas (Bergou 2010) are the exact
gradient of the energy at the frozen state, but away from it the transported frame adds
terms they omit (the holonomy of the reference twist, and the frame rotation in the
curvatures). Hence the Jacobian of the force *formula* has an antisymmetric part, while
the DER Hessian is the exact, symmetric Hessian of the energy. We check both facts:
H == d2E/dq2 (second differences of the energy), H == sym(-dF/dq) to round-off, and for
stretching, which has no frames, H == -dF/dq exactly.
"""

from __future__ import annotations

import numpy as np
import pytest

from tests.rodkit import energy, force_and_hessian, random_rod

H_FD = 1e-6  # central-difference step (rod lengths are O(1))
FORCE_RTOL = 1e-7  # |F - (-dE/dq)_fd| / max|F|
HESS_RTOL = 1e-7  # |H - (-dF/dq)_fd| / max|H|  (measured ~1e-10)
HESS_ENERGY_RTOL = 1e-6  # |H - d2E/dq2| / max|H| (second differences, measured ~1e-7)
H_FD2 = 1e-4  # second-difference step: error O(h^2) + O(eps/h^2)

PARTS = {
    "stretch": ("stretch",),
    "bend_twist": ("bend_twist",),
    "all": ("stretch", "bend_twist"),
}
STIFF = {"k_s": 37.0, "k_b": 1.3, "k_t": 0.7}


def _fd_gradient(fun, q: np.ndarray) -> np.ndarray:
    g = np.empty_like(q)
    for k in range(q.size):
        qp = q.copy()
        qm = q.copy()
        qp[k] += H_FD
        qm[k] -= H_FD
        g[k] = (fun(qp) - fun(qm)) / (2 * H_FD)
    return g


def _fd_jacobian(fun, q: np.ndarray) -> np.ndarray:
    cols = []
    for k in range(q.size):
        qp = q.copy()
        qm = q.copy()
        qp[k] += H_FD
        qm[k] -= H_FD
        cols.append((fun(qp) - fun(qm)) / (2 * H_FD))
    return np.array(cols).T


@pytest.mark.parametrize("seed", range(6))
@pytest.mark.parametrize("part", list(PARTS))
def test_force_is_minus_energy_gradient(seed: int, part: str) -> None:
    rng = np.random.default_rng(seed)
    q, rest, frozen = random_rod(rng, n_nodes=5 + seed % 4)
    parts = PARTS[part]
    force, _ = force_and_hessian(q, rest, frozen, **STIFF, parts=parts)
    grad_fd = _fd_gradient(lambda x: energy(x, rest, frozen, **STIFF, parts=parts), q)
    err = np.max(np.abs(force + grad_fd)) / np.max(np.abs(force))
    assert err < FORCE_RTOL, f"{part}: force vs -dE/dq relative error {err:.2e}"


@pytest.mark.parametrize("seed", range(6))
@pytest.mark.parametrize("part", list(PARTS))
def test_hessian_is_symmetric_part_of_minus_force_jacobian(seed: int, part: str) -> None:
    rng = np.random.default_rng(100 + seed)
    q, rest, frozen = random_rod(rng, n_nodes=5 + seed % 4)
    parts = PARTS[part]
    _, hess = force_and_hessian(q, rest, frozen, **STIFF, parts=parts)
    jac_fd = _fd_jacobian(lambda x: force_and_hessian(x, rest, frozen, **STIFF, parts=parts)[0], q)
    if part == "stretch":  # no frames: the force formula is an exact gradient everywhere
        err = np.max(np.abs(hess + jac_fd)) / np.max(np.abs(hess))
    else:
        err = np.max(np.abs(hess + 0.5 * (jac_fd + jac_fd.T))) / np.max(np.abs(hess))
    assert err < HESS_RTOL, f"{part}: Hessian vs -dF/dq relative error {err:.2e}"


@pytest.mark.parametrize("seed", range(3))
@pytest.mark.parametrize("part", list(PARTS))
def test_hessian_is_energy_second_derivative(seed: int, part: str) -> None:
    rng = np.random.default_rng(200 + seed)
    q, rest, frozen = random_rod(rng, n_nodes=5)
    parts = PARTS[part]
    _, hess = force_and_hessian(q, rest, frozen, **STIFF, parts=parts)

    def e(x: np.ndarray) -> float:
        return energy(x, rest, frozen, **STIFF, parts=parts)

    n = q.size
    h = H_FD2
    hess_fd = np.empty((n, n))
    for i in range(n):
        for j in range(i, n):
            vals = []
            for a, b in ((h, h), (h, -h), (-h, h), (-h, -h)):
                x = q.copy()
                x[i] += a
                x[j] += b
                vals.append(e(x))
            hess_fd[i, j] = hess_fd[j, i] = (vals[0] - vals[1] - vals[2] + vals[3]) / (4 * h * h)
    err = np.max(np.abs(hess - hess_fd)) / np.max(np.abs(hess))
    assert err < HESS_ENERGY_RTOL, f"{part}: Hessian vs d2E/dq2 relative error {err:.2e}"


def test_twist_force_jacobian_is_not_symmetric() -> None:
    """The check above is not vacuous: the bend-twist force Jacobian really has an
    antisymmetric part of order one (so comparing against its symmetric part matters)."""
    q, rest, frozen = random_rod(np.random.default_rng(3), n_nodes=6)
    parts = PARTS["bend_twist"]
    _, hess = force_and_hessian(q, rest, frozen, **STIFF, parts=parts)
    jac_fd = _fd_jacobian(lambda x: force_and_hessian(x, rest, frozen, **STIFF, parts=parts)[0], q)
    assert np.max(np.abs(jac_fd - jac_fd.T)) > 1e-2 * np.max(np.abs(hess))


def test_hessian_is_symmetric_at_frozen_state() -> None:
    q, rest, frozen = random_rod(np.random.default_rng(7), n_nodes=8)
    _, hess = force_and_hessian(q, rest, frozen, **STIFF)
    assert np.max(np.abs(hess - hess.T)) < 1e-12 * np.max(np.abs(hess))


def _moved(seed: int, scale: float):
    """A random rod (its frozen state) and an iterate moved away from it by ``scale``."""
    rng = np.random.default_rng(300 + seed)
    q0, rest, frozen = random_rod(rng, n_nodes=5 + seed % 4)
    q = q0 + scale * rng.normal(size=q0.size)
    return q, rest, frozen


@pytest.mark.parametrize("scale", [0.0, 0.05, 0.3])
@pytest.mark.parametrize("seed", range(4))
@pytest.mark.parametrize("part", list(PARTS))
def test_exact_jacobian_is_minus_force_jacobian(seed: int, scale: float, part: str) -> None:
    """With the transport terms the assembled matrix is -dF/dq itself, at the frozen
    state and at iterates moved away from it (as in later Newton iterations)."""
    q, rest, frozen = _moved(seed, scale)
    parts = PARTS[part]
    _, jac = force_and_hessian(q, rest, frozen, **STIFF, parts=parts, transport=True)
    jac_fd = _fd_jacobian(lambda x: force_and_hessian(x, rest, frozen, **STIFF, parts=parts)[0], q)
    err = np.max(np.abs(jac + jac_fd)) / np.max(np.abs(jac))
    assert err < HESS_RTOL, f"{part}, moved {scale}: J vs -dF/dq relative error {err:.2e}"


def test_der_hessian_misses_the_transport_terms_away_from_the_frozen_state() -> None:
    """The check above is not vacuous: away from the frozen state even the symmetric part
    of -dF/dq differs from the DER Hessian (the rotation of the transported frame)."""
    q, rest, frozen = _moved(1, 0.3)
    parts = PARTS["bend_twist"]
    _, hess = force_and_hessian(q, rest, frozen, **STIFF, parts=parts)
    jac_fd = _fd_jacobian(lambda x: force_and_hessian(x, rest, frozen, **STIFF, parts=parts)[0], q)
    err = np.max(np.abs(hess + 0.5 * (jac_fd + jac_fd.T))) / np.max(np.abs(hess))
    assert err > 1e-3, f"DER Hessian matches sym(-dF/dq) to {err:.2e}: nothing to test"


def test_rotation_gradient_matches_finite_differences() -> None:
    """d psi/d edge (elastic._rotation_gradient): the turn of the transported director
    about the tangent, measured against the instantaneous transport's zero turn."""
    from cnt_env.rod.elastic import _rotation_gradient
    from cnt_env.rod.frames import parallel_transport

    rng = np.random.default_rng(11)
    for _ in range(5):
        a = rng.normal(size=3)
        a /= np.linalg.norm(a)
        d = 1.7 * (a + 0.6 * rng.normal(size=3))
        u = np.cross(a, rng.normal(size=3))
        u /= np.linalg.norm(u)

        def director(x: np.ndarray, u=u, a=a) -> np.ndarray:
            out = np.empty(3)
            parallel_transport(u, a, x / np.linalg.norm(x), out)
            return out

        t = d / np.linalg.norm(d)
        d2 = np.cross(t, director(d))
        fd = np.array([
            (director(d + H_FD * ek) - director(d - H_FD * ek)) @ d2 / (2 * H_FD)
            for ek in np.eye(3)
        ])  # fmt: skip
        assert np.allclose(_rotation_gradient(tuple(d), tuple(a)), fd, rtol=1e-7, atol=1e-10)

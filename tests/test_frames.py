"""Parallel transport, time-parallel reference frames and reference twist."""

from __future__ import annotations

import numpy as np
import pytest

from cnt_env.rod import frames


def _unit(v: np.ndarray) -> np.ndarray:
    return v / np.linalg.norm(v)


def test_parallel_transport_maps_tangent_and_is_a_rotation() -> None:
    rng = np.random.default_rng(0)
    for _ in range(50):
        a, b, u = _unit(rng.normal(size=3)), _unit(rng.normal(size=3)), rng.normal(size=3)
        out = np.empty(3)
        frames.parallel_transport(a, a, b, out)
        np.testing.assert_allclose(out, b, atol=1e-14)
        frames.parallel_transport(u, a, b, out)
        assert np.linalg.norm(out) == pytest.approx(np.linalg.norm(u), rel=1e-14)
        axis = np.cross(a, b)  # the rotation axis is left alone
        frames.parallel_transport(axis, a, b, out)
        np.testing.assert_allclose(out, axis, atol=1e-14)


def test_parallel_transport_is_identity_for_parallel_tangents() -> None:
    t = _unit(np.array([0.3, -0.4, 0.5]))
    u = np.array([1.0, 2.0, 3.0])
    out = np.empty(3)
    frames.parallel_transport(u, t, t.copy(), out)
    np.testing.assert_array_equal(out, u)


def _rotate(v: np.ndarray, axis: np.ndarray, angle: float) -> np.ndarray:
    k = _unit(axis)
    return v * np.cos(angle) + np.cross(k, v) * np.sin(angle) + k * k.dot(v) * (1 - np.cos(angle))


def test_frame_stays_orthonormal_through_180_degrees_of_small_rotations() -> None:
    """Transport one edge's frame step by step while its tangent turns by ~179 degrees
    about a wobbling axis (1000 steps): it must stay orthonormal and right-handed."""
    rng = np.random.default_rng(1)
    t = np.array([[1.0, 0.0, 0.0]])
    d1 = np.array([[0.0, 1.0, 0.0]])
    d2 = np.empty((1, 3))
    n_steps = 1000
    for k in range(n_steps):
        axis = np.array([0.0, 0.2 * np.sin(0.01 * k), 1.0]) + 0.05 * rng.normal(size=3)
        t_new = _unit(_rotate(t[0], axis, np.deg2rad(179.0) / n_steps))[None, :]
        d1_new = np.empty((1, 3))
        frames.time_parallel_frames(t, d1, t_new, 1, d1_new, d2)
        t, d1 = t_new, d1_new
    assert np.degrees(np.arccos(np.clip(t[0, 0], -1, 1))) > 150.0
    assert abs(np.linalg.norm(d1[0]) - 1) < 1e-13
    assert abs(d1[0].dot(t[0])) < 1e-13
    np.testing.assert_allclose(d2[0], np.cross(t[0], d1[0]), atol=1e-13)


def test_reference_twist_has_no_2pi_jumps() -> None:
    """Precess edge 1 of a two-edge rod three times around a cone of half-angle 75
    degrees about edge 0. Time-parallel transport picks up the holonomy, 2 pi (1 - cos a)
    per turn, so the reference twist must grow smoothly to 3 * 2 pi (1 - cos a) ~ 4.4 pi
    without wrapping into (-pi, pi]."""
    half_angle = np.deg2rad(75.0)
    n_per_turn = 400
    axis = np.array([0.0, 0.0, 1.0])

    def tangent(phase: float) -> np.ndarray:
        return np.array(
            [np.sin(half_angle) * np.cos(phase), np.sin(half_angle) * np.sin(phase),
             np.cos(half_angle)]
        )  # fmt: skip

    tangents = np.array([axis, tangent(0.0)])
    d1 = np.empty((2, 3))
    frames.initial_reference_frame(tangents, 2, d1)
    ref_twist = np.zeros(3)
    frames.reference_twist(tangents, d1, np.zeros(3), 3, ref_twist)
    start = ref_twist[1]
    history = [start]
    d2 = np.empty((2, 3))
    for k in range(1, 3 * n_per_turn + 1):
        new_t = np.array([axis, tangent(2 * np.pi * k / n_per_turn)])
        new_d1 = np.empty((2, 3))
        frames.time_parallel_frames(tangents, d1, new_t, 2, new_d1, d2)
        new_twist = np.zeros(3)
        frames.reference_twist(new_t, new_d1, ref_twist, 3, new_twist)
        tangents, d1, ref_twist = new_t, new_d1, new_twist
        history.append(ref_twist[1])
    steps = np.abs(np.diff(history))
    assert steps.max() < 0.1, "a jump in the reference twist"
    expected = 3 * 2 * np.pi * (1 - np.cos(half_angle))
    assert abs(history[-1] - start) == pytest.approx(expected, rel=1e-3)
    assert abs(history[-1] - start) > 4 * np.pi  # well beyond any wrap-around


def test_curvature_binormal_of_a_right_angle() -> None:
    t = np.array([[1.0, 0.0, 0.0], [0.0, 1.0, 0.0]])
    kb = np.zeros((3, 3))
    frames.curvature_binormal(t, 3, kb)
    # |kb| = 2 tan(phi/2) = 2 for phi = 90 degrees, along t0 x t1 = +z
    np.testing.assert_allclose(kb[1], [0.0, 0.0, 2.0], atol=1e-15)


def _frames_in_turn(q, n, t_old, d1_old, rt_old) -> list[np.ndarray]:
    ne = n - 1
    out = [np.zeros((ne, 3)), np.zeros(ne), np.zeros((ne, 3)), np.zeros((ne, 3)), np.zeros(n),
           np.zeros((ne, 3)), np.zeros((ne, 3)), np.zeros((n, 3)), np.zeros((n, 2)),
           np.zeros(n)]  # fmt: skip
    tg, ln, d1, d2, rt, m1, m2, kb, kappa, tw = out
    frames.compute_tangents(q, n, tg, ln)
    frames.time_parallel_frames(t_old, d1_old, tg, ne, d1, d2)
    frames.reference_twist(tg, d1, rt_old, n, rt)
    frames.material_frames(q, d1, d2, ne, m1, m2)
    frames.curvature_binormal(tg, n, kb)
    frames.strains(q, kb, m1, m2, rt, n, kappa, tw)
    return out


@pytest.mark.parametrize("seed", range(6))
def test_fused_update_gives_the_bits_of_the_kernels_in_turn(seed: int) -> None:
    """frames.update_all (the stepper's per-iterate pass) against the six kernels called
    in turn, bit for bit, on random rods moved from a start-of-step frame; one edge keeps
    its start tangent (the parallel-transport identity branch)."""
    rng = np.random.default_rng(seed)
    n = int(rng.integers(2, 40))
    start = np.cumsum(rng.normal(size=(n, 3)), axis=0)
    q0 = np.zeros(4 * n)
    q0.reshape(n, 4)[:, :3] = start
    ne = n - 1
    t_old, lengths = np.zeros((ne, 3)), np.zeros(ne)
    frames.compute_tangents(q0, n, t_old, lengths)
    d1_old = np.zeros((ne, 3))
    frames.initial_reference_frame(t_old, ne, d1_old)
    rt_old = 10.0 ** rng.uniform(-3, 0, size=n) * rng.normal(size=n)
    moved = start + 0.2 * rng.normal(size=start.shape)
    moved[1] = moved[0] + (start[1] - start[0])  # edge 0 parallel to its start tangent
    q = np.zeros(4 * n)
    q.reshape(n, 4)[:, :3] = moved
    q.reshape(n, 4)[:, 3] = rng.normal(size=n)
    expected = _frames_in_turn(q, n, t_old, d1_old, rt_old)
    got = _frames_in_turn(q, n, t_old, d1_old, rt_old)  # same shapes, then overwritten
    for a in got:
        a[...] = np.nan
    frames.update_all(q, n, t_old, d1_old, rt_old, *got)
    for name, a, b in zip(("tangents", "lengths", "d1", "d2", "ref_twist", "m1", "m2", "kb",
                           "kappa", "twist"), expected, got, strict=True):  # fmt: skip
        if name in ("ref_twist", "kb", "kappa", "twist"):  # interior nodes only
            a, b = a[1 : n - 1], b[1 : n - 1]
        np.testing.assert_array_equal(b, a, err_msg=name)

"""Small helpers shared by the rod tests: random rods and energy/force/Hessian evaluation
with frames time-parallel-transported from a frozen state (docs/model.md §3)."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from cnt_env.rod import elastic, frames
from cnt_env.rod.banded import KL, KU, LDAB


@dataclass
class FrozenFrame:
    """Start-of-step reference state the iterate's frames are transported from."""

    tangents: np.ndarray
    d1: np.ndarray
    ref_twist: np.ndarray


def random_rod(rng: np.random.Generator, n_nodes: int, max_turn: float = 1.0):
    """Random polyline with edges of length 0.5-1.5 turning by at most ``max_turn`` rad
    per node, random material angles, rest lengths within 20% of the actual ones, and a
    random (non space-parallel) reference frame. Returns (q, rest_lengths, frozen)."""
    x = np.zeros((n_nodes, 3))
    t = rng.normal(size=3)
    t /= np.linalg.norm(t)
    for i in range(1, n_nodes):
        kick = rng.normal(size=3)
        kick -= kick.dot(t) * t
        kick *= rng.uniform(0, max_turn) / max(np.linalg.norm(kick), 1e-12)
        t = t + np.tan(np.linalg.norm(kick)) * kick / max(np.linalg.norm(kick), 1e-12)
        t /= np.linalg.norm(t)
        x[i] = x[i - 1] + rng.uniform(0.5, 1.5) * t
    q = np.zeros(4 * n_nodes - 1)
    for i in range(n_nodes):
        q[4 * i : 4 * i + 3] = x[i]
    q[3::4] = rng.uniform(-np.pi, np.pi, n_nodes - 1)
    n_edges = n_nodes - 1
    tangents = np.empty((n_edges, 3))
    lengths = np.empty(n_edges)
    frames.compute_tangents(q, n_nodes, tangents, lengths)
    d1 = np.empty((n_edges, 3))
    frames.initial_reference_frame(tangents, n_edges, d1)
    # spin each reference director about its tangent: a generic, twisted reference frame
    for j in range(n_edges):
        a = rng.uniform(-np.pi, np.pi)
        d2 = np.cross(tangents[j], d1[j])
        d1[j] = np.cos(a) * d1[j] + np.sin(a) * d2
    ref_twist = np.zeros(n_nodes)
    frames.reference_twist(tangents, d1, np.zeros(n_nodes), n_nodes, ref_twist)
    rest = lengths * rng.uniform(0.8, 1.2, n_edges)
    return q, rest, FrozenFrame(tangents.copy(), d1.copy(), ref_twist.copy())


def voronoi(rest: np.ndarray) -> np.ndarray:
    n_nodes = rest.size + 1
    v = np.zeros(n_nodes)
    v[1:-1] = 0.5 * (rest[:-1] + rest[1:])
    return v


def strains_from(q: np.ndarray, frozen: FrozenFrame):
    """Frames and strains of configuration q, transported from ``frozen``."""
    n_nodes = (q.size + 1) // 4
    n_edges = n_nodes - 1
    tangents = np.empty((n_edges, 3))
    lengths = np.empty(n_edges)
    frames.compute_tangents(q, n_nodes, tangents, lengths)
    d1 = np.empty((n_edges, 3))
    d2 = np.empty((n_edges, 3))
    frames.time_parallel_frames(frozen.tangents, frozen.d1, tangents, n_edges, d1, d2)
    ref_twist = np.zeros(n_nodes)
    frames.reference_twist(tangents, d1, frozen.ref_twist, n_nodes, ref_twist)
    m1 = np.empty((n_edges, 3))
    m2 = np.empty((n_edges, 3))
    frames.material_frames(q, d1, d2, n_edges, m1, m2)
    kb = np.zeros((n_nodes, 3))
    frames.curvature_binormal(tangents, n_nodes, kb)
    kappa = np.zeros((n_nodes, 2))
    twist = np.zeros(n_nodes)
    frames.strains(q, kb, m1, m2, ref_twist, n_nodes, kappa, twist)
    return {
        "tangents": tangents, "d1": d1, "d2": d2, "m1": m1, "m2": m2,
        "kb": kb, "kappa": kappa, "twist": twist, "ref_twist": ref_twist,
    }  # fmt: skip


def energy(q, rest, frozen, k_s, k_b, k_t, parts=("stretch", "bend_twist")) -> float:
    n_nodes = (q.size + 1) // 4
    s = strains_from(q, frozen)
    total = 0.0
    if "stretch" in parts:
        total += elastic.stretch_energy(q, n_nodes, rest, k_s)
    if "bend_twist" in parts:
        total += elastic.bend_twist_energy(s["kappa"], s["twist"], voronoi(rest), n_nodes, k_b, k_t)
    return total


def force_and_hessian(
    q, rest, frozen, k_s, k_b, k_t, parts=("stretch", "bend_twist"), transport=False
):
    """Elastic force -dE/dq and the dense matrix assembled through the band: the DER
    Hessian d2E/dq2, or with ``transport`` the exact Jacobian -dF/dq of the force."""
    n_nodes = (q.size + 1) // 4
    n_dof = q.size
    s = strains_from(q, frozen)
    force = np.zeros(n_dof)
    ab = np.zeros((LDAB, n_dof))
    if "stretch" in parts:
        elastic.add_stretch(q, n_nodes, rest, k_s, force, ab, True)
    if "bend_twist" in parts:
        elastic.add_bend_twist(
            q, n_nodes, s["m1"], s["m2"], s["twist"], voronoi(rest), k_b, k_t, force, ab, True,
            frozen.tangents, transport, np.zeros(0, dtype=np.uint8),
        )  # fmt: skip
    dense = np.zeros((n_dof, n_dof))
    for i in range(n_dof):
        for j in range(max(0, i - KL), min(n_dof, i + KU + 1)):
            dense[i, j] = ab[KL + KU + i - j, j]
    return force, dense

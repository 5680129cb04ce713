"""Small linear algebra without BLAS, so that a rollout has the same bits on every CPU.

NumPy hands ``@``, ``np.dot`` and ``np.linalg.norm`` of a vector to OpenBLAS, which picks
its kernels per CPU (and by ``OPENBLAS_CORETYPE``). The kernels sum in different orders
and with or without fused multiply-adds, so the last bit of a dot product depends on the
machine; a deposition is chaotic and carries that bit into a different trace within a
few control steps (docs/architecture.md, "Determinism"). Measured on one Intel Xeon: the
route follower's held-out ``detour_block``, seed 0, scored 0.8458 in 81 steps with the
SkylakeX kernels, 0.8437 in 81 with the Haswell ones and 0.8034 in 78 with the Prescott
ones, and its observations parted after the first control step.

Every product and sum on a rollout's path (the simulator, the route task, the scripted
policies) goes through these helpers instead: products elementwise (exact IEEE
rounding) and sums by ``np.add.reduce``, whose pairwise order is fixed by the array's
length, not by the CPU. ``tests/test_numerics.py`` checks the rollout against two
OpenBLAS kernel sets and that no ``@``, ``dot`` or ``linalg`` call comes back on that
path. Analysis (``patterns``, plotting) may still use BLAS: it reads a finished trace.
"""

from __future__ import annotations

import math

import numpy as np

FloatArray = np.ndarray


def dot(a: FloatArray, b: FloatArray) -> float:
    """The dot product of two 1-D arrays (``b`` may be boolean), in a fixed order."""
    return float(np.add.reduce(np.multiply(a, b)))


def norm(v: FloatArray) -> float:
    """The Euclidean length of a 1-D array: sqrt(v · v), in a fixed order."""
    return math.sqrt(dot(v, v))


def rows_dot(m: FloatArray, v: FloatArray) -> FloatArray:
    """Each row of ``m`` (n, k) dotted with ``v`` (k,): the (n,) array ``m @ v``."""
    return np.add.reduce(np.multiply(m, v), axis=-1)


def rotate(points: FloatArray, heading: float) -> FloatArray:
    """Plane points (n, 2) turned by ``heading`` rad, from the first axis toward the
    second: ``points @ [[c, s], [-s, c]]``."""
    p = np.asarray(points, dtype=np.float64)
    c, s = math.cos(heading), math.sin(heading)
    return np.stack([p[:, 0] * c - p[:, 1] * s, p[:, 0] * s + p[:, 1] * c], axis=-1)

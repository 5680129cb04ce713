"""Discrete elastic rod (DER) core: numba kernels on arrays.

Conventions shared by every module in this package (one layout everywhere):

* ``n_nodes`` nodes x_0 .. x_{n_nodes-1}; ``n_edges = n_nodes - 1``; edge j joins
  x_j and x_{j+1} and carries the material angle theta_j.
* The DOF vector interleaves them (docs/model.md §3):
  ``q = [x0 y0 z0 th0 x1 y1 z1 th1 ... x_{N-1} y_{N-1} z_{N-1}]``,
  so ``n_dof = 4 * n_nodes - 1``; node i lives at ``q[4i:4i+3]``, edge j's
  angle at ``q[4j+3]``.
* Arrays on edges have leading dimension ``n_edges`` (tangents, d1, d2, m1, m2,
  rest_lengths); arrays on interior vertices (Voronoi quantities: kb, kappa,
  ref_twist, voronoi_lengths) have leading dimension ``n_nodes`` and entries 0
  and n_nodes-1 are unused, so that index i means node i everywhere.
* Jacobians use LAPACK general-band storage with ``KL = KU = 10``:
  ``ab`` has shape ``(2*KL + KU + 1, n_dof)`` and A[i, j] is stored at
  ``ab[KL + KU + i - j, j]``; the top KL rows are workspace for the fill-in
  of the pivoted LU (see ``banded.py``).
* Kernels are ``@njit(cache=True)``, serial, no fastmath; they write into
  arrays owned by the caller.
"""

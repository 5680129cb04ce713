"""Plane geometry of keep-out polygons, in the substrate plane (x, z), one home for it.

A polygon is a (k, 2) float array of vertices (k >= 3), closed implicitly (the last
vertex joins the first). Used by the score (trace points laid inside a keep-out are
shorts), the observation (the keep-out point nearest the contact) and the route
follower (its plan around keep-outs).

* :func:`nearest_on_boundary`: for each of n points, the nearest point of one polygon's
  boundary and its distance (the projection on each edge, clipped to the edge);
* :func:`nearest_on_polygons`: the nearest boundary point over several polygons;
* :func:`outward_normal`: the outward normal of the edge nearest a point;
* :func:`inside_polygon` / :func:`in_polygons` (polygons packed by :func:`pack`): the
  even-odd rule (a point is inside when a ray along +x crosses the boundary an odd number
  of times), in one compiled kernel; :func:`length_in_polygons`: the length of a
  polyline inside them;
* :func:`segments_cross` / :func:`segment_distance`: whether two segments properly cross,
  and the distance between them (0 when they meet); used to check a route's parts
  against one another (``routes.Route``);
* :func:`in_pad_strips`: the points in a pad's electrode (the strip within a half-width
  of its segment, flat ends), as the image shows it (raster); the score's compiled test
  of a trace segment entering it is ``scoring._touches_strip``, and the top view
  (``plotting.topview``, a lower layer) draws its corners.
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit

from cnt_env import numerics

__all__ = [
    "FAR",
    "in_pad_strips",
    "in_polygons",
    "inside_polygon",
    "length_in_polygons",
    "nearest_on_boundary",
    "nearest_on_polygons",
    "outward_normal",
    "pack",
    "segment_distance",
    "segments_cross",
]

#: Offset returned by :func:`nearest_on_polygons` when there is no polygon (the
#: observation clips it to spaces.POSITION_BOUND: "no keep-out").
FAR = 1.0e6


def _edge_projections(
    points: np.ndarray, poly: np.ndarray
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """``(q, d, ab)``: each of ``points`` (n, 2) projected on each edge of ``poly`` (k, 2),
    clipped to the edge (n, k, 2), its distance (n, k), and the edges (k, 2). A
    zero-length edge (a repeated vertex) projects onto its point: t = 0, not 0 / 0."""
    a = np.asarray(poly, dtype=np.float64)
    ab = np.roll(a, -1, axis=0) - a
    den = np.einsum("kj,kj->k", ab, ab)
    t = np.einsum("nkj,kj->nk", points[:, None, :] - a[None], ab) / np.where(den > 0, den, 1.0)
    q = a[None] + np.clip(t, 0.0, 1.0)[..., None] * ab[None]
    d = np.hypot(q[..., 0] - points[:, None, 0], q[..., 1] - points[:, None, 1])
    return q, d, ab


def nearest_on_boundary(points: np.ndarray, poly: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """``(near, dist)``: for each of ``points`` (n, 2), the nearest point (n, 2) of the
    boundary of ``poly`` (k, 2) and its distance (n,)."""
    q, d, _ = _edge_projections(points, poly)
    i = np.argmin(d, axis=1)
    rows = np.arange(len(points))
    return q[rows, i], d[rows, i]


def outward_normal(point: np.ndarray, poly: np.ndarray) -> np.ndarray:
    """The unit normal (2,), pointing out of ``poly``, of its edge nearest ``point``: the
    way out for a point on the boundary, where the direction from the nearest boundary
    point is undefined."""
    _, d, ab = _edge_projections(np.asarray(point, dtype=np.float64)[None], poly)
    length = np.hypot(ab[:, 0], ab[:, 1])
    e = ab[int(np.argmin(np.where(length > 0, d[0], np.inf)))]
    n = np.array([e[1], -e[0]]) / math.hypot(*e)
    step = 1e-6 * (1.0 + float(np.abs(np.asarray(poly)).max()))
    return -n if inside_polygon((point + step * n)[None], poly)[0] else n


def nearest_on_polygons(point: np.ndarray, polygons: tuple[np.ndarray, ...]) -> np.ndarray:
    """The point of the polygons' boundaries nearest ``point`` (2,); ``point`` + FAR when
    there is none."""
    best, best_d = point + FAR, np.inf
    for poly in polygons:
        near, d = nearest_on_boundary(point[None], poly)
        if d[0] < best_d:
            best, best_d = near[0], d[0]
    return best


@njit(cache=True)
def _in_any(px, pz, verts, starts):  # pragma: no cover - numba
    """Whether (px, pz) lies inside one of the packed polygons, by the even-odd rule."""
    for k in range(starts.shape[0] - 1):
        a, b = starts[k], starts[k + 1]
        inside = False
        for j in range(a, b):
            jj = j + 1 if j + 1 < b else a
            x0, z0, x1, z1 = verts[j, 0], verts[j, 1], verts[jj, 0], verts[jj, 1]
            # the edge straddles the ray's z, and crosses it at x > px
            if (z0 > pz) != (z1 > pz) and px < x0 + (pz - z0) * (x1 - x0) / (z1 - z0):
                inside = not inside
        if inside:
            return True
    return False


@njit(cache=True)
def _inside_any(points, verts, starts, out):  # pragma: no cover - numba
    """``out[i]`` = points[i] lies inside one of the polygons (vertices ``verts``, polygon
    k from ``starts[k]`` to ``starts[k + 1]``), by the even-odd rule."""
    for i in range(points.shape[0]):
        out[i] = _in_any(points[i, 0], points[i, 1], verts, starts)


@njit(cache=True)
def _length_inside(points, verts, starts):  # pragma: no cover - numba
    """Length of the polyline ``points`` inside the union of the packed polygons: each
    segment is cut where it crosses an edge, and a piece counts when its midpoint is
    inside (exact for any node spacing; a wall thinner than it is not skipped)."""
    total = 0.0
    ts = np.empty(verts.shape[0] + 2)
    for i in range(points.shape[0] - 1):
        cx, cz = points[i, 0], points[i, 1]
        ux, uz = points[i + 1, 0] - cx, points[i + 1, 1] - cz
        length = math.sqrt(ux * ux + uz * uz)
        if length == 0.0:
            continue
        ts[0], ts[1] = 0.0, 1.0
        n = 2
        for k in range(starts.shape[0] - 1):
            a, b = starts[k], starts[k + 1]
            for j in range(a, b):
                jj = j + 1 if j + 1 < b else a
                x0, z0 = verts[j, 0], verts[j, 1]
                ex, ez = verts[jj, 0] - x0, verts[jj, 1] - z0
                den = ux * ez - uz * ex
                if den == 0.0:  # parallel: the pieces' midpoints decide
                    continue
                t = ((x0 - cx) * ez - (z0 - cz) * ex) / den
                s = ((x0 - cx) * uz - (z0 - cz) * ux) / den
                if 0.0 < t < 1.0 and 0.0 <= s <= 1.0:
                    ts[n] = t
                    n += 1
        cuts = np.sort(ts[:n])
        for m in range(n - 1):
            t0, t1 = cuts[m], cuts[m + 1]
            if t1 > t0:
                tm = 0.5 * (t0 + t1)
                if _in_any(cx + tm * ux, cz + tm * uz, verts, starts):
                    total += (t1 - t0) * length
    return total


def pack(polygons: tuple[np.ndarray, ...]) -> tuple[np.ndarray, np.ndarray]:
    """``(verts, starts)``: the polygons' vertices stacked (m, 2) and where each begins,
    with the total m at the end (the layout of :func:`in_polygons`)."""
    if not polygons:
        return np.zeros((0, 2)), np.zeros(1, dtype=np.int64)
    verts = np.ascontiguousarray(np.concatenate(polygons), dtype=np.float64)
    starts = np.concatenate([[0], np.cumsum([len(k) for k in polygons])]).astype(np.int64)
    return verts, starts


def inside_polygon(points: np.ndarray, poly: np.ndarray) -> np.ndarray:
    """Boolean (n,): which of ``points`` (n, 2) lie inside ``poly`` (k, 2)."""
    verts, starts = pack((poly,))
    out = np.empty(len(points), dtype=np.bool_)
    _inside_any(np.ascontiguousarray(points, dtype=np.float64), verts, starts, out)
    return out


def length_in_polygons(points: np.ndarray, verts: np.ndarray, starts: np.ndarray) -> float:
    """Length of the polyline ``points`` (n, 2) inside the polygons packed by :func:`pack`
    (their union; the even-odd rule), cut exactly at the polygons' edges."""
    return float(_length_inside(np.ascontiguousarray(points, dtype=np.float64), verts, starts))


def in_polygons(points: np.ndarray, verts: np.ndarray, starts: np.ndarray) -> np.ndarray:
    """Boolean (n,): which of ``points`` (n, 2) lie inside any of the polygons packed by
    :func:`pack` (``verts``, ``starts``)."""
    out = np.empty(len(points), dtype=np.bool_)
    _inside_any(np.ascontiguousarray(points, dtype=np.float64), verts, starts, out)
    return out


def _orient(a: np.ndarray, b: np.ndarray, c: np.ndarray) -> float:
    """Twice the signed area of the triangle (a, b, c): > 0 when c is left of a -> b."""
    return float((b[0] - a[0]) * (c[1] - a[1]) - (b[1] - a[1]) * (c[0] - a[0]))


def segments_cross(p0: np.ndarray, p1: np.ndarray, q0: np.ndarray, q1: np.ndarray) -> bool:
    """Whether segments p0-p1 and q0-q1 cross at a point interior to both (each
    segment's ends strictly on opposite sides of the other's line; touching is not
    crossing)."""
    d1, d2 = _orient(q0, q1, p0), _orient(q0, q1, p1)
    d3, d4 = _orient(p0, p1, q0), _orient(p0, p1, q1)
    return d1 * d2 < 0 and d3 * d4 < 0


def _point_segment_distance(p: np.ndarray, a: np.ndarray, b: np.ndarray) -> float:
    """The distance from point p to segment a-b (a == b allowed)."""
    ab = b - a
    den = numerics.dot(ab, ab)
    t = 0.0 if den == 0.0 else min(max(numerics.dot(p - a, ab) / den, 0.0), 1.0)
    return float(np.hypot(*(a + t * ab - p)))


def segment_distance(p0: np.ndarray, p1: np.ndarray, q0: np.ndarray, q1: np.ndarray) -> float:
    """The distance between segments p0-p1 and q0-q1: 0 when they cross, else the least
    distance from an end of one to the other."""
    if segments_cross(p0, p1, q0, q1):
        return 0.0
    pairs = ((p0, q0, q1), (p1, q0, q1), (q0, p0, p1), (q1, p0, p1))
    return min(_point_segment_distance(*pair) for pair in pairs)


def in_pad_strips(points: np.ndarray, pads: np.ndarray, half: float) -> np.ndarray:
    """Which ``points`` (n, 2) lie in any pad's electrode (pads (p, 2, 2)): along the pad
    within [0, length], across it within ``half`` (edges included)."""
    hit = np.zeros(len(points), dtype=bool)
    for a, b in pads:
        e = b - a
        length = float(np.hypot(*e))
        if length == 0.0:
            continue
        e = e / length
        d = points - a
        u = numerics.rows_dot(d, e)
        v = d[:, 1] * e[0] - d[:, 0] * e[1]
        hit |= (u >= 0.0) & (u <= length) & (np.abs(v) <= half)
    return hit

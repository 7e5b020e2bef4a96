"""Garment-body association: each garment vertex's nearest place on the unposed body.

docs/method.md's indicator matrix ``I`` (one body vertex per garment vertex) and the skinning
tier's surface binding (triangle + barycentric coordinates) come from one query, stored
once per garment-body pair. Shape letters: N garment vertices, V body vertices, F body
triangles.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy.spatial import cKDTree

from .mesh import cross

__all__ = ["Association", "associate", "closest_point_on_triangles", "incident_faces", "on_triangles", "surface_at"]


@dataclass(frozen=True)
class Association:
    """Where each garment vertex sits relative to the unposed body surface."""

    triangle: np.ndarray
    """(N,) int64 index of the nearest body triangle."""
    barycentric: np.ndarray
    """(N, 3) float64 barycentric coordinates of the nearest surface point in it."""
    vertex: np.ndarray
    """(N,) int64 nearest body vertex (docs/method.md's indicator ``I``)."""
    distance: np.ndarray
    """(N,) float64 distance [m] from the garment vertex to the body surface."""


def closest_point_on_triangles(tri: np.ndarray, p: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Closest point on each triangle to each point, pairwise (Ericson, RTCD 5.1.5).

    Args:
        tri: (P, 3, 3) triangle corners [m].
        p: (P, 3) query points [m].
    Returns:
        ``(closest (P, 3) [m], barycentric (P, 3))``.
    """
    a, b, c = tri[:, 0], tri[:, 1], tri[:, 2]
    ab, ac, ap = b - a, c - a, p - a
    d1 = np.einsum("ij,ij->i", ab, ap)
    d2 = np.einsum("ij,ij->i", ac, ap)
    bp = p - b
    d3 = np.einsum("ij,ij->i", ab, bp)
    d4 = np.einsum("ij,ij->i", ac, bp)
    cp = p - c
    d5 = np.einsum("ij,ij->i", ab, cp)
    d6 = np.einsum("ij,ij->i", ac, cp)
    va = d3 * d6 - d5 * d4
    vb = d5 * d2 - d1 * d6
    vc = d1 * d4 - d3 * d2
    with np.errstate(divide="ignore", invalid="ignore"):
        denom = va + vb + vc
        v = np.where(denom != 0, vb / denom, 0.0)
        w = np.where(denom != 0, vc / denom, 0.0)
        bary = np.stack([1 - v - w, v, w], axis=1)
        # Edge regions, then vertex regions: later assignments win, as in the branchy original.
        t_ab = np.clip(d1 / (d1 - d3), 0, 1)
        t_ac = np.clip(d2 / (d2 - d6), 0, 1)
        t_bc = np.clip((d4 - d3) / ((d4 - d3) + (d5 - d6)), 0, 1)
    on_ab = (vc <= 0) & (d1 >= 0) & (d3 <= 0)
    on_ac = (vb <= 0) & (d2 >= 0) & (d6 <= 0)
    on_bc = (va <= 0) & ((d4 - d3) >= 0) & ((d5 - d6) >= 0)
    bary[on_ab] = np.stack([1 - t_ab, t_ab, np.zeros_like(t_ab)], axis=1)[on_ab]
    bary[on_ac] = np.stack([1 - t_ac, np.zeros_like(t_ac), t_ac], axis=1)[on_ac]
    bary[on_bc] = np.stack([np.zeros_like(t_bc), 1 - t_bc, t_bc], axis=1)[on_bc]
    at_a = (d1 <= 0) & (d2 <= 0)
    at_b = (d3 >= 0) & (d4 <= d3)
    at_c = (d6 >= 0) & (d5 <= d6)
    bary[at_a] = (1.0, 0.0, 0.0)
    bary[at_b] = (0.0, 1.0, 0.0)
    bary[at_c] = (0.0, 0.0, 1.0)
    # Degenerate (zero-area or collinear) triangles: the region tests above run on
    # round-off, so take the nearest of the three edges as segments instead.
    normal = cross(ab, ac)
    flat = np.einsum("ij,ij->i", normal, normal) <= 1e-14 * (
        np.einsum("ij,ij->i", ab, ab) * np.einsum("ij,ij->i", ac, ac))
    flat |= ~np.isfinite(bary).all(axis=1)
    if np.any(flat):
        bary[flat] = _nearest_edge_barycentric(tri[flat], p[flat])
    closest = np.einsum("pk,pkc->pc", bary, tri)
    return closest, bary


def _nearest_edge_barycentric(tri: np.ndarray, p: np.ndarray) -> np.ndarray:
    """(P, 3) barycentrics of the closest point on the triangle's three edge segments."""
    best_d = np.full(p.shape[0], np.inf)
    best = np.zeros((p.shape[0], 3))
    for i, j in ((0, 1), (1, 2), (2, 0)):
        a, e = tri[:, i], tri[:, j] - tri[:, i]
        ee = np.einsum("ij,ij->i", e, e)
        with np.errstate(divide="ignore", invalid="ignore", over="ignore"):
            t = np.where(ee > 0, np.einsum("ij,ij->i", p - a, e) / ee, 0.0)
        t = np.clip(np.nan_to_num(t, nan=0.0), 0.0, 1.0)
        d = np.linalg.norm(a + t[:, None] * e - p, axis=1)
        better = d < best_d
        best_d[better] = d[better]
        b = np.zeros((p.shape[0], 3))
        b[:, i], b[:, j] = 1.0 - t, t
        best[better] = b[better]
    return best


def incident_faces(faces: np.ndarray, num_vertices: int) -> np.ndarray:
    """(V, D) int64 the triangles around each vertex (rows of ``faces`` (F, 3)), padded with -1."""
    flat_v = faces.ravel()
    flat_f = np.repeat(np.arange(faces.shape[0]), 3)
    order = np.argsort(flat_v, kind="stable")
    flat_v, flat_f = flat_v[order], flat_f[order]
    counts = np.bincount(flat_v, minlength=num_vertices)
    starts = np.concatenate([[0], np.cumsum(counts)[:-1]])
    slot = np.arange(flat_v.shape[0]) - starts[flat_v]
    table = np.full((num_vertices, max(int(counts.max()), 1)), -1, dtype=np.int64)
    table[flat_v, slot] = flat_f
    return table


def surface_at(association: Association, body_vertices: np.ndarray, body_normals: np.ndarray,
               body_faces: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Each associated point's nearest body surface point and the vertex normal interpolated
    there (not renormalised), from the association's triangles and barycentric coordinates.

    Args:
        association: of N points against the body (:func:`associate`).
        body_vertices: (V, 3) that body [m]; body_normals: (V, 3) its vertex normals;
        body_faces: (F, 3) int its triangles.
    Returns:
        ``(closest (N, 3) [m], normal (N, 3))``.
    """
    return on_triangles(association.triangle, association.barycentric, body_vertices, body_normals, body_faces)


def on_triangles(triangle: np.ndarray, barycentric: np.ndarray, body_vertices: np.ndarray,
                 body_normals: np.ndarray, body_faces: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """The points at ``barycentric`` (N, 3) in the body triangles ``triangle`` (N,) and the
    vertex normal interpolated there (not renormalised): :func:`surface_at` for a stored map.

    Returns:
        ``(points (N, 3) [m], normal (N, 3))``.
    """
    corners = np.asarray(body_faces)[triangle]  # (N, 3)
    return (np.einsum("nk,nkc->nc", barycentric, np.asarray(body_vertices)[corners]),
            np.einsum("nk,nkc->nc", barycentric, np.asarray(body_normals)[corners]))


def associate(points: np.ndarray, body_vertices: np.ndarray, body_faces: np.ndarray,
              *, candidates: int = 8, chunk: int = 8192) -> Association:
    """Associate garment vertices with the nearest point of the unposed body surface.

    The nearest surface point is searched among the triangles around the
    ``candidates`` nearest body vertices, which is exact for meshes of even density.

    Args:
        points: (N, 3) garment rest points [m], canonical body frame.
        body_vertices: (V, 3) unposed shaped body [m].
        body_faces: (F, 3) int body triangles.
    """
    points = np.asarray(points, dtype=np.float64)
    tree = cKDTree(body_vertices)
    k = min(candidates, body_vertices.shape[0])
    ring = incident_faces(body_faces, body_vertices.shape[0])
    n = points.shape[0]
    triangle = np.empty(n, dtype=np.int64)
    bary = np.empty((n, 3))
    distance = np.empty(n)
    _, nearest = tree.query(points, k=1)
    for lo in range(0, n, chunk):
        hi = min(lo + chunk, n)
        p = points[lo:hi]
        _, near = tree.query(p, k=k)
        near = near.reshape(hi - lo, k)
        cand = ring[near].reshape(hi - lo, -1)  # (n, k*D), -1 padded
        valid = cand >= 0
        rows, cols = np.nonzero(valid)
        tri_idx = cand[rows, cols]
        closest, b = closest_point_on_triangles(body_vertices[body_faces[tri_idx]], p[rows])
        d2 = np.full(cand.shape, np.inf)
        d2[rows, cols] = np.einsum("ij,ij->i", closest - p[rows], closest - p[rows])
        best = np.argmin(d2, axis=1)
        pick = np.full(cand.shape, -1, dtype=np.int64)
        pick[rows, cols] = np.arange(rows.shape[0])
        sel = pick[np.arange(hi - lo), best]
        triangle[lo:hi] = tri_idx[sel]
        bary[lo:hi] = b[sel]
        distance[lo:hi] = np.sqrt(d2[np.arange(hi - lo), best])
    return Association(triangle=triangle, barycentric=bary,
                       vertex=np.asarray(nearest, dtype=np.int64), distance=distance)

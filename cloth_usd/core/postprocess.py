"""docs/method.md's post-process: push garment vertices out of the body.

A garment vertex that penetrates the body, or sits closer than ``margin`` to it, is moved
out along the normal of a body vertex ``b`` until it is ``margin`` in front of that
vertex's tangent plane: ``s = dot(p - b, n)``; if ``s < margin``: ``p += (margin - s) n``.
The body vertex is the one nearest to the garment vertex in that frame, among the body
under the garment (:func:`nearest_body_points`; the candidates are
:attr:`~cloth_usd.core.pipeline.BodyPatch.contact`): a vertex that slid along the body, or
a skirt swung into the other thigh, is measured against the body under it, not against the
body vertex it was bound to at rest. Shape letters: T frames, N garment vertices, K
candidate body vertices.
"""

from __future__ import annotations

import numpy as np

from ..errors import ArgumentError

__all__ = ["push_out", "nearest_vertex", "nearest_body_points", "garment_margin", "DEFAULT_MARGIN", "LIMB_RADIUS",
           "SEARCH_REACH"]

#: Default clearance from the body surface [m] (2 mm).
DEFAULT_MARGIN = 0.002
#: The radius of the thinnest body part a garment wraps [m] (a shin, a forearm): what
#: :func:`garment_margin` sizes the clearance for.
LIMB_RADIUS = 0.045


def push_out(points: np.ndarray, body_points: np.ndarray, body_normals: np.ndarray, *,
             margin: float = DEFAULT_MARGIN) -> tuple[np.ndarray, np.ndarray]:
    """Push penetrating (or too close) garment vertices out along the body normal.

    Args:
        points: (T, N, 3) garment points [m].
        body_points: (T, N, 3) each garment vertex's associated posed body vertex [m].
        body_normals: (T, N, 3) unit outward normals at those body vertices (a zero
            normal leaves its vertex unmoved).
        margin: clearance [m] to keep in front of the body's tangent plane.
    Returns:
        ``(points (T, N, 3) float64 [m], moved (T,) int64)``: the corrected points (a new
        array) and how many vertices moved in each frame.
    """
    p = np.asarray(points, dtype=np.float64)
    b = np.asarray(body_points, dtype=np.float64)
    n = np.asarray(body_normals, dtype=np.float64)
    if p.ndim != 3 or p.shape[-1] != 3 or b.shape != p.shape or n.shape != p.shape:
        raise ArgumentError(f"points, body_points and body_normals must all be (T, N, 3), got "
                            f"{p.shape}, {b.shape}, {n.shape}")
    if not margin >= 0:
        raise ArgumentError(f"margin must be >= 0 [m], got {margin}")
    s = np.einsum("tnc,tnc->tn", p - b, n)
    live = np.einsum("tnc,tnc->tn", n, n) > 0
    push = np.where(live & (s < margin), margin - s, 0.0)
    return p + push[..., None] * n, np.count_nonzero(push > 0, axis=1).astype(np.int64)


#: A garment vertex further than this [m] from every candidate body vertex is neither inside
#: the body nor near it (:func:`nearest_body_points` does not search further: the search
#: costs a third as much).
SEARCH_REACH = 0.05


def nearest_vertex(points: np.ndarray, candidates: np.ndarray, *, reach: float = np.inf) -> np.ndarray:
    """(T, N) int64 each point's nearest candidate in its frame; ``K`` (one past the last
    candidate) where none lies within ``reach`` [m] or the point is not finite.

    Args:
        points: (T, N, 3) garment points [m].
        candidates: (T, K, 3) the posed body vertices searched [m].
    """
    from scipy.spatial import cKDTree

    p = np.asarray(points, dtype=np.float64)
    c = np.asarray(candidates, dtype=np.float64)
    index = np.full(p.shape[:2], c.shape[1], dtype=np.int64)
    for t in range(p.shape[0]):
        finite = np.isfinite(p[t]).all(axis=1)  # a non-finite vertex stays so (the guard catches it)
        if finite.any():
            index[t, finite] = cKDTree(c[t]).query(p[t, finite], distance_upper_bound=reach)[1]
    return index


def nearest_body_points(points: np.ndarray, body_points: np.ndarray, body_normals: np.ndarray, *,
                        reach: float = SEARCH_REACH) -> tuple[np.ndarray, np.ndarray]:
    """Each garment vertex's nearest body vertex in its frame, and that vertex's normal.

    Args:
        points: (T, N, 3) garment points [m].
        body_points: (T, K, 3) the candidate posed body vertices [m].
        body_normals: (T, K, 3) their unit outward normals.
        reach: a vertex with no candidate within this distance [m] gets a zero normal, which
            :func:`push_out` leaves unmoved.
    Returns:
        ``(body_points (T, N, 3), body_normals (T, N, 3))`` float64, what :func:`push_out` takes.
    """
    p = np.asarray(points, dtype=np.float64)
    b = np.asarray(body_points, dtype=np.float64)
    n = np.asarray(body_normals, dtype=np.float64)
    if p.ndim != 3 or b.ndim != 3 or b.shape != n.shape or b.shape[0] != p.shape[0] or b.shape[1] == 0:
        raise ArgumentError(f"points (T, N, 3), body_points and body_normals (T, K, 3) with K > 0 expected, got "
                            f"{p.shape}, {b.shape}, {n.shape}")
    index = nearest_vertex(p, b, reach=reach)
    found = index < b.shape[1]
    rows, index = np.arange(p.shape[0])[:, None], np.where(found, index, 0)
    return b[rows, index], n[rows, index] * found[..., None]


def garment_margin(rest_points: np.ndarray, faces: np.ndarray, *, base: float = DEFAULT_MARGIN,
                   radius: float = LIMB_RADIUS) -> float:
    """The clearance [m] that keeps a garment's triangles, not only its vertices, off the body.

    Pushed out to ``margin`` at its vertices, a flat triangle spanning a curved limb still
    has the limb bulging through its middle by the sagitta ``r - sqrt(r^2 - c^2 / 4)`` of its
    edge ``c`` over the limb's radius ``r``: 4.7 mm for the 4 cm edges of a 1000-vertex garment
    on a shin, where the body showed through a tight trouser leg in a close-up render. So the
    margin is the larger of ``base`` and that sagitta at the median edge length.

    Args:
        rest_points: (N, 3) the rest garment [m]; faces: (M, 3) int its triangles.
        base: the smallest clearance [m]; radius: the limb radius [m].
    """
    p = np.asarray(rest_points, dtype=np.float64)
    f = np.asarray(faces, dtype=np.int64)
    if f.size == 0:
        return float(base)
    edges = np.concatenate([f[:, [0, 1]], f[:, [1, 2]], f[:, [2, 0]]])
    c = float(np.median(np.linalg.norm(p[edges[:, 0]] - p[edges[:, 1]], axis=1)))
    half = min(0.5 * c, radius)
    return max(float(base), radius - float(np.sqrt(radius * radius - half * half)))

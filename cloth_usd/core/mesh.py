"""Mesh operations on vertex arrays (numpy/scipy only): uniform Laplacian smoothing, vector lengths,
cross products and a mesh's open edges."""

from __future__ import annotations

import numpy as np
from scipy import sparse

__all__ = ["laplacian_smooth", "neighbour_mean", "TAUBIN_LAMBDA", "TAUBIN_MU", "vector_lengths",
           "cross", "open_edges", "boundary_vertices", "edge_components"]


def vector_lengths(v: np.ndarray) -> np.ndarray:
    """(...) the lengths of the 3-vectors ``v`` (..., 3): ``np.linalg.norm(v, axis=-1)``, in ``v``'s
    float dtype, computed component by component. numpy reduces a last axis of 3 slowly: the
    lengths of a 4000-vertex shirt's 12000 edges in four frames (float32) take 0.09 ms this way
    and 1.03 ms through ``np.linalg.norm``, which the detail tier's strain limit called sixteen
    times a batch."""
    v = np.asarray(v)
    return np.sqrt(v[..., 0] * v[..., 0] + v[..., 1] * v[..., 1] + v[..., 2] * v[..., 2])


def cross(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """(..., 3) the cross products of the 3-vectors ``a`` and ``b`` (..., 3): ``np.cross(a, b)``, the
    same values, computed component by component. ``np.cross`` moves the last axis to the front and
    back: for (4, 13922, 3) arrays (the triangles of a posed body patch in a batch of four frames, whose
    normals every batch of a learned tier takes) it takes 1.63 ms, this 0.35 ms."""
    a, b = np.asarray(a), np.asarray(b)
    out = np.empty(np.broadcast_shapes(a.shape, b.shape), dtype=np.result_type(a, b))
    out[..., 0] = a[..., 1] * b[..., 2] - a[..., 2] * b[..., 1]
    out[..., 1] = a[..., 2] * b[..., 0] - a[..., 0] * b[..., 2]
    out[..., 2] = a[..., 0] * b[..., 1] - a[..., 1] * b[..., 0]
    return out


def open_edges(faces: np.ndarray) -> np.ndarray:
    """(B', 2) int64 the open edges of triangles ``faces`` (M, 3), each an edge of one triangle only
    (a garment's hems, cuffs and neckline), sorted, lower vertex first."""
    f = np.asarray(faces, dtype=np.int64).reshape(-1, 3)
    edges = np.sort(np.concatenate([f[:, [0, 1]], f[:, [1, 2]], f[:, [2, 0]]]), axis=1)
    uniq, counts = np.unique(edges, axis=0, return_counts=True)
    return uniq[counts == 1]


def boundary_vertices(faces: np.ndarray) -> np.ndarray:
    """(B,) int64 the sorted vertices on the :func:`open_edges` of triangles ``faces`` (M, 3)."""
    return np.unique(open_edges(faces))


def neighbour_mean(faces: np.ndarray, n: int) -> sparse.csr_matrix:
    """(N, N) row-normalised adjacency of ``n`` vertices joined by triangles ``faces`` (M, 3): ``A @ x`` is each
    vertex's neighbour mean (what :func:`laplacian_smooth` steps towards)."""
    faces = np.asarray(faces, dtype=np.int64)
    e = np.concatenate([faces[:, [0, 1]], faces[:, [1, 2]], faces[:, [2, 0]]])
    e = np.unique(np.sort(e, axis=1), axis=0)
    rows = np.concatenate([e[:, 0], e[:, 1]])
    cols = np.concatenate([e[:, 1], e[:, 0]])
    adj = sparse.csr_matrix((np.ones(rows.shape[0]), (rows, cols)), shape=(n, n))
    deg = np.asarray(adj.sum(axis=1)).ravel()
    return sparse.diags(1.0 / np.maximum(deg, 1.0)) @ adj


#: Taubin's lambda|mu steps (:func:`laplacian_smooth`): the coarse ground truth's smoothing and the one over a
#: garment's own model's displacement (:data:`~cloth_usd.core.pipeline.OWN_SMOOTHING`).
TAUBIN_LAMBDA, TAUBIN_MU = 0.5, -0.53


def laplacian_smooth(positions: np.ndarray, faces: np.ndarray, *, iterations: int = 10,
                     lam: float = 0.5, mu: float = 0.0, mean: sparse.csr_matrix | None = None) -> np.ndarray:
    """Uniform Laplacian smoothing, ``x <- x + lam (mean(neighbours) - x)``, per frame.

    With ``mu < 0`` every pass is followed by a second one of step ``mu`` (Taubin's
    lambda|mu smoothing): it removes the same fine detail without shrinking the mesh.

    Args:
        positions: (T, N, 3) or (N, 3) vertices [m].
        faces: (M, 3) int triangles.
        mu: the step of the inflating pass (0: none, plain Laplacian smoothing).
        mean: :func:`neighbour_mean` of ``faces``, when the caller made it already (a frame's smoothing costs
            less than making it).
    Returns:
        The smoothed vertices, same shape, float32 when the input is float32.
    """
    pos = np.asarray(positions)
    single = pos.ndim == 2
    x = (pos[None] if single else pos).astype(np.float64)
    num_t, n = x.shape[:2]
    avg = neighbour_mean(faces, n) if mean is None else mean
    flat = x.transpose(1, 0, 2).reshape(n, num_t * 3)  # all frames in one sparse product
    for _ in range(iterations):
        flat = flat + lam * (avg @ flat - flat)
        if mu:
            flat = flat + mu * (avg @ flat - flat)
    out = flat.reshape(n, num_t, 3).transpose(1, 0, 2).astype(pos.dtype if pos.dtype == np.float32 else np.float64)
    return out[0] if single else out


def edge_components(num: int, edges: np.ndarray) -> np.ndarray:
    """(num,) the connected part of each of ``num`` vertices joined by ``edges`` (E, 2)."""
    from scipy.sparse.csgraph import connected_components

    adj = sparse.coo_matrix((np.ones(len(edges)), (edges[:, 0], edges[:, 1])), shape=(num, num))
    return connected_components(adj, directed=False)[1]

"""Node features of the learned tiers (docs/method.md), numpy only.

The coarse model reads, per garment vertex, its associated posed body vertex: normal,
position with the root translation removed, and the fit attribute a1; a model trained with
contact features also reads where the body nearest to the garment vertex's base point is
(:func:`contact_features`: that body vertex's normal and the base point's signed distance
to its tangent plane), which is how it sees an arm swung into the shirt. The detail model
reads, per vertex of the coarse garment: normal, position with the root translation
removed, and the distance to each of the 24 posed joints. The attribute parser reads
(alpha, beta, theta) per frame. Feature order is the exported models' input contract
(:mod:`cloth_usd.runtime.io`). Shape letters: T frames, N garment vertices, V body (or
any mesh's) vertices, M triangles, J joints (24).
"""

from __future__ import annotations

import numpy as np
from scipy import sparse

from ..errors import ArgumentError
from .mesh import cross, vector_lengths
from .postprocess import nearest_vertex
from .smpl import NUM_JOINTS

__all__ = ["vertex_normals", "coarse_features", "contact_features", "detail_features", "attributes",
           "COARSE_FEATURES", "CONTACT_FEATURES", "CONTACT_REACH", "DETAIL_FEATURES", "ATTRIBUTE_FEATURES",
           "NUM_BETAS"]

#: Coarse node features: body normal (3), body position minus root translation (3), a1 (1).
COARSE_FEATURES = 7
#: Contact features (:func:`contact_features`): nearest body normal (3), signed distance (1).
CONTACT_FEATURES = 4
#: How far [m] :func:`contact_features` looks for the body (so its signed distances lie in
#: +-this); a point with no body vertex this close reads a zero normal and +this.
CONTACT_REACH = 0.05
#: Detail node features: normal (3), position minus root translation (3), 24 joint distances.
DETAIL_FEATURES = 3 + 3 + NUM_JOINTS
#: SMPL shape coefficients the parser reads.
NUM_BETAS = 10
#: Parser input: alpha (3) + beta (10) + theta (72).
ATTRIBUTE_FEATURES = 3 + NUM_BETAS + 3 * NUM_JOINTS


def _incidence(faces: np.ndarray, num_vertices: int) -> sparse.csr_matrix:
    """(V, M) sparse 0/1 matrix: vertex v is a corner of triangle m (degenerate corners once each)."""
    m = faces.shape[0]
    rows = faces.ravel()
    cols = np.repeat(np.arange(m), 3)
    return sparse.csr_matrix((np.ones(rows.shape[0]), (rows, cols)), shape=(num_vertices, m))


def vertex_normals(points: np.ndarray, faces: np.ndarray) -> np.ndarray:
    """Area-weighted unit vertex normals.

    Each vertex sums the unnormalised normals (cross products, length twice the area) of
    the triangles around it, so zero-area triangles add nothing; a vertex whose sum is
    zero (isolated, or only degenerate triangles around it) gets the zero vector, never NaN.

    Args:
        points: (V, 3) or (T, V, 3) float vertex positions [m].
        faces: (M, 3) int triangles (counter-clockwise seen from outside).
    Returns:
        Same shape as ``points``, float64 unit normals (or zero).
    """
    pts = np.asarray(points, dtype=np.float64)
    faces = np.asarray(faces, dtype=np.int64)
    if pts.ndim not in (2, 3) or pts.shape[-1] != 3:
        raise ArgumentError(f"points must be (V, 3) or (T, V, 3), got {pts.shape}")
    if faces.ndim != 2 or faces.shape[1] != 3:
        raise ArgumentError(f"faces must be (M, 3), got {faces.shape}")
    single = pts.ndim == 2
    p = pts[None] if single else pts
    num_t, num_v = p.shape[:2]
    a, b, c = p[:, faces[:, 0]], p[:, faces[:, 1]], p[:, faces[:, 2]]
    face_n = cross(b - a, c - a)  # (T, M, 3), |.| = 2 area
    summed = _incidence(faces, num_v) @ face_n.transpose(1, 0, 2).reshape(faces.shape[0], -1)
    summed = np.asarray(summed).reshape(num_v, num_t, 3).transpose(1, 0, 2)
    length = vector_lengths(summed)[..., None]
    out = np.divide(summed, length, out=np.zeros_like(summed), where=length > 1e-20)
    return out[0] if single else out


def coarse_features(posed_body: np.ndarray, body_normals: np.ndarray, assoc_vertex: np.ndarray,
                    transl: np.ndarray, a1: float) -> np.ndarray:
    """The coarse model's node features on the associated body vertices.

    Args:
        posed_body: (T, V, 3) posed body vertices [m], world frame (``transl`` included).
        body_normals: (T, V, 3) their unit normals.
        assoc_vertex: (N,) int associated body vertex of each garment vertex (docs/method.md's I).
        transl: (T, 3) root translation [m] (SMPL ``transl``), removed from positions.
        a1: the first fit factor of the garment-body pair.
    Returns:
        (T, N, 7) float64: body normal (3), body position minus ``transl`` [m] (3), a1 (1).
    """
    idx = np.asarray(assoc_vertex, dtype=np.int64)
    pos = np.asarray(posed_body)[:, idx] - np.asarray(transl, dtype=np.float64)[:, None, :]
    fit = np.full(pos.shape[:2] + (1,), float(a1))
    return np.concatenate([np.asarray(body_normals)[:, idx], pos, fit], axis=-1)


def contact_features(points: np.ndarray, body_points: np.ndarray, body_normals: np.ndarray, *,
                     reach: float = CONTACT_REACH, trees: list | None = None) -> np.ndarray:
    """Where the body nearest to each point is: the contact features of the coarse model.

    Per frame, each point's nearest body vertex ``b`` (among ``body_points``, within
    ``reach``), its unit normal ``n`` and the point's signed distance ``dot(p - b, n)`` to
    its tangent plane (negative: behind it, inside the body; within ``+-reach``, as ``b`` is).
    A point with no body vertex within ``reach``, or not finite, reads ``n = 0`` and
    ``+reach``, as if far in front of the body. The normal turns with the body and the
    distance does not change: any frame the body and the points share gives the same.

    Args:
        points: (T, N, 3) the garment the coarse displacement is added to [m].
        body_points: (T, K, 3) the candidate posed body vertices [m] (the body under the garment).
        body_normals: (T, K, 3) their unit outward normals.
        reach: search radius [m].
        trees: T :func:`~cloth_usd.core.postprocess.search_tree` over each frame's
            ``body_points``, when the caller built them already (the post-process searches the
            same body).
    Returns:
        (T, N, 4) float64: normal (3), signed distance [m] (1).
    """
    p = np.asarray(points, dtype=np.float64)
    b = np.asarray(body_points, dtype=np.float64)
    n = np.asarray(body_normals, dtype=np.float64)
    if p.ndim != 3 or p.shape[-1] != 3 or b.ndim != 3 or b.shape != n.shape or b.shape[0] != p.shape[0] \
            or b.shape[1] == 0 or (trees is not None and len(trees) != p.shape[0]):
        raise ArgumentError(f"points (T, N, 3), body_points and body_normals (T, K, 3) with K > 0 (and T trees) "
                            f"expected, got {p.shape}, {b.shape}, {n.shape}")
    index = nearest_vertex(p, b, reach=reach, trees=trees)
    found = index < b.shape[1]
    rows, index = np.arange(p.shape[0])[:, None], np.where(found, index, 0)
    normal = n[rows, index] * found[..., None]
    with np.errstate(invalid="ignore"):  # a non-finite point reads as far; its NaN is dropped below
        distance = np.einsum("tnc,tnc->tn", p - b[rows, index], normal)
    return np.concatenate([normal, np.where(found, distance, reach)[..., None]], axis=-1)


def detail_features(coarse: np.ndarray, garment_faces: np.ndarray, posed_joints: np.ndarray,
                    transl: np.ndarray) -> np.ndarray:
    """The detail model's node features on the coarse garment.

    Args:
        coarse: (T, N, 3) coarse garment points [m], world frame (``transl`` included).
        garment_faces: (M, 3) int garment triangles.
        posed_joints: (T, 24, 3) posed joints [m], the same world frame as ``coarse``.
        transl: (T, 3) root translation [m], removed from positions.
    Returns:
        (T, N, 30) float64: vertex normal (3), position minus ``transl`` [m] (3), distance
        to each of the 24 joints [m] (24).
    """
    coarse = np.asarray(coarse, dtype=np.float64)
    joints = np.asarray(posed_joints, dtype=np.float64)
    if joints.shape[1:] != (NUM_JOINTS, 3):
        raise ArgumentError(f"posed_joints must be (T, {NUM_JOINTS}, 3), got {joints.shape}")
    normals = vertex_normals(coarse, garment_faces)
    pos = coarse - np.asarray(transl, dtype=np.float64)[:, None, :]
    dist = vector_lengths(coarse[:, :, None, :] - joints[:, None, :, :])  # (T, N, 24)
    return np.concatenate([normals, pos, dist], axis=-1)


def attributes(alpha: np.ndarray, betas: np.ndarray, poses: np.ndarray) -> np.ndarray:
    """The attribute parser's input per frame.

    Args:
        alpha: (3,) fit attribute of the garment-body pair.
        betas: (B',) SMPL shape coefficients; zero-padded or cut to 10.
        poses: (T, 72) axis-angle [rad].
    Returns:
        (T, 85) float64: alpha (3), betas (10), pose (72).
    """
    alpha = np.asarray(alpha, dtype=np.float64).reshape(-1)
    if alpha.shape != (3,):
        raise ArgumentError(f"alpha must have 3 factors, got {alpha.shape[0]}")
    b = np.zeros(NUM_BETAS)
    betas = np.asarray(betas, dtype=np.float64).reshape(-1)[:NUM_BETAS]
    b[:betas.shape[0]] = betas
    poses = np.asarray(poses, dtype=np.float64).reshape(-1, 3 * NUM_JOINTS)
    fixed = np.broadcast_to(np.concatenate([alpha, b]), (poses.shape[0], 3 + NUM_BETAS))
    return np.concatenate([fixed, poses], axis=1)

"""The skinning tier: garment vertices carried by the body's LBS.

Each garment vertex takes the skinning weights (and pose correctives) of its nearest
body surface point, interpolated with barycentric coordinates, and is skinned from its
own rest position, so its rest offset from the body rides along. Every learned tier
must beat this baseline. Shape letters: T frames, N garment vertices, J joints.
"""

from __future__ import annotations

from dataclasses import dataclass
from functools import cached_property

import numpy as np
from scipy import sparse

from ..errors import ArgumentError
from .association import Association, associate
from .body import BodyModel, blend_skin, joint_transforms, pose_feature, shape_body
from .rotations import axis_angle_to_matrix
from .scene import Category
from .smpl import NUM_JOINTS

__all__ = ["SkinBinding", "LOWER_FREE_BEYOND", "bind_garment", "bind_worn", "harmonic_weights", "skin_garment"]

#: A dress's or trousers' vertices farther than this from the body [m] take weights
#: interpolated over the garment (:func:`bind_garment` ``free_beyond``): the skirt, or the
#: crotch, between the legs follows both legs instead of tearing where its nearest body point
#: changes leg. Measured on CMU 10_04 (``bench/bench_binding.py``): with nearest weights the
#: four dresses' and the four trousers' largest edge reaches 7.6-17x its rest length; with
#: 5 mm, 1.7-2.0x (dresses) and 2.6-3.3x (trousers); 1 cm and 2 cm leave more.
LOWER_FREE_BEYOND = 0.005


@dataclass(frozen=True)
class SkinBinding:
    """A garment bound to one body shape; computed once per garment-body pair."""

    rest_points: np.ndarray
    """(N, 3) float64 rest garment points [m], canonical body frame (zero pose, no transl)."""
    joints: np.ndarray
    """(J, 3) float64 rest joints of the shaped body [m]."""
    association: Association
    weights: np.ndarray
    """(N, J) float64 interpolated skinning weights, rows sum to 1."""
    posedirs: np.ndarray | None
    """(N, 3, 207) float64 interpolated pose correctives [m], None when the body has none."""

    @cached_property
    def sparse_weights(self) -> sparse.csr_matrix:
        """:attr:`weights` as a sparse matrix, made once: what :func:`skin_garment` multiplies by."""
        return sparse.csr_matrix(self.weights)


def bind_garment(body: BodyModel, betas: np.ndarray, rest_points: np.ndarray, *,
                 faces: np.ndarray | None = None, free_beyond: float | None = None) -> SkinBinding:
    """Associate a garment with the unposed body of shape ``betas`` and interpolate weights.

    Args:
        betas: (B',) shape coefficients.
        rest_points: (N, 3) rest garment points [m], canonical body frame.
        faces: (M, 3) int garment triangles; needed with ``free_beyond``.
        free_beyond: vertices farther than this from the body [m] take the harmonic
            interpolation of the others' weights over the garment mesh
            (:func:`harmonic_weights`) instead of their nearest body point's: a skirt hanging
            between the legs then follows both legs rather than tearing along the line where
            its nearest body point changes leg. None: every vertex its nearest point's.
    """
    v_shaped, joints = shape_body(body, betas)
    assoc = associate(rest_points, v_shaped, body.faces)
    corners = body.faces[assoc.triangle]  # (N, 3)
    weights = np.einsum("nk,nkj->nj", assoc.barycentric, body.weights[corners])
    weights /= weights.sum(axis=1, keepdims=True)
    posedirs = None
    if body.posedirs is not None:
        posedirs = np.einsum("nk,nkcp->ncp", assoc.barycentric, body.posedirs[corners])
    if free_beyond is not None:
        if faces is None:
            raise ArgumentError("bind_garment: free_beyond needs the garment's faces")
        free = assoc.distance > free_beyond
        if free.any() and not free.all():
            weights = harmonic_weights(weights, faces, free)
            weights = np.clip(weights, 0.0, None)
            weights /= weights.sum(axis=1, keepdims=True)
            if posedirs is not None:
                n = posedirs.shape[0]
                posedirs = harmonic_weights(posedirs.reshape(n, -1), faces, free).reshape(posedirs.shape)
    return SkinBinding(rest_points=np.asarray(rest_points, dtype=np.float64), joints=joints,
                       association=assoc, weights=weights, posedirs=posedirs)


def bind_worn(body: BodyModel, betas: np.ndarray, rest_points: np.ndarray, faces: np.ndarray,
              category: Category | str) -> SkinBinding:
    """:func:`bind_garment` as every tier binds a garment of ``category``, in a bake and in
    training alike: a dress's or trousers' vertices beyond :data:`LOWER_FREE_BEYOND` take
    blended weights, every other garment's vertices their nearest body point's.

    Args:
        betas: (B',) shape coefficients.
        rest_points: (N, 3) rest garment points [m], canonical body frame.
        faces: (M, 3) int garment triangles.
        category: the garment's category.
    """
    free = LOWER_FREE_BEYOND if Category(category) in (Category.DRESS, Category.TROUSERS) else None
    return bind_garment(body, betas, rest_points, faces=faces, free_beyond=free)


def harmonic_weights(values: np.ndarray, faces: np.ndarray, free: np.ndarray) -> np.ndarray:
    """Per-vertex values with the ``free`` vertices' replaced by the harmonic interpolation
    of the others' over the mesh graph (uniform Laplacian: each free vertex the mean of its
    neighbours); a free component that touches no fixed vertex keeps its values.

    Args:
        values: (N, C) float64 per-vertex values (skinning weights: rows that sum to 1 keep
            summing to 1).
        faces: (M, 3) int triangles.
        free: (N,) bool vertices to interpolate.
    Returns:
        (N, C) float64.
    """
    from scipy.sparse import csgraph, linalg as splinalg

    n = values.shape[0]
    f = np.asarray(faces, dtype=np.int64)
    i = np.concatenate([f[:, 0], f[:, 1], f[:, 2], f[:, 1], f[:, 2], f[:, 0]])
    j = np.concatenate([f[:, 1], f[:, 2], f[:, 0], f[:, 0], f[:, 1], f[:, 2]])
    adj = sparse.csr_matrix((np.ones(len(i)), (i, j)), shape=(n, n))
    adj.data[:] = 1.0  # duplicate edges summed: back to 0/1
    lap = sparse.diags(np.asarray(adj.sum(axis=1)).ravel()) - adj
    free = np.asarray(free, dtype=bool).copy()
    # a free component with no fixed vertex has no boundary condition: leave it as it is
    _, label = csgraph.connected_components(adj[free][:, free], directed=False)
    anchored = np.zeros(label.max() + 1 if label.size else 0, dtype=bool)
    touches = np.asarray(adj[free][:, ~free].sum(axis=1)).ravel() > 0
    np.logical_or.at(anchored, label, touches)
    idx = np.flatnonzero(free)
    free[idx[~anchored[label]]] = False
    if not free.any():
        return values.copy()
    out = values.astype(np.float64).copy()
    a = lap[free][:, free].tocsc()
    b = -(lap[free][:, ~free] @ out[~free])
    out[free] = splinalg.splu(a).solve(np.asarray(b))
    return out


def skin_garment(binding: SkinBinding, poses: np.ndarray, transl: np.ndarray,
                 parents: np.ndarray) -> np.ndarray:
    """Deform a bound garment for a batch of frames.

    Args:
        poses: (T, 72) axis-angle [rad].
        transl: (T, 3) root translation [m].
        parents: (J,) kinematic tree.
    Returns:
        (T, N, 3) float64 garment points [m], internal world frame.
    """
    rotmats = axis_angle_to_matrix(np.asarray(poses, dtype=np.float64).reshape(-1, NUM_JOINTS, 3))
    _, skin = joint_transforms(rotmats, binding.joints, parents)
    rest = np.broadcast_to(binding.rest_points, (rotmats.shape[0],) + binding.rest_points.shape)
    if binding.posedirs is not None:
        rest = rest + np.einsum("ncp,tp->tnc", binding.posedirs, pose_feature(rotmats))
    return blend_skin(binding.sparse_weights, skin, rest) + np.asarray(transl, dtype=np.float64)[:, None, :]

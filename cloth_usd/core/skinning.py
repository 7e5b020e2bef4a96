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

from .association import Association, associate
from .body import BodyModel, blend_skin, joint_transforms, pose_feature, shape_body
from .rotations import axis_angle_to_matrix
from .smpl import NUM_JOINTS

__all__ = ["SkinBinding", "bind_garment", "skin_garment"]


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


def bind_garment(body: BodyModel, betas: np.ndarray, rest_points: np.ndarray) -> SkinBinding:
    """Associate a garment with the unposed body of shape ``betas`` and interpolate weights.

    Args:
        betas: (B',) shape coefficients.
        rest_points: (N, 3) rest garment points [m], canonical body frame.
    """
    v_shaped, joints = shape_body(body, betas)
    assoc = associate(rest_points, v_shaped, body.faces)
    corners = body.faces[assoc.triangle]  # (N, 3)
    weights = np.einsum("nk,nkj->nj", assoc.barycentric, body.weights[corners])
    weights /= weights.sum(axis=1, keepdims=True)
    posedirs = None
    if body.posedirs is not None:
        posedirs = np.einsum("nk,nkcp->ncp", assoc.barycentric, body.posedirs[corners])
    return SkinBinding(rest_points=np.asarray(rest_points, dtype=np.float64), joints=joints,
                       association=assoc, weights=weights, posedirs=posedirs)


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

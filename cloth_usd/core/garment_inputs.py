"""What a garment's own model reads and how its output is posed (numpy; the runtime's side of
:mod:`cloth_usd.nn.garment_model`).

The model maps the pose (the 24 joints' rotation matrices minus the identity, heading taken
out of the root: :func:`pose_features`) and the body's shape (:func:`shape_features`) to a
displacement ``d`` of every vertex of one garment in its unposed frame; the garment's own
skinning then poses it (:func:`skin_displaced`):
``x_n = sum_j w_nj T_j (X_n + P_n + d_n)``, which is the skinned garment plus
``(sum_j w_nj R_j) d_n`` (:class:`SkinParts`). A bundle names the garment by its vertex count
and :func:`faces_sha256`. The model reads only the joints that move the garment
(:func:`read_joints`); the others' features reach it as zeros.
"""

from __future__ import annotations

import hashlib
from dataclasses import dataclass

import numpy as np

from .body import blend_skin, joint_transforms, pose_feature
from .rotations import axis_angle_to_matrix
from .skinning import SkinBinding
from .smpl import MIRROR_JOINTS, NUM_JOINTS, PARENTS

__all__ = ["POSE_FEATURES", "SHAPE_FEATURES", "READ_REACH", "READ_WEIGHT", "SkinParts", "faces_sha256",
           "garment_displacement_inputs", "pose_features", "read_joints", "shape_features", "skin_displaced",
           "skin_parts"]

#: Pose inputs: 24 rotation matrices minus the identity, row-major.
POSE_FEATURES = 9 * NUM_JOINTS
#: Shape inputs: the body's first 10 shape coefficients.
SHAPE_FEATURES = 10


def faces_sha256(faces: np.ndarray) -> str:
    """The garment's identity for its own bundle: sha256 of its (M, 3) triangles as int64."""
    return hashlib.sha256(np.ascontiguousarray(faces, dtype=np.int64).tobytes()).hexdigest()


#: The skinning weight from which a joint counts as moving a garment vertex, or the body under it
#: (:func:`read_joints`). On the three sample garments 0.05 and 0.1 pick the same joints.
READ_WEIGHT = 0.1
#: [m] body vertices this close to the rest garment are the body it lies on (:func:`read_joints`):
#: at 2 cm the sample dress's knees, under its skirt, and the trousers' knees and ankles; at 5 cm the
#: dress reached its head as well.
READ_REACH = 0.02


def read_joints(weights, body_weights=None) -> np.ndarray:
    """(24,) bool the joints whose rotation a garment's own model reads.

    A joint is read when it carries at least :data:`READ_WEIGHT` of the skinning weight of some
    garment vertex or of some body vertex the garment lies on (``body_weights``: a skirt bound to
    the hips lies on the thighs, and the knees swing them into it), when it is an ancestor of
    such a joint (it moves the whole chain), and when its mirror image is read (a garment's two
    sides read the same joints). The rest (a T-shirt's hands and feet, the trousers' arms and
    head) cannot move the garment; a model that reads them learns from them what its few
    training sequences happened to pair with them. The sample dress's model moved its garment by
    13.7 mm on average when the head turned 60 degrees, and the sample trousers' by 2-4.5 mm for
    each joint of an arm. Reading the children of those joints as well measured worse on both
    samples' Newton test sets (docs/models.md).

    Args:
        weights: (N, 24) the garment's skinning weights (dense, or scipy sparse).
        body_weights: (R, 24) the body's skinning weights of the body vertices within
            :data:`READ_REACH` of the rest garment (None: none).
    """
    rows = [weights.toarray() if hasattr(weights, "toarray") else np.asarray(weights, dtype=np.float64)]
    if body_weights is not None:
        rows.append(np.asarray(body_weights, dtype=np.float64))
    if any(w.ndim != 2 or w.shape[1] != NUM_JOINTS for w in rows):
        raise ValueError(f"weights must be (N, {NUM_JOINTS}), got {', '.join(str(w.shape) for w in rows)}")
    moving = np.logical_or.reduce([w.max(axis=0, initial=0.0) >= READ_WEIGHT for w in rows])
    read = moving.copy()
    for j in np.flatnonzero(moving):
        p = PARENTS[j]
        while p >= 0:
            read[p] = True
            p = PARENTS[p]
    return read | read[list(MIRROR_JOINTS)]


def pose_features(poses: np.ndarray) -> np.ndarray:
    """(T, 216) float64 the model's pose input: rotation matrices minus the identity.

    Args:
        poses: (T, 72) axis-angle [rad], heading already taken out of the root.
    """
    rot = axis_angle_to_matrix(np.asarray(poses, dtype=np.float64).reshape(-1, NUM_JOINTS, 3))
    return (rot - np.eye(3)).reshape(rot.shape[0], POSE_FEATURES)


def shape_features(betas: np.ndarray, frames: int) -> np.ndarray:
    """(T, 10) float64 the model's shape input: the first 10 coefficients, zero-padded, per frame."""
    b = np.zeros(SHAPE_FEATURES)
    given = np.asarray(betas, dtype=np.float64).ravel()[:SHAPE_FEATURES]
    b[:given.size] = given
    return np.broadcast_to(b, (frames, SHAPE_FEATURES)).copy()


def garment_displacement_inputs(canonical_poses: np.ndarray, betas: np.ndarray) -> dict[str, np.ndarray]:
    """The exported model's named inputs (:data:`cloth_usd.runtime.io.GARMENT_INPUTS`), float32.

    Args:
        canonical_poses: (T, 72) axis-angle [rad], heading taken out of the root.
        betas: (B',) the body's shape coefficients.
    """
    pose = pose_features(canonical_poses)
    return {"pose": pose.astype(np.float32), "betas": shape_features(betas, len(pose)).astype(np.float32)}


@dataclass(frozen=True)
class SkinParts:
    """What posing the displaced garment needs of a batch of frames (numpy, float64)."""

    base: np.ndarray
    """(T, N, 3) the skinned garment without displacement [m] (``transl`` included)."""
    linear: np.ndarray
    """(T, N, 3, 3) each vertex's blended joint rotation: a displacement ``d`` moves it by ``linear @ d``."""


def _unposed(binding: SkinBinding, poses: np.ndarray, parents: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """``(skin (T, J, 3, 4), unposed points with the pose correctives (T, N, 3))``."""
    rot = axis_angle_to_matrix(np.asarray(poses, dtype=np.float64).reshape(-1, NUM_JOINTS, 3))
    _, skin = joint_transforms(rot, binding.joints, parents)
    rest = np.broadcast_to(binding.rest_points, (rot.shape[0],) + binding.rest_points.shape)
    if binding.posedirs is not None:
        rest = rest + np.einsum("ncp,tp->tnc", binding.posedirs, pose_feature(rot))
    return skin, rest


def skin_parts(binding: SkinBinding, poses: np.ndarray, transl: np.ndarray, parents: np.ndarray) -> SkinParts:
    """The skinned garment of ``poses`` and how a displacement of its unposed points moves it."""
    skin, rest = _unposed(binding, poses, parents)
    base = blend_skin(binding.sparse_weights, skin, rest) + np.asarray(transl, dtype=np.float64)[:, None, :]
    t, j = skin.shape[:2]
    cols = np.ascontiguousarray(skin[..., :3].transpose(1, 0, 2, 3)).reshape(j, t * 9)
    linear = np.asarray(binding.sparse_weights @ cols).reshape(-1, t, 3, 3).transpose(1, 0, 2, 3)
    return SkinParts(base=base, linear=linear)


def skin_displaced(binding: SkinBinding, poses: np.ndarray, transl: np.ndarray, parents: np.ndarray,
                   displacement: np.ndarray) -> np.ndarray:
    """(T, N, 3) float64 the garment posed with its unposed points displaced [m]: as
    :func:`~cloth_usd.core.skinning.skin_garment`, the displacement added before skinning.

    Args:
        binding: the garment's :class:`~cloth_usd.core.skinning.SkinBinding`.
        poses: (T, 72) axis-angle [rad] (the frame the garment is wanted in).
        transl: (T, 3) root translation [m].
        displacement: (T, N, 3) in the unposed garment's frame [m].
    """
    skin, rest = _unposed(binding, poses, parents)
    points = rest + np.asarray(displacement, dtype=np.float64)
    return blend_skin(binding.sparse_weights, skin, points) + np.asarray(transl, dtype=np.float64)[:, None, :]

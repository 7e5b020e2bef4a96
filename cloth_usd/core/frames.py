"""Where a rest-posed character stands: its turn in the world, from its joints.

The scene contract says a character's rest pose is SMPL's zero pose, so its rest
joints are ``J(betas)`` moved and turned into the world. The turn is measured from
the joints themselves (the hips give the body's left, the spine its up), which holds
whatever joint orientations (bone rolls) or stage axes a rig uses.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from .rotations import axis_angle_to_matrix, matrix_to_axis_angle
from .scene import Character, Motion
from .smpl import NUM_JOINTS

__all__ = ["body_frame", "rest_orientation", "reorient_poses", "CanonicalMotion", "canonical_motion", "canonical_rest_points",
           "worn_rest_points"]

_PELVIS, _L_HIP, _R_HIP, _NECK, _L_SHOULDER, _R_SHOULDER = 0, 1, 2, 12, 16, 17


def body_frame(joints: np.ndarray) -> np.ndarray:
    """(3, 3) rotation whose columns are the body's left, up and forward axes.

    Args:
        joints: (24, 3) SMPL joint positions [m].
    """
    up = joints[_NECK] - joints[_PELVIS]
    up = up / np.linalg.norm(up)
    left = (joints[_L_HIP] - joints[_R_HIP]) + (joints[_L_SHOULDER] - joints[_R_SHOULDER])
    left = left - up * (left @ up)
    left = left / np.linalg.norm(left)
    return np.stack([left, up, np.cross(left, up)], axis=1)


def rest_orientation(rest_joints: np.ndarray, model_joints: np.ndarray) -> np.ndarray:
    """(3, 3) rotation that turns the canonical body into the world's rest pose.

    Args:
        rest_joints: (24, 3) rest joint positions in the world [m].
        model_joints: (24, 3) the body model's ``J(betas)`` [m].
    """
    return body_frame(rest_joints) @ body_frame(model_joints).T


def reorient_poses(poses: np.ndarray, turn: np.ndarray) -> np.ndarray:
    """Poses read relative to a turned rest pose, expressed from SMPL's canonical rest.

    With world deltas ``G_j`` the canonical global rotations are ``G_j @ turn``: the root
    gains the turn, the other local rotations are conjugated by it.

    Args:
        poses: (T, 72) axis-angle [rad], zero at the world's rest pose.
        turn: (3, 3) from :func:`rest_orientation`.
    Returns:
        (T, 72) axis-angle [rad], zero for a body facing +Z.
    """
    if np.allclose(turn, np.eye(3), atol=1e-9):
        return poses
    rot = axis_angle_to_matrix(poses.reshape(-1, NUM_JOINTS, 3))
    out = turn.T @ rot @ turn
    out[:, 0] = rot[:, 0] @ turn
    return matrix_to_axis_angle(out).reshape(poses.shape)


@dataclass(frozen=True)
class CanonicalMotion:
    """A character's motion expressed from SMPL's canonical rest, ready for the body model."""

    joints: np.ndarray
    """(J, 3) float64 the body model's ``J(betas)`` [m]."""
    turn: np.ndarray
    """(3, 3) float64 the character's world turn at rest (:func:`rest_orientation`)."""
    rest_root_position: np.ndarray
    """(3,) float64 the rest pelvis in the world [m]."""
    poses: np.ndarray
    """(T, 72) float64 axis-angle [rad], zero for a body facing +Z."""
    transl: np.ndarray
    """(T, 3) float64 SMPL root translation [m]."""

    def rest_points(self, world_points: np.ndarray) -> np.ndarray:
        """World rest points (a garment worn at rest) in the canonical body frame: the
        rest pelvis moved onto ``J(betas)[0]`` and the world turn undone.

        Args:
            world_points: (N, 3) [m], internal world frame.
        Returns:
            (N, 3) float64 [m], canonical body frame.
        """
        return canonical_rest_points(world_points, self.rest_root_position, self.turn, self.joints)


def canonical_rest_points(world_points: np.ndarray, rest_root_position: np.ndarray, turn: np.ndarray,
                          joints: np.ndarray) -> np.ndarray:
    """World rest points (a garment worn at rest) in the canonical body frame: the rest
    pelvis moved onto ``J(betas)[0]`` and the world turn undone.

    Args:
        world_points: (N, 3) [m], internal world frame.
        rest_root_position: (3,) the rest pelvis in the world [m].
        turn: (3, 3) the character's world turn at rest (:func:`rest_orientation`).
        joints: (J, 3) the body model's ``J(betas)`` [m].
    Returns:
        (N, 3) float64 [m], canonical body frame.
    """
    return (np.asarray(world_points, dtype=np.float64) - rest_root_position) @ turn + joints[0]


def worn_rest_points(character: Character, world_points: np.ndarray, joints: np.ndarray) -> np.ndarray:
    """A garment's world rest points, worn by ``character``, in the canonical body frame
    (:func:`canonical_rest_points` with the character's rest pelvis and turn).

    Args:
        world_points: (N, 3) [m], internal world frame.
        joints: (J, 3) the body model's ``J(betas)`` of the character's shape [m].
    """
    return canonical_rest_points(world_points, character.rest_root_position,
                                 rest_orientation(character.rest_joints, joints), joints)


def canonical_motion(character: Character, motion: Motion, joints: np.ndarray) -> CanonicalMotion:
    """Re-express a character's read motion from SMPL's canonical rest.

    Args:
        joints: (J, 3) the body model's ``J(betas)`` for ``character.betas`` [m].
    """
    turn = rest_orientation(character.rest_joints, joints)
    return CanonicalMotion(joints=joints, turn=turn, rest_root_position=character.rest_root_position,
                           poses=reorient_poses(motion.poses, turn),
                           transl=motion.root_position - joints[0])

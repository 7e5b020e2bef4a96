"""Procedural SMPL motions. Shape letters: T frames.

SMPL's frame: Y up, the body faces +Z, its left is +X; local joint rotations are in the
parent's rest-aligned frame, so flexing a hip forward is a negative rotation about X.
"""

from __future__ import annotations

import numpy as np
from scipy.spatial.transform import Rotation

from ..core.smpl import JOINT_NAMES

__all__ = ["walk_cycle", "blend_from_rest"]

_J = {name: i for i, name in enumerate(JOINT_NAMES)}


def blend_from_rest(poses: np.ndarray, frames: int) -> np.ndarray:
    """Ease the first ``frames`` frames in from the rest pose (slerp per joint).

    Args:
        poses: (T, 72) axis-angle [rad].
    Returns:
        (T, 72) poses whose frame 0 is the rest pose.
    """
    out = poses.copy()
    n = min(frames, poses.shape[0])
    for t in range(n):
        s = 0.5 - 0.5 * np.cos(np.pi * t / max(n, 1))  # smooth step 0 -> 1
        rot = Rotation.from_rotvec(poses[t].reshape(24, 3))
        out[t] = (rot.as_rotvec() * s).reshape(72)  # slerp from identity = scaled rotation vector
    return out


def walk_cycle(num_frames: int, fps: float = 24.0, *, stride_hz: float = 0.9, speed: float = 1.1,
               arm_drop: float = 1.15, blend_frames: int = 12) -> tuple[np.ndarray, np.ndarray]:
    """A walk with swinging arms and a little torso twist.

    Returns:
        ``(poses (T, 72) axis-angle [rad], root_offset (T, 3) [m])``: the root offset is
        the pelvis displacement from its rest place.
    """
    t = np.arange(num_frames) / fps
    phase = 2 * np.pi * stride_hz * t
    s, c2 = np.sin(phase), np.cos(2 * phase)
    euler = np.zeros((num_frames, 24, 3))  # per-joint xyz Euler angles
    euler[:, _J["left_hip"], 0] = -0.45 * s
    euler[:, _J["right_hip"], 0] = 0.45 * s
    euler[:, _J["left_knee"], 0] = 0.55 * np.maximum(0.0, np.sin(phase + 1.2)) + 0.05
    euler[:, _J["right_knee"], 0] = 0.55 * np.maximum(0.0, np.sin(phase + 1.2 + np.pi)) + 0.05
    euler[:, _J["left_ankle"], 0] = 0.15 * np.sin(phase - 0.6)
    euler[:, _J["right_ankle"], 0] = -0.15 * np.sin(phase - 0.6)
    euler[:, _J["spine1"], 1] = 0.10 * s
    euler[:, _J["spine3"], 1] = -0.12 * s
    euler[:, _J["spine2"], 0] = 0.05
    euler[:, _J["left_shoulder"], 2] = -arm_drop
    euler[:, _J["right_shoulder"], 2] = arm_drop
    euler[:, _J["left_shoulder"], 0] = 0.45 * s
    euler[:, _J["right_shoulder"], 0] = -0.45 * s
    euler[:, _J["left_elbow"], 1] = -0.35 - 0.2 * np.maximum(0.0, s)  # forearm forward
    euler[:, _J["right_elbow"], 1] = 0.35 + 0.2 * np.maximum(0.0, -s)
    rot = Rotation.from_euler("XYZ", euler.reshape(-1, 3))  # intrinsic: z turns first, then y, x
    poses = blend_from_rest(rot.as_rotvec().reshape(num_frames, 72), blend_frames)
    ramp = np.clip(np.arange(num_frames) / max(blend_frames, 1), 0.0, 1.0)
    root = np.zeros((num_frames, 3))
    root[:, 2] = np.cumsum(speed / fps * ramp)
    root[:, 1] = 0.02 * c2 * ramp - 0.01 * ramp
    return poses, root

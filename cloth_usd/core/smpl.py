"""SMPL's fixed facts: the 24 joint names, the kinematic tree and array sizes."""

from __future__ import annotations

import numpy as np

__all__ = ["JOINT_NAMES", "PARENTS", "MIRROR_JOINTS", "NUM_JOINTS", "NUM_BETAS", "POSE_DIM"]

#: The 24 SMPL joints, in SMPL's order (index = SMPL joint index).
JOINT_NAMES: tuple[str, ...] = (
    "pelvis", "left_hip", "right_hip", "spine1", "left_knee", "right_knee",
    "spine2", "left_ankle", "right_ankle", "spine3", "left_foot", "right_foot",
    "neck", "left_collar", "right_collar", "head", "left_shoulder",
    "right_shoulder", "left_elbow", "right_elbow", "left_wrist", "right_wrist",
    "left_hand", "right_hand",
)

#: Parent of each joint (SMPL's ``kintree_table[0]``); -1 for the root.
PARENTS: np.ndarray = np.array(
    [-1, 0, 0, 0, 1, 2, 3, 4, 5, 6, 7, 8, 9, 9, 9, 12, 13, 14, 16, 17, 18, 19, 20, 21],
    dtype=np.int64,
)
PARENTS.setflags(write=False)

#: SMPL's 24 joints with left and right swapped.
MIRROR_JOINTS = (0, 2, 1, 3, 5, 4, 6, 8, 7, 9, 11, 10, 12, 14, 13, 15, 17, 16, 19, 18, 21, 20, 23, 22)

NUM_JOINTS = 24
NUM_BETAS = 10
#: Axis-angle pose size: 24 joints x 3, joint 0 is the global orientation.
POSE_DIM = 72

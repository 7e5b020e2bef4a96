"""The hand-made BVH fixture ``data/tpose_26.bvh``: its skeleton and its known angles.

A Mixamo-named, Y-up, centimetre skeleton of 26 joints in a T-pose facing +Z: SMPL's
24 joints one to one, plus two unmapped thumbs. Running this module rewrites the file.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

PATH = Path(__file__).parent / "data" / "tpose_26.bvh"
NUM_FRAMES = 10
FRAME_TIME = 0.04  # 25 fps
ORDERS = ("ZXY", "XYZ", "YZX")  # joint j (j >= 1) uses ORDERS[j % 3]; the root uses "ZYX"

# name, parent name, offset [cm], End Site offset or None, SMPL joint or None
_LEFT = [
    ("LeftUpLeg", "Hips", (9, -8, 0), None, "left_hip"),
    ("LeftLeg", "LeftUpLeg", (0, -40, 0), None, "left_knee"),
    ("LeftFoot", "LeftLeg", (0, -42, 0), None, "left_ankle"),
    ("LeftToeBase", "LeftFoot", (0, -6, 13), (0, 0, 5), "left_foot"),
]
_SPINE = [
    ("Spine", "Hips", (0, 10, 0), None, "spine1"),
    ("Spine1", "Spine", (0, 13, 0), None, "spine2"),
    ("Spine2", "Spine1", (0, 6, 0), None, "spine3"),
    ("Neck", "Spine2", (0, 22, 0), None, "neck"),
    ("Head", "Neck", (0, 9, 0), (0, 18, 0), "head"),
]
_LEFT_ARM = [
    ("LeftShoulder", "Spine2", (4, 17, 0), None, "left_collar"),
    ("LeftArm", "LeftShoulder", (13, 0, 0), None, "left_shoulder"),
    ("LeftForeArm", "LeftArm", (26, 0, 0), None, "left_elbow"),
    ("LeftHand", "LeftForeArm", (25, 0, 0), None, "left_wrist"),
    ("LeftHandMiddle1", "LeftHand", (9, 0, 0), (4, 0, 0), "left_hand"),
    ("LeftHandThumb1", "LeftHand", (3, 0, 3), (3, 0, 0), None),
]


def _right(rows):
    def flip(name):
        return name.replace("Left", "Right")

    def mirror(v):
        return None if v is None else (-v[0], v[1], v[2])

    return [(flip(n), flip(p), mirror(o), mirror(e), s and s.replace("left", "right"))
            for n, p, o, e, s in rows]


JOINTS = ([("Hips", None, (0, 0, 0), None, "pelvis")] + _LEFT + _right(_LEFT) + _SPINE
          + _LEFT_ARM + _right(_LEFT_ARM))
NAMES = tuple(j[0] for j in JOINTS)
SMPL_OF = {j[0]: j[4] for j in JOINTS}


def order(j: int) -> str:
    """Rotation channel order of file joint j."""
    return "ZYX" if j == 0 else ORDERS[j % 3]


def angles_deg(j: int, f: int) -> np.ndarray:
    """(3,) the rotation channel values of file joint j at frame f, in channel order [deg]."""
    return np.array([((7 * j + 13 * k + 5 * f) % 61) - 30 for k in range(3)], dtype=np.float64)


def root_position_cm(f: int) -> np.ndarray:
    """(3,) the Hips position channels at frame f [cm]."""
    return np.array([2.0 * f, 95.0 + 0.5 * f, 5.0 * f])


def _children(name):
    return [j for j in JOINTS if j[1] == name]


def write(path: Path = PATH) -> None:
    lines = ["HIERARCHY"]

    def emit(row, depth):
        name, parent, offset, end, _ = row
        j = NAMES.index(name)
        pad = "  " * depth
        lines.append(f"{pad}{'ROOT' if parent is None else 'JOINT'} {name}")
        lines.append(f"{pad}{{")
        lines.append(f"{pad}  OFFSET {offset[0]:g} {offset[1]:g} {offset[2]:g}")
        rot = " ".join(f"{a}rotation" for a in order(j))
        pos = "Xposition Yposition Zposition " if parent is None else ""
        lines.append(f"{pad}  CHANNELS {6 if parent is None else 3} {pos}{rot}")
        for child in _children(name):
            emit(child, depth + 1)
        if end is not None:
            lines.extend([f"{pad}  End Site", f"{pad}  {{", f"{pad}    OFFSET {end[0]:g} {end[1]:g} {end[2]:g}",
                          f"{pad}  }}"])
        lines.append(f"{pad}}}")

    emit(JOINTS[0], 0)
    lines += ["MOTION", f"Frames: {NUM_FRAMES}", f"Frame Time: {FRAME_TIME}"]
    for f in range(NUM_FRAMES):
        values = list(root_position_cm(f))
        for j in range(len(JOINTS)):
            values += list(angles_deg(j, f))
        lines.append(" ".join(f"{v:g}" for v in values))
    path.write_text("\n".join(lines) + "\n")


if __name__ == "__main__":
    write()

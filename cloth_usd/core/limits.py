"""The range of bodies and poses cloth_usd's models were trained on, and checks against it.

Procedural training motions (``cloth_usd.datagen``) keep every joint inside
:data:`JOINT_LIMITS` and training bodies keep ``|beta| <= BETA_LIMIT``. Real motion capture
leaves :data:`JOINT_LIMITS` (most frames of CMU clips do, at the elbows, hands and ankles),
so a bundle trained on it records the range its training poses span (:func:`pose_range`,
:func:`pose_range_record`) and a bake checks a learned tier against that. Inputs outside
still bake, but the result is an extrapolation, so the bake warns. Shape letters: T frames,
J joints (24).
"""

from __future__ import annotations

import warnings
from dataclasses import dataclass

import numpy as np
from scipy.spatial.transform import Rotation

from .smpl import JOINT_NAMES, NUM_JOINTS

__all__ = ["BETA_LIMIT", "BETA_MARGIN", "BETA_MAX", "EULER_ORDERS", "JOINT_LIMITS", "POSE_MARGIN_DEG", "PoseOutlier",
           "betas_outside", "betas_outside_range", "betas_range_from_record", "betas_range_record", "pose_excess",
           "pose_outliers", "pose_range", "pose_range_from_record", "pose_range_record", "poses_to_euler"]

#: Largest ``|beta|`` of the bodies the models were trained on (SMPL's shape space is
#: a PCA in standard deviations; beyond 3 the bodies are implausible).
BETA_LIMIT = 3.0
#: How far past the range of its training bodies [standard deviations] a body's shape
#: coefficient may lie before the bake warns (:func:`betas_outside_range`).
BETA_MARGIN = 0.5
#: Largest ``|beta|`` a stage may author at all: past it a body is not a body (at 1e30 its
#: points lie 5e24 m away), so the stage is refused rather than warned about.
BETA_MAX = 10.0
#: How far past its trained range [deg] a joint angle may lie before the bake warns (:func:`pose_outliers`).
POSE_MARGIN_DEG = 10.0

#: Intrinsic Euler order of each joint's angles (scipy's upper-case convention). The middle
#: angle of each order stays inside (-90, 90) deg in :data:`JOINT_LIMITS`, so angles read
#: back from a rotation are unique.
EULER_ORDERS: tuple[str, ...] = tuple("YXZ" if name.endswith("_elbow") else "XYZ" for name in JOINT_NAMES)

_J = {name: i for i, name in enumerate(JOINT_NAMES)}

#: Plausible human ranges per joint, intrinsic Euler angles [deg] for the LEFT side and
#: the midline; right joints are the mirror image (x kept, y and z negated and swapped).
_LIMITS_DEG: dict[str, tuple[tuple[float, float], ...]] = {
    "pelvis": ((-30, 30), (-45, 45), (-20, 20)),  # global orientation (dance sway only)
    "spine1": ((-20, 45), (-30, 30), (-25, 25)),  # +x bends forward, y twists, z bends sideways
    "spine2": ((-20, 45), (-30, 30), (-25, 25)),
    "spine3": ((-20, 45), (-30, 30), (-25, 25)),
    "neck": ((-30, 40), (-45, 45), (-30, 30)),
    "head": ((-30, 40), (-40, 40), (-30, 30)),
    "left_hip": ((-120, 30), (-45, 45), (-30, 50)),  # -x flexes forward, +z abducts
    "left_knee": ((0, 140), (-5, 5), (-5, 5)),  # +x flexes
    "left_ankle": ((-25, 50), (-20, 20), (-25, 25)),  # +x points the toes down
    "left_foot": ((-45, 30), (-5, 5), (-5, 5)),
    "left_collar": ((-15, 15), (-20, 20), (-15, 30)),  # +z shrugs
    "left_shoulder": ((-90, 90), (-85, 40), (-90, 90)),  # -z lowers the arm, +z raises it
    "left_elbow": ((-60, 60), (-150, 5), (-5, 5)),  # -y flexes the forearm forward
    "left_wrist": ((-60, 60), (-30, 30), (-70, 70)),
    "left_hand": ((-15, 15), (-15, 15), (-40, 15)),
}


def _limits_table() -> np.ndarray:
    lim = np.zeros((NUM_JOINTS, 3, 2))
    for name, rows in _LIMITS_DEG.items():
        lim[_J[name]] = rows
        if name.startswith("left_"):
            mirror = np.array(rows, dtype=np.float64)
            mirror[1:] = -mirror[1:, ::-1]
            lim[_J["right_" + name[5:]]] = mirror
    lim = np.deg2rad(lim)
    lim.setflags(write=False)
    return lim


#: (24, 3, 2) [rad]: per joint and per Euler angle about x, y, z (in the joint's
#: :data:`EULER_ORDERS`), the (low, high) bounds of plausible human motion. Every range
#: contains 0 (the rest pose).
JOINT_LIMITS: np.ndarray = _limits_table()


def poses_to_euler(poses: np.ndarray) -> np.ndarray:
    """Per-joint Euler angles in :data:`EULER_ORDERS`.

    Args:
        poses: (T, 72) axis-angle [rad].
    Returns:
        (T, 24, 3) angles about x, y, z [rad] (indexed by axis, not by order).
    """
    poses = np.asarray(poses, dtype=np.float64)
    rot = poses.reshape(len(poses), NUM_JOINTS, 3)
    out = np.empty_like(rot)
    for order in sorted(set(EULER_ORDERS)):
        joints = [j for j, o in enumerate(EULER_ORDERS) if o == order]
        with warnings.catch_warnings():  # at +-90 deg about the middle axis the third angle reads 0: fine here
            warnings.filterwarnings("ignore", message="Gimbal lock detected", category=UserWarning)
            angles = Rotation.from_rotvec(rot[:, joints].reshape(-1, 3)).as_euler(order)
        by_axis = np.argsort(["XYZ".index(a) for a in order])
        out[:, joints] = angles.reshape(len(poses), len(joints), 3)[..., by_axis]
    return out


def betas_outside(betas: np.ndarray, limit: float = BETA_LIMIT) -> np.ndarray:
    """Indices of the shape coefficients with ``|beta| > limit``.

    Args:
        betas: (B,) float shape coefficients.
    Returns:
        (K,) int64 indices into ``betas``.
    """
    return np.flatnonzero(np.abs(np.asarray(betas, dtype=np.float64)) > limit)


@dataclass(frozen=True)
class PoseOutlier:
    """Frames whose pose leaves :data:`JOINT_LIMITS` (the root orientation is free)."""

    frames: np.ndarray
    """(K,) int64 indices of the frames outside, ascending."""
    joint: str
    """The joint furthest outside at the first such frame."""
    axis: str
    """``x``, ``y`` or ``z``: its Euler angle that is outside."""
    angle_deg: float
    """That angle [deg]."""
    low_deg: float
    """The trained range of that angle [deg], low end."""
    high_deg: float
    """High end [deg]."""


def pose_excess(euler: np.ndarray, limits: np.ndarray | None = None) -> np.ndarray:
    """How far each joint angle lies outside its limits (the root left out: it turns freely).

    Args:
        euler: (T, 24, 3) angles [rad] (:func:`poses_to_euler`).
        limits: (J, 3, 2) [rad] the range to check against; :data:`JOINT_LIMITS` when None.
    Returns:
        (T, 23, 3) [rad], > 0 outside, <= 0 inside.
    """
    lim = _joint_limits(limits)
    euler = euler[:, 1:]
    return np.maximum(euler - lim[..., 1], lim[..., 0] - euler)


def _joint_limits(limits: np.ndarray | None) -> np.ndarray:
    """(23, 3, 2) [rad] the limits of the joints below the root: ``limits``'s, :data:`JOINT_LIMITS` when None."""
    return (JOINT_LIMITS if limits is None else np.asarray(limits, dtype=np.float64))[1:]


def pose_outliers(poses: np.ndarray, margin_deg: float = POSE_MARGIN_DEG, limits: np.ndarray | None = None
                  ) -> PoseOutlier | None:
    """The frames where some joint (not the root) is more than ``margin_deg`` outside its limits.

    Args:
        poses: (T, 72) axis-angle [rad], SMPL's (root first).
        limits: (J, 3, 2) [rad] the range to check against (:func:`pose_range`, or
            :func:`pose_range_from_record` of a bundle's); :data:`JOINT_LIMITS` when None.
    Returns:
        None when every frame is inside.
    """
    euler = poses_to_euler(poses)
    excess = pose_excess(euler, limits)  # (T, 23, 3) [rad], > 0 outside
    outside = excess > np.deg2rad(margin_deg)
    frames = np.flatnonzero(outside.any(axis=(1, 2)))
    if frames.size == 0:
        return None
    first = frames[0]
    joint, axis = np.unravel_index(int(np.argmax(excess[first])), excess[first].shape)
    low, high = np.rad2deg(_joint_limits(limits)[joint, axis])
    return PoseOutlier(frames=frames.astype(np.int64), joint=JOINT_NAMES[joint + 1], axis="xyz"[axis],
                       angle_deg=float(np.rad2deg(euler[first, joint + 1, axis])), low_deg=float(low),
                       high_deg=float(high))


def pose_range(poses: np.ndarray) -> np.ndarray:
    """The range the poses span: per joint and Euler angle (:func:`poses_to_euler`), the
    smallest and largest over the frames.

    Args:
        poses: (T, 72) axis-angle [rad], T > 0.
    Returns:
        (J, 3, 2) float64 [rad], ``[..., 0]`` low, ``[..., 1]`` high.
    """
    poses = np.asarray(poses, dtype=np.float64)
    if poses.ndim != 2 or poses.shape[1] != 3 * NUM_JOINTS or poses.shape[0] == 0:
        raise ValueError(f"poses must be (T, {3 * NUM_JOINTS}) with T > 0, got {poses.shape}")
    euler = poses_to_euler(poses)
    return np.stack([euler.min(axis=0), euler.max(axis=0)], axis=-1)


def pose_range_record(poses: np.ndarray) -> dict:
    """The range of :func:`pose_range` as a bundle manifest records it (JSON): ``{"frames": T,
    "euler_deg": {joint name: [[low, high] about x, y, z]}}``, degrees rounded to 0.01."""
    lim = np.rad2deg(pose_range(poses))
    return {"frames": int(len(poses)),
            "euler_deg": {name: [[round(float(lo), 2), round(float(hi), 2)] for lo, hi in lim[j]]
                          for j, name in enumerate(JOINT_NAMES)}}


def pose_range_from_record(record: object) -> np.ndarray:
    """(J, 3, 2) [rad] the range a :func:`pose_range_record` holds.

    Raises:
        ValueError: a record without every joint's three ``[low, high]`` pairs (low <= high,
            finite), saying what is wrong.
    """
    table = record.get("euler_deg") if isinstance(record, dict) else None
    if not isinstance(table, dict):
        raise ValueError("expected {\"frames\": T, \"euler_deg\": {joint: [[low, high] x 3]}}")
    missing = [name for name in JOINT_NAMES if name not in table]
    if missing:
        raise ValueError(f"euler_deg lacks the joints {', '.join(missing)}")
    try:
        lim = np.array([table[name] for name in JOINT_NAMES], dtype=np.float64)
    except (TypeError, ValueError):
        lim = np.empty(0)
    if lim.shape != (NUM_JOINTS, 3, 2) or not np.isfinite(lim).all() or (lim[..., 0] > lim[..., 1]).any():
        raise ValueError("euler_deg must give each joint three finite [low, high] pairs, low <= high")
    return np.deg2rad(lim)


def betas_range_record(betas: np.ndarray) -> dict:
    """The range of training bodies' shapes as a bundle manifest records it (JSON):
    ``{"count": K, "betas": [[low, high] per coefficient]}``.

    Args:
        betas: (K, B) float shape coefficients of the K training bodies, K > 0.
    """
    b = np.asarray(betas, dtype=np.float64)
    if b.ndim != 2 or b.shape[0] == 0 or not np.isfinite(b).all():
        raise ValueError(f"betas must be (K, B) finite with K > 0, got {b.shape}")
    return {"count": int(b.shape[0]),
            "betas": [[round(float(lo), 4), round(float(hi), 4)] for lo, hi in zip(b.min(axis=0), b.max(axis=0))]}


def betas_range_from_record(record: object) -> np.ndarray:
    """(B, 2) the ``[low, high]`` per coefficient a :func:`betas_range_record` holds.

    Raises:
        ValueError: a record without finite ``[low, high]`` pairs (low <= high), saying what is wrong.
    """
    rows = record.get("betas") if isinstance(record, dict) else None
    try:
        lim = np.array(rows, dtype=np.float64)
    except (TypeError, ValueError):
        lim = np.empty(0)
    if lim.ndim != 2 or lim.shape[1] != 2 or lim.shape[0] == 0 or not np.isfinite(lim).all() \
            or (lim[:, 0] > lim[:, 1]).any():
        raise ValueError("expected {\"count\": K, \"betas\": [[low, high] per coefficient]}, finite, low <= high")
    return lim


def betas_outside_range(betas: np.ndarray, limits: np.ndarray, margin: float = BETA_MARGIN) -> np.ndarray:
    """Indices of the shape coefficients more than ``margin`` outside ``limits``.

    Args:
        betas: (B',) shape coefficients; those past ``limits``' B count against 0..0.
        limits: (B, 2) ``[low, high]`` per coefficient (:func:`betas_range_from_record`).
    Returns:
        (K,) int64 indices into ``betas``.
    """
    b = np.asarray(betas, dtype=np.float64)
    lim = np.zeros((b.shape[0], 2))
    n = min(b.shape[0], limits.shape[0])
    lim[:n] = limits[:n]
    return np.flatnonzero((b < lim[:, 0] - margin) | (b > lim[:, 1] + margin))

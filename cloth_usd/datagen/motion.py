"""Pose sequences for the SMPL skeleton: procedural motions and shared sequence tools.

Shape letters: T frames. SMPL's frame: Y up, the body faces +Z, its left is +X. Poses
are (T, 72) axis-angle [rad], joint 0 the global orientation, every other joint's
rotation local, in its parent's rest-aligned frame (rest = the T-pose). So flexing a
hip forward is a negative rotation about X, bending a knee a positive one, and
lowering the left arm a negative rotation about Z.

Procedural motions are written as per-joint intrinsic Euler angles about x, y and z
(order :data:`EULER_ORDERS`: ``XYZ``, i.e. ``Rx @ Ry @ Rz`` with z turning first, except
the elbows, whose flexion about y needs more than 90 deg and so is the outer angle),
bounded by :data:`JOINT_LIMITS`, and eased in from the rest pose so that a cloth
simulation starts from the rest garment.
"""

from __future__ import annotations

from dataclasses import dataclass
from enum import Enum

import numpy as np
from scipy.spatial.transform import Rotation, Slerp

from ..core.limits import EULER_ORDERS, JOINT_LIMITS, poses_to_euler
from ..core.smpl import JOINT_NAMES, NUM_JOINTS
from ..errors import ArgumentError, MotionFileError

__all__ = [
    "EULER_ORDERS",
    "JOINT_LIMITS",
    "MotionFileError",
    "MotionKind",
    "MotionSpec",
    "blend_from_rest",
    "euler_to_poses",
    "generate",
    "poses_to_euler",
    "resample",
    "walk_cycle",
]

_J = {name: i for i, name in enumerate(JOINT_NAMES)}


# --------------------------------------------------------------------------- limits
# EULER_ORDERS and JOINT_LIMITS live in cloth_usd.core.limits (the baker warns with them).


def euler_to_poses(euler: np.ndarray) -> np.ndarray:
    """Axis-angle poses from per-joint Euler angles in :data:`EULER_ORDERS`.

    Args:
        euler: (T, 24, 3) angles about x, y, z [rad] (indexed by axis, not by order).
    Returns:
        (T, 72) axis-angle [rad].
    """
    euler = np.asarray(euler, dtype=np.float64)
    out = np.empty_like(euler)
    for order in sorted(set(EULER_ORDERS)):
        joints = [j for j, o in enumerate(EULER_ORDERS) if o == order]
        cols = ["XYZ".index(a) for a in order]
        angles = euler[:, joints][..., cols].reshape(-1, 3)
        out[:, joints] = Rotation.from_euler(order, angles).as_rotvec().reshape(len(euler), len(joints), 3)
    return out.reshape(len(euler), 72)




# --------------------------------------------------------------------------- sequence tools
def blend_from_rest(poses: np.ndarray, frames: int) -> np.ndarray:
    """Ease the first ``frames`` frames in from the rest pose (slerp per joint).

    Args:
        poses: (T, 72) axis-angle [rad].
        frames: length of the ease-in; 0 leaves the poses unchanged.
    Returns:
        (T, 72) poses whose frame 0 is the rest pose (when ``frames >= 1``).
    """
    out = poses.copy()
    # The ease keeps its length when the sequence is shorter: a 3-frame clip of a
    # 12-frame ease-in moves gently instead of jumping to the full pose.
    for t in range(min(frames, poses.shape[0])):
        s = 0.5 - 0.5 * np.cos(np.pi * t / max(frames, 1))  # smooth step 0 -> 1
        rot = Rotation.from_rotvec(poses[t].reshape(24, 3))
        out[t] = (rot.as_rotvec() * s).reshape(72)  # slerp from identity = scaled rotation vector
    return out


def resample(poses: np.ndarray, root: np.ndarray, src_fps: float, dst_fps: float
             ) -> tuple[np.ndarray, np.ndarray]:
    """Resample a pose sequence in time: slerp per joint, linear for the root.

    Output frame k lies at time ``k / dst_fps``; the sequence keeps its duration, so
    there are ``floor((T - 1) * dst_fps / src_fps) + 1`` output frames.

    Args:
        poses: (T, 72) axis-angle [rad].
        root: (T, 3) root translation [m].
        src_fps, dst_fps: frame rates [1/s], both > 0.
    Returns:
        ``(poses (T', 72) [rad], root (T', 3) [m])``.
    """
    poses = np.asarray(poses, dtype=np.float64)
    root = np.asarray(root, dtype=np.float64)
    if not (src_fps > 0 and dst_fps > 0):
        raise ArgumentError(f"frame rates must be > 0, got src_fps={src_fps}, dst_fps={dst_fps}")
    if poses.ndim != 2 or poses.shape[1] != 72 or root.shape != (poses.shape[0], 3):
        raise ArgumentError(f"expected poses (T, 72) and root (T, 3), got {poses.shape} and {root.shape}")
    n_src = poses.shape[0]
    if n_src == 0:
        raise ArgumentError("cannot resample an empty sequence")
    if abs(src_fps - dst_fps) <= 1e-5 * dst_fps or n_src == 1:  # BVH frame times are rounded (0.0333333)
        return poses.copy(), root.copy()
    # the same rounding may leave the last frame a hair short of a whole output frame
    n_dst = int(np.floor((n_src - 1) * dst_fps / src_fps + 1e-3)) + 1
    t_src = np.arange(n_src) / src_fps
    t_dst = np.minimum(np.arange(n_dst) / dst_fps, t_src[-1])
    out = np.empty((n_dst, 24, 3))
    joints = poses.reshape(n_src, 24, 3)
    for j in range(24):
        out[:, j] = Slerp(t_src, Rotation.from_rotvec(joints[:, j]))(t_dst).as_rotvec()
    new_root = np.stack([np.interp(t_dst, t_src, root[:, k]) for k in range(3)], axis=-1)
    return out.reshape(n_dst, 72), new_root


# --------------------------------------------------------------------------- procedural
class MotionKind(str, Enum):
    """The procedural motions :func:`generate` makes."""

    WALK = "walk"
    RUN = "run"
    ARM_RAISE = "arm_raise"  # both arms from down to overhead and back, through the side
    ARM_SWING = "arm_swing"  # arms hanging, swinging forward and back
    TORSO_TWIST = "torso_twist"
    TORSO_BEND = "torso_bend"  # forward bend and sideways lean
    DANCE = "dance"  # random smooth motion of every joint within JOINT_LIMITS


@dataclass(frozen=True)
class MotionSpec:
    """What :func:`generate` makes; the same spec always gives the same sequence."""

    kind: MotionKind | str = MotionKind.WALK
    """Which motion; a :class:`MotionKind` or its string value."""
    seconds: float = 4.0
    """Duration [s], > 0."""
    fps: float = 24.0
    """Frame rate [1/s], > 0."""
    seed: int = 0
    """Random seed: tempo, amplitude and phase jitter (all kinds), the whole dance."""
    intensity: float = 1.0
    """Amplitude scale in [0, 2]; motions are clipped to :data:`JOINT_LIMITS` regardless."""
    blend_seconds: float = 0.5
    """Ease-in from the rest pose [s], >= 0; frame 0 is exactly the rest pose when > 0."""

    def __post_init__(self) -> None:
        try:
            object.__setattr__(self, "kind", MotionKind(self.kind))
        except ValueError:
            valid = ", ".join(k.value for k in MotionKind)
            raise ArgumentError(f"MotionSpec.kind: unknown motion {self.kind!r}; valid: {valid}") from None
        if not self.seconds > 0:
            raise ArgumentError(f"MotionSpec.seconds must be > 0, got {self.seconds}")
        if not self.fps > 0:
            raise ArgumentError(f"MotionSpec.fps must be > 0, got {self.fps}")
        if not 0.0 <= self.intensity <= 2.0:
            raise ArgumentError(f"MotionSpec.intensity must lie in [0, 2], got {self.intensity}")
        if not self.blend_seconds >= 0:
            raise ArgumentError(f"MotionSpec.blend_seconds must be >= 0, got {self.blend_seconds}")

    @property
    def num_frames(self) -> int:
        """T, the number of frames: ``round(seconds * fps)``, at least 1."""
        return max(1, int(round(self.seconds * self.fps)))


def generate(spec: MotionSpec) -> tuple[np.ndarray, np.ndarray]:
    """A procedural pose sequence.

    Every joint stays within :data:`JOINT_LIMITS` (as Euler angles, :func:`poses_to_euler`) and the
    sequence eases in from the rest pose over ``spec.blend_seconds``.

    Returns:
        ``(poses (T, 72) axis-angle [rad], root_offset (T, 3) [m])``: the root offset is
        the pelvis displacement from its rest place (zero at frame 0).
    """
    n = spec.num_frames
    t = np.arange(n) / spec.fps
    rng = np.random.default_rng(spec.seed)
    jitter = _Jitter(tempo=1.0 + 0.1 * rng.uniform(-1, 1), amp=spec.intensity * (1.0 + 0.1 * rng.uniform(-1, 1)),
                     phase=rng.uniform(0.0, 2 * np.pi))
    ease = _ease(t, spec.blend_seconds)
    euler = np.zeros((n, NUM_JOINTS, 3))
    root = np.zeros((n, 3))
    kind = spec.kind
    if kind in (MotionKind.WALK, MotionKind.RUN):
        run = kind is MotionKind.RUN
        phase = 2 * np.pi * (1.4 if run else 0.9) * jitter.tempo * t + jitter.phase
        (_run_euler if run else _walk_euler)(euler, phase, jitter.amp)
        speed = (3.0 if run else 1.1) * jitter.tempo * min(jitter.amp, 1.0)
        root[:, 2] = np.concatenate([[0.0], np.cumsum(speed * ease[1:] / spec.fps)])
        root[:, 1] = (0.04 if run else 0.02) * jitter.amp * np.cos(2 * phase) * ease
    elif kind is MotionKind.ARM_RAISE:
        _arm_raise_euler(euler, 2 * np.pi * t * jitter.tempo / 4.0, jitter.amp)
    elif kind is MotionKind.ARM_SWING:
        _arm_swing_euler(euler, 2 * np.pi * 0.7 * jitter.tempo * t + jitter.phase, jitter.amp)
    elif kind is MotionKind.TORSO_TWIST:
        _torso_twist_euler(euler, 2 * np.pi * 0.4 * jitter.tempo * t + jitter.phase, jitter.amp)
    elif kind is MotionKind.TORSO_BEND:
        _torso_bend_euler(euler, 2 * np.pi * 0.25 * jitter.tempo * t, jitter.amp)
    else:  # DANCE
        _dance_euler(euler, t, spec.intensity, rng)
        for k in (0, 2):  # a little sway of the root on the floor plane
            f, p = rng.uniform(0.1, 0.4), rng.uniform(0, 2 * np.pi)
            root[:, k] = 0.05 * spec.intensity * (np.sin(2 * np.pi * f * t + p) - np.sin(p)) * ease
    euler = np.clip(euler, JOINT_LIMITS[..., 0], JOINT_LIMITS[..., 1]) * ease[:, None, None]
    poses = euler_to_poses(euler)
    poses[ease == 0.0] = 0.0  # the rest pose, exactly
    return poses, root


@dataclass(frozen=True)
class _Jitter:
    tempo: float
    amp: float
    phase: float


def _ease(t: np.ndarray, seconds: float) -> np.ndarray:
    """(T,) smooth step 0 -> 1 over ``seconds`` (all ones when ``seconds`` is 0)."""
    if seconds <= 0:
        return np.ones_like(t)
    return 0.5 - 0.5 * np.cos(np.pi * np.clip(t / seconds, 0.0, 1.0))


def _set(euler: np.ndarray, joint: str, axis: int, value) -> None:
    euler[:, _J[joint], axis] = value


def _arms_down(euler: np.ndarray, drop: float) -> None:
    _set(euler, "left_shoulder", 2, -drop)
    _set(euler, "right_shoulder", 2, drop)


def _walk_euler(euler: np.ndarray, phase: np.ndarray, amp: float, arm_drop: float = 1.15) -> None:
    s = np.sin(phase)
    _set(euler, "left_hip", 0, -0.45 * amp * s)
    _set(euler, "right_hip", 0, 0.45 * amp * s)
    _set(euler, "left_knee", 0, 0.55 * amp * np.maximum(0.0, np.sin(phase + 1.2)) + 0.05)
    _set(euler, "right_knee", 0, 0.55 * amp * np.maximum(0.0, np.sin(phase + 1.2 + np.pi)) + 0.05)
    _set(euler, "left_ankle", 0, 0.15 * amp * np.sin(phase - 0.6))
    _set(euler, "right_ankle", 0, -0.15 * amp * np.sin(phase - 0.6))
    _set(euler, "spine1", 1, 0.10 * amp * s)
    _set(euler, "spine3", 1, -0.12 * amp * s)
    _set(euler, "spine2", 0, 0.05)
    _arms_down(euler, arm_drop)
    _set(euler, "left_shoulder", 0, 0.45 * amp * s)  # left arm back while the left leg is forward
    _set(euler, "right_shoulder", 0, -0.45 * amp * s)
    _set(euler, "left_elbow", 1, -0.35 - 0.2 * amp * np.maximum(0.0, s))  # forearm forward
    _set(euler, "right_elbow", 1, 0.35 + 0.2 * amp * np.maximum(0.0, -s))


def _run_euler(euler: np.ndarray, phase: np.ndarray, amp: float) -> None:
    s = np.sin(phase)
    _set(euler, "left_hip", 0, -0.25 - 0.6 * amp * s)
    _set(euler, "right_hip", 0, -0.25 + 0.6 * amp * s)
    _set(euler, "left_knee", 0, 0.3 + 1.1 * amp * np.maximum(0.0, np.sin(phase + 1.2)))
    _set(euler, "right_knee", 0, 0.3 + 1.1 * amp * np.maximum(0.0, np.sin(phase + 1.2 + np.pi)))
    _set(euler, "left_ankle", 0, 0.25 * amp * np.sin(phase - 0.6))
    _set(euler, "right_ankle", 0, -0.25 * amp * np.sin(phase - 0.6))
    _set(euler, "spine1", 0, 0.12)  # lean into the run
    _set(euler, "spine2", 0, 0.05)
    _set(euler, "spine1", 1, 0.12 * amp * s)
    _set(euler, "spine3", 1, -0.15 * amp * s)
    _arms_down(euler, 1.25)
    _set(euler, "left_shoulder", 0, 0.7 * amp * s)
    _set(euler, "right_shoulder", 0, -0.7 * amp * s)
    _set(euler, "left_elbow", 1, -1.4)
    _set(euler, "right_elbow", 1, 1.4)


def _arm_raise_euler(euler: np.ndarray, phase: np.ndarray, amp: float) -> None:
    down, up = np.deg2rad(-75.0), np.deg2rad(85.0)
    lift = down + (up - down) * min(amp, 1.0) * (0.5 - 0.5 * np.cos(phase))  # down -> overhead -> down
    _set(euler, "left_shoulder", 2, lift)
    _set(euler, "right_shoulder", 2, -lift)
    _set(euler, "left_elbow", 1, -0.15)
    _set(euler, "right_elbow", 1, 0.15)
    shrug = 0.15 * np.clip(lift / up, 0.0, 1.0)  # the collar bones follow overhead
    _set(euler, "left_collar", 2, shrug)
    _set(euler, "right_collar", 2, -shrug)


def _arm_swing_euler(euler: np.ndarray, phase: np.ndarray, amp: float) -> None:
    s = np.sin(phase)
    _arms_down(euler, 1.2)
    _set(euler, "left_shoulder", 0, 0.9 * amp * s)
    _set(euler, "right_shoulder", 0, -0.9 * amp * s)
    _set(euler, "left_elbow", 1, -0.2 - 0.3 * amp * np.maximum(0.0, -s))
    _set(euler, "right_elbow", 1, 0.2 + 0.3 * amp * np.maximum(0.0, s))
    _set(euler, "spine2", 1, 0.08 * amp * s)


def _torso_twist_euler(euler: np.ndarray, phase: np.ndarray, amp: float) -> None:
    s = np.sin(phase)
    for j in ("spine1", "spine2", "spine3"):
        _set(euler, j, 1, 0.2 * amp * s)
    _set(euler, "neck", 1, -0.15 * amp * s)  # the head keeps looking ahead
    _arms_down(euler, 1.1)
    _set(euler, "left_shoulder", 0, 0.25 * amp * np.sin(phase - 0.5))  # loose arms lag the twist
    _set(euler, "right_shoulder", 0, -0.25 * amp * np.sin(phase - 0.5))


def _torso_bend_euler(euler: np.ndarray, phase: np.ndarray, amp: float) -> None:
    forward = 0.5 - 0.5 * np.cos(phase)
    side = np.sin(0.5 * phase)
    for j in ("spine1", "spine2", "spine3"):
        _set(euler, j, 0, 0.35 * amp * forward)
        _set(euler, j, 2, 0.2 * amp * side)
    _set(euler, "neck", 0, 0.15 * amp * forward)
    _arms_down(euler, 1.2)


def _dance_euler(euler: np.ndarray, t: np.ndarray, intensity: float, rng: np.random.Generator) -> None:
    """Per joint axis, 3 random sinusoids (0.1-0.6 Hz) squashed smoothly into the limits.

    ``angle = c + h tanh(b + intensity * 0.8 * S(t))`` with c, h the centre and half-width
    of the joint's range and ``b`` chosen so that S = 0 gives the rest angle 0 (or the
    nearest angle at 80 % of the way to a bound, for ranges that end at 0 like the knee).
    """
    lo, hi = JOINT_LIMITS[..., 0], JOINT_LIMITS[..., 1]
    c, h = 0.5 * (lo + hi), 0.5 * (hi - lo)
    b = np.arctanh(np.clip(-c / h, -0.8, 0.8))
    freq = rng.uniform(0.1, 0.6, size=(NUM_JOINTS, 3, 3))
    phase = rng.uniform(0.0, 2 * np.pi, size=(NUM_JOINTS, 3, 3))
    weight = rng.uniform(0.5, 1.0, size=(NUM_JOINTS, 3, 3))
    weight /= weight.sum(axis=-1, keepdims=True)
    waves = np.sin(2 * np.pi * freq * t[:, None, None, None] + phase) - np.sin(phase)  # 0 at t = 0
    signal = 0.5 * np.sum(weight * waves, axis=-1)  # (T, 24, 3) in [-1, 1]
    gain = 0.8 * intensity * np.ones((NUM_JOINTS, 1))
    gain[_J["pelvis"]] *= 0.5  # the global orientation sways, it does not spin
    euler[:] = c + h * np.tanh(b + gain * signal)


# --------------------------------------------------------------------------- the first walk
def walk_cycle(num_frames: int, fps: float = 24.0, *, stride_hz: float = 0.9, speed: float = 1.1,
               arm_drop: float = 1.15, blend_frames: int = 12) -> tuple[np.ndarray, np.ndarray]:
    """A walk with swinging arms and a little torso twist.

    Returns:
        ``(poses (T, 72) axis-angle [rad], root_offset (T, 3) [m])``: the root offset is
        the pelvis displacement from its rest place.
    """
    t = np.arange(num_frames) / fps
    phase = 2 * np.pi * stride_hz * t
    euler = np.zeros((num_frames, 24, 3))  # per-joint xyz Euler angles
    _walk_euler(euler, phase, 1.0, arm_drop)
    rot = Rotation.from_euler("XYZ", euler.reshape(-1, 3))  # intrinsic: z turns first, then y, x
    poses = blend_from_rest(rot.as_rotvec().reshape(num_frames, 72), blend_frames)
    ramp = np.clip(np.arange(num_frames) / max(blend_frames, 1), 0.0, 1.0)
    root = np.zeros((num_frames, 3))
    root[:, 2] = np.cumsum(speed / fps * ramp)
    root[:, 1] = 0.02 * np.cos(2 * phase) * ramp - 0.01 * ramp
    return poses, root

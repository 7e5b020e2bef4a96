"""Motion capture as a data set motion: a BVH clip retargeted to SMPL, at natural speed, eased in.

A cloth simulation starts from the garment draped on the rest (T-) pose, so a real clip
cannot start at its first captured frame: the body would jump into a pose the garment
never followed. :func:`mocap_motion` turns a stretch of a BVH file into a sequence that

1. starts facing +Z at the origin: the clip's heading and position at its first frame
   are taken out of every frame (a turn about +Y and a shift on the floor), so the ease
   below never spins or slides the body;
2. **eases in** from the rest pose to the clip's first pose over ``ease_seconds``
   (slerp per joint from the identity, a smooth step in time);
3. plays the clip at its own speed, resampled to ``fps``, its root's movement ramped in
   over the first ``ramp_seconds`` (a walk accelerates from standing instead of starting
   at full speed in one frame).

The ease and the ramp are the **warm-up**: the garment is still catching up with the
body there. Their frame count is returned (and recorded in the job's ``meta`` as
``warmup_frames`` by the factory); training and evaluation leave those frames out.
Shape letters: T frames.
"""

from __future__ import annotations

import hashlib
import json
from dataclasses import dataclass
from pathlib import Path

import numpy as np
from scipy.spatial.transform import Rotation

from ..core.files import models_dir
from ..core.heading import root_yaw, yaw_matrices
from ..errors import ArgumentError, MotionFileError
from .bvh import read_rigged_bvh, retarget_bvh, trim_bvh
from .motion import blend_from_rest

__all__ = ["MocapSpec", "MocapMotion", "mocap_motion", "STORED_MOTIONS", "store_motions", "stored_motion",
           "stored_motion_names"]


@dataclass(frozen=True)
class MocapSpec:
    """A stretch of one BVH file as a data set motion; the same spec gives the same sequence."""

    bvh: str
    """The file, relative to the mocap folder (``--mocap``); e.g. ``cmu/05/05_02.bvh``."""
    start_seconds: float = 0.0
    """Where the stretch starts in the file [s] (after CMU's prepended T-pose frame), >= 0."""
    seconds: float = 4.0
    """How much of the clip is played [s], > 0; the ramp is part of it, the ease is not."""
    fps: float = 30.0
    """Output frame rate [1/s], > 0; must equal the simulation's."""
    ease_seconds: float = 1.0
    """The ease-in from the rest pose before the clip [s], > 0."""
    ramp_seconds: float = 0.5
    """The root's movement ramps in over the clip's first ``ramp_seconds`` [s], >= 0."""
    name: str | None = None
    """The motion's label in sequence names; None: the file's stem and the start."""
    max_body_speed: float = 15.0
    """A stretch in which a vertex of the (mean) body moves faster than this [m/s] between
    two frames is refused when the data set is planned: a capture glitch, which no cloth
    simulation survives. CMU salsa 10 from 2 s moves a hand 0.77 m in one frame (23 m/s;
    every one of its simulated sequences stretched past 1.9x within 0.4 s); real fast
    motion stays near 10 m/s (martial arts 04: 10.4)."""

    def __post_init__(self) -> None:
        if not isinstance(self.bvh, str) or not self.bvh:
            raise ArgumentError(f"MocapSpec.bvh must be a file name, got {self.bvh!r}")
        for key, low, strict in (("start_seconds", 0.0, False), ("seconds", 0.0, True), ("fps", 0.0, True),
                                 ("ease_seconds", 0.0, True), ("ramp_seconds", 0.0, False)):
            value = getattr(self, key)
            if not isinstance(value, (int, float)) or not np.isfinite(value) or value < low or (strict and value == low):
                raise ArgumentError(f"MocapSpec.{key} must be {'>' if strict else '>='} {low:g}, got {value!r}")
        if self.ramp_seconds > self.seconds:
            raise ArgumentError(f"MocapSpec.ramp_seconds ({self.ramp_seconds}) is longer than the clip "
                                f"({self.seconds} s)")

    @property
    def label(self) -> str:
        """The motion's name in sequence names (letters, digits, '-', '_', '.')."""
        if self.name:
            return self.name
        path = Path(self.bvh)
        stem = path.stem if path.parent.name in path.stem else f"{path.parent.name}{path.stem}"
        stem = "".join(c for c in stem if c.isalnum())
        return f"mocap-{stem}-t{self.start_seconds:g}".replace(".", "p")


@dataclass(frozen=True)
class MocapMotion:
    """A retargeted, eased-in clip."""

    poses: np.ndarray
    """(T, 72) float64 axis-angle [rad]; frame 0 is the rest pose."""
    transl: np.ndarray
    """(T, 3) float64 root offset [m]; zero over the ease."""
    warmup_frames: int
    """The ease and the ramp: the first frames, left out of training and evaluation."""
    source: dict
    """Provenance: the file (as named in the spec), its sha256, rig and the file frames used."""


def mocap_motion(spec: MocapSpec, mocap_dir: str | Path, *, smpl_joints: np.ndarray | None = None) -> MocapMotion:
    """Read, retarget and ease in the stretch of a BVH file that ``spec`` names.

    Args:
        spec: which file, which stretch, at what rate.
        mocap_dir: the folder ``spec.bvh`` is relative to.
        smpl_joints: (24, 3) rest joints the retargeting aims the bones at (the embedded
            mean shape when None).
    Raises:
        MotionFileError: the file is missing, unreadable or of an unknown rig; the stretch
            lies outside it (each names the file).
    """
    path = Path(mocap_dir) / spec.bvh
    if not path.is_file():
        raise MotionFileError(f"{path}: no such BVH file (the motion {spec.bvh!r} is relative to the mocap "
                              f"folder {mocap_dir})")
    bvh, rig, mapping, first = read_rigged_bvh(path)
    start = first + int(round(spec.start_seconds * bvh.fps))
    stop = start + int(np.ceil(spec.seconds * bvh.fps))
    if stop >= bvh.num_frames:
        have = (bvh.num_frames - 1 - first) / bvh.fps
        raise MotionFileError(f"{path}: {spec.start_seconds:g} s + {spec.seconds:g} s is past the end of the clip "
                              f"({have:.2f} s of motion)")
    poses, root = retarget_bvh(trim_bvh(bvh, start, stop), mapping=mapping, fps=spec.fps, up_axis=None,
                               blend_seconds=0.0, smpl_joints=smpl_joints)
    n_clip = int(round(spec.seconds * spec.fps))
    poses, root = poses[:n_clip], root[:n_clip]
    poses, root = _face_forward(poses, root)
    ramp = int(round(spec.ramp_seconds * spec.fps))
    root = _ramp_root(root, ramp)
    ease = int(round(spec.ease_seconds * spec.fps))
    lead = blend_from_rest(np.repeat(poses[:1], ease, axis=0), ease)  # rest -> the clip's first pose
    poses = np.concatenate([lead, poses])
    transl = np.concatenate([np.zeros((ease, 3)), root])
    source = {"bvh": spec.bvh, "sha256": hashlib.sha256(path.read_bytes()).hexdigest(), "rig": rig,
              "file_frames": [start, stop], "file_fps": bvh.fps}
    return MocapMotion(poses=poses, transl=transl, warmup_frames=ease + ramp, source=source)


def _face_forward(poses: np.ndarray, root: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Take the first frame's heading out of every frame (root rotation and root path)."""
    turn = yaw_matrices(-root_yaw(poses[:1]))[0]
    out = poses.copy()
    out[:, :3] = (Rotation.from_matrix(turn) * Rotation.from_rotvec(poses[:, :3])).as_rotvec()
    return out, (root - root[:1]) @ turn.T


def _ramp_root(root: np.ndarray, frames: int) -> np.ndarray:
    """The root path with its velocity scaled by a smooth step 0 -> 1 over the first ``frames``."""
    if frames <= 0 or len(root) < 2:
        return root.copy()
    step = np.diff(root, axis=0)
    k = np.arange(1, len(root))
    scale = np.where(k < frames, 0.5 - 0.5 * np.cos(np.pi * k / frames), 1.0)
    return np.concatenate([root[:1], root[:1] + np.cumsum(step * scale[:, None], axis=0)])


#: The CMU stretches shipped with the package (``models/motions``): ``train-garment`` trains a
#: garment's own models on them by default, so that a user with no mocap folder still trains on
#: real motion (``scripts/store_motions.py`` writes the file from a mocap folder and a list of
#: :class:`MocapSpec` entries).
STORED_MOTIONS = "motions/cmu_stretches.npz"
#: The CMU stretches the test set ``train-garment`` writes holds out (under ``models/``): none of
#: them is a stretch of :data:`STORED_MOTIONS` or of its clips.
STORED_TEST_MOTIONS = "motions/cmu_test_stretches.npz"


def store_motions(specs: list[dict], mocap_dir: str | Path, out: str | Path, *,
                  smpl_joints: np.ndarray | None = None) -> list[str]:
    """Retarget and ease in the stretches ``specs`` names (entries as a data set config's
    ``bvh`` motions) and write them to one ``.npz`` that :func:`stored_motion` reads.

    The poses and root paths are stored as float32 (the float64 retarget rounded, 1e-7 rad);
    each stretch keeps its name (:attr:`MocapSpec.label`), warm-up and provenance.

    Returns:
        the names written, in order.
    Raises:
        ArgumentError: a bad entry, or two entries of one name.
        MotionFileError: as :func:`mocap_motion`.
    """
    names, motions = [], []
    for i, fields in enumerate(specs):
        try:
            spec = MocapSpec(**fields)
        except TypeError as exc:
            raise ArgumentError(f"motion {i}: {exc}") from None
        if spec.label in names:
            raise ArgumentError(f"motion {i}: the name {spec.label!r} is taken by an earlier entry")
        names.append(spec.label)
        m = mocap_motion(spec, mocap_dir, smpl_joints=smpl_joints)
        motions.append((m, {**m.source, "spec": dict(fields), "fps": spec.fps}))
    lengths = [len(m.poses) for m, _ in motions]
    np.savez_compressed(
        out, names=np.array(names), offsets=np.concatenate([[0], np.cumsum(lengths)]).astype(np.int64),
        poses=np.concatenate([m.poses for m, _ in motions]).astype(np.float32),
        transl=np.concatenate([m.transl for m, _ in motions]).astype(np.float32),
        warmup=np.array([m.warmup_frames for m, _ in motions], dtype=np.int64),
        sources=np.array(json.dumps([s for _, s in motions])))
    return names


def stored_motion_names(path: str | Path | None = None) -> tuple[str, ...]:
    """The names of the stretches in ``path`` (default: :data:`STORED_MOTIONS` of the package)."""
    with np.load(_stored_path(path)) as f:
        return tuple(str(n) for n in f["names"])


def stored_motion(name: str, path: str | Path | None = None) -> tuple[MocapMotion, float]:
    """One stretch of the stored file, as :func:`mocap_motion` made it from its clip.

    Args:
        name: the stretch's name.
        path: the file; None looks in the package's :data:`STORED_MOTIONS`, then its
            :data:`STORED_TEST_MOTIONS`.
    Returns:
        ``(motion, fps)``; the motion's poses and root path in float64.
    Raises:
        ArgumentError: no stretch of that name (the message lists the files and a few names).
    """
    files = [Path(path)] if path is not None else [models_dir() / STORED_MOTIONS, models_dir() / STORED_TEST_MOTIONS]
    held = []
    for file in files:
        with np.load(file) as f:
            names = [str(n) for n in f["names"]]
            if name not in names:
                held.append(f"{file} holds {len(names)}: {', '.join(names[:4])}{', ...' if len(names) > 4 else ''}")
                continue
            k = names.index(name)
            lo, hi = f["offsets"][k], f["offsets"][k + 1]
            source = json.loads(str(f["sources"]))[k]
            motion = MocapMotion(poses=f["poses"][lo:hi].astype(np.float64),
                                 transl=f["transl"][lo:hi].astype(np.float64),
                                 warmup_frames=int(f["warmup"][k]), source={**source, "stored": name})
        return motion, float(source["fps"])
    raise ArgumentError(f"no stored motion {name!r}; {'; '.join(held)}")


def _stored_path(path: str | Path | None) -> Path:
    return Path(path) if path is not None else models_dir() / STORED_MOTIONS

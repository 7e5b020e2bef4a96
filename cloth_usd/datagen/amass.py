"""AMASS motion files (``.npz``) as SMPL pose sequences in SMPL's Y-up frame.

Shape letters: T frames. AMASS stores, per sequence, ``poses`` (T, 156) SMPL-H
axis-angle (22 body joints, then 30 hand joints; SMPL-X files have other extras after
the first 66 values), ``trans`` (T, 3) [m], ``betas`` and the capture rate
(``mocap_framerate``, or ``mocap_frame_rate`` in newer releases). Its world is Z up;
SMPL's is Y up, so the global orientation and translation are turned -90 deg about X.
"""

from __future__ import annotations

import zipfile
from pathlib import Path

import numpy as np
from scipy.spatial.transform import Rotation

from ..errors import ArgumentError
from .motion import MotionFileError, blend_from_rest, resample

__all__ = ["AmassError", "load_amass", "load_amass_betas", "Z_UP_TO_Y_UP"]

#: (3, 3) rotation from AMASS's Z-up world to SMPL's Y-up one (-90 deg about X):
#: +Z (up) -> +Y, -Y -> +Z.
Z_UP_TO_Y_UP: np.ndarray = Rotation.from_euler("x", -90, degrees=True).as_matrix()
Z_UP_TO_Y_UP.setflags(write=False)

_RATE_KEYS = ("mocap_framerate", "mocap_frame_rate")
_BODY_VALUES = 66  # 22 SMPL-H body joints x 3; SMPL's two hand joints follow in SMPL's 72


class AmassError(MotionFileError):
    """An AMASS file is missing, unreadable or lacks a key."""


def _open(path: Path, keys: tuple[str, ...]) -> dict[str, np.ndarray]:
    """The arrays under ``keys`` that the file holds (others are not read), plus the key list."""
    try:
        with np.load(path, allow_pickle=False) as npz:
            data = {k: npz[k] for k in keys if k in npz.files}
            data["__files__"] = np.array(sorted(npz.files))
            return data
    except FileNotFoundError:
        raise AmassError(f"{path}: no such AMASS file") from None
    except ValueError as exc:  # object arrays need pickle, which we refuse
        raise AmassError(f"{path}: not a plain-array .npz (pickled objects are refused): {exc}") from None
    except (OSError, zipfile.BadZipFile) as exc:
        raise AmassError(f"{path}: cannot read as .npz: {exc}") from None


def _array(data: dict[str, np.ndarray], key: str, path: Path) -> np.ndarray:
    if key not in data:
        raise AmassError(f"{path}: missing key {key!r} (the file has: {_listing(data)})")
    value = np.asarray(data[key])
    if not np.issubdtype(value.dtype, np.number):
        raise AmassError(f"{path}: key {key!r} holds {value.dtype}, expected numbers")
    value = value.astype(np.float64)
    if not np.all(np.isfinite(value)):
        raise AmassError(f"{path}: key {key!r} holds non-finite values")
    return value


def _listing(data: dict[str, np.ndarray]) -> str:
    return ", ".join(str(k) for k in data["__files__"]) or "nothing"


def load_amass(path: str | Path, *, fps: float | None = None, blend_seconds: float = 0.5
               ) -> tuple[np.ndarray, np.ndarray]:
    """Load an AMASS sequence as SMPL poses and root offsets in SMPL's Y-up frame.

    Body joints come from the first 66 pose values; SMPL's two hand joints are set to
    zero unless the file holds exactly 72 values (SMPL layout), which are kept as they
    are. The root offset is the translation relative to frame 0: relative, it does not
    depend on the body shape, whereas the absolute translation under a change of axes
    would (SMPL rotates about the shape-dependent pelvis joint).

    Args:
        path: the ``.npz`` file.
        fps: output frame rate [1/s]; None keeps the file's capture rate.
        blend_seconds: ease-in from the rest pose [s] (frame 0 exactly rest); 0 turns it off.
    Returns:
        ``(poses (T, 72) axis-angle [rad], root_offset (T, 3) [m])``.
    Raises:
        AmassError: the file is missing or malformed; the message names file and key.
    """
    path = Path(path)
    if fps is not None and not fps > 0:
        raise ArgumentError(f"fps must be > 0, got {fps}")
    if not blend_seconds >= 0:
        raise ArgumentError(f"blend_seconds must be >= 0, got {blend_seconds}")
    data = _open(path, ("poses", "trans", *_RATE_KEYS))
    raw = _array(data, "poses", path)
    trans = _array(data, "trans", path)
    rate_key = next((k for k in _RATE_KEYS if k in data), None)
    if rate_key is None:
        raise AmassError(f"{path}: missing the frame rate key (one of {', '.join(_RATE_KEYS)}; "
                         f"the file has: {_listing(data)})")
    rate = float(np.asarray(_array(data, rate_key, path)).reshape(-1)[0])
    if not rate > 0:
        raise AmassError(f"{path}: key {rate_key!r} must be > 0, got {rate}")
    if raw.ndim != 2 or raw.shape[1] < _BODY_VALUES or raw.shape[0] == 0:
        raise AmassError(f"{path}: key 'poses' has shape {raw.shape}, expected (T, 72) or (T, >= 66) with T >= 1")
    if trans.shape != (raw.shape[0], 3):
        raise AmassError(f"{path}: key 'trans' has shape {trans.shape}, expected ({raw.shape[0]}, 3) "
                         "to match 'poses'")
    poses = np.zeros((raw.shape[0], 72))
    width = 72 if raw.shape[1] == 72 else _BODY_VALUES
    poses[:, :width] = raw[:, :width]
    root_rot = Rotation.from_matrix(Z_UP_TO_Y_UP) * Rotation.from_rotvec(poses[:, :3])
    poses[:, :3] = root_rot.as_rotvec()
    root = (trans - trans[0]) @ Z_UP_TO_Y_UP.T
    if fps is not None:
        poses, root = resample(poses, root, rate, fps)
    if blend_seconds > 0:
        poses = blend_from_rest(poses, max(1, int(round(blend_seconds * (rate if fps is None else fps)))))
    return poses, root


def load_amass_betas(path: str | Path, num_betas: int = 10) -> np.ndarray:
    """The body shape of an AMASS sequence: (num_betas,) float64, zero-padded or cut."""
    path = Path(path)
    betas = _array(_open(path, ("betas",)), "betas", path).reshape(-1)
    out = np.zeros(num_betas)
    k = min(num_betas, betas.size)
    out[:k] = betas[:k]
    return out

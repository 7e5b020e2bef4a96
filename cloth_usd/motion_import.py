"""Bring your own motion: a BVH or AMASS file as a new USD shot with an SMPL character.

:func:`import_motion` retargets the file onto SMPL (:mod:`cloth_usd.datagen.bvh`,
:mod:`cloth_usd.datagen.amass`) and writes a new stage as the scene contract asks
(docs/scene_contract.md): a SkelRoot ``/Character`` with the Skeleton
``/Character/Skeleton`` (SMPL's 24 joints and hierarchy, rest = the T-pose of the body
shaped by the betas, ``smpl:betas``, ``smpl:gender``), its SkelAnimation
``/Character/Skeleton/Motion`` and, for each garment file, the garment Mesh referenced
under ``/Character`` with ``cloth:body`` bound to the Skeleton, so that ``cloth-usd
bake`` bakes the shot as it is. The stage is Y up, in metres, at ``fps`` frames per
second, time codes ``start, start + 1, ...``. The USD reading and authoring is
:mod:`cloth_usd.usd.motion_stage`'s.

Shape letters: T frames.
"""

from __future__ import annotations

import logging
import os
import re
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from ._version import __version__
from .core.body import load_body_model, shape_body
from .core.joint_names import as_joint_map
from .core.smpl import JOINT_NAMES, NUM_BETAS
from .errors import ArgumentError, MotionFileError
from .usd.motion_stage import GarmentSource, read_garment_source, write_motion_stage
from .usd.write import check_output_path

__all__ = ["DEFAULT_FPS", "DEFAULT_START", "ImportResult", "bvh_motion", "import_motion", "parse_betas",
           "parse_source_frames"]

log = logging.getLogger(__name__)

#: Frame rate of an imported shot unless ``fps`` says otherwise [1/s]. Mocap is usually
#: captured at 120 fps (CMU, AMASS); a shot at 30 fps bakes four times fewer frames and
#: the garment motion does not need more.
DEFAULT_FPS = 30.0
#: First time code of an imported shot, as in the samples.
DEFAULT_START = 1001.0
#: The skeleton and its SkelRoot.
SKELETON_PATH = "/Character/Skeleton"

_SUFFIXES = (".bvh", ".npz")
_GENDERS = ("neutral", "female", "male")


@dataclass(frozen=True)
class ImportResult:
    """What :func:`import_motion` wrote."""

    output: Path
    """The stage written."""
    rig: str
    """How the motion was read: a BVH rig (``cmu-mb``, ``cmu-daz``, ``mixamo``, ``smpl``,
    ``joint map``, or ``<rig> + joint map``) or ``amass``."""
    source_frames: tuple[int, int]
    """The file's frames used, first and last (0-based, inclusive), at its own rate."""
    frames: int
    """Frames (time codes) written."""
    fps: float
    """Frames per second of the stage [1/s]."""
    start: float
    """First time code."""
    betas: np.ndarray
    """(10,) float64 shape coefficients authored as ``smpl:betas``."""
    gender: str
    """``smpl:gender``."""
    garments: tuple[str, ...]
    """Prim paths of the referenced garments."""


# ------------------------------------------------------------------------- parsing
def parse_betas(text: str) -> np.ndarray:
    """``"B0,B1,..."`` -> (10,) float64 (fewer are padded with zeros).

    Raises:
        ArgumentError: not comma-separated finite numbers, or more than 10.
    """
    try:
        values = [float(v) for v in text.split(",") if v.strip()]
    except ValueError:
        raise ArgumentError(f"--betas {text!r}: expected comma-separated numbers, e.g. 0.6,-0.4,0.2") from None
    return _check_betas(values, f"--betas {text!r}")


def parse_source_frames(text: str) -> tuple[int, int]:
    """``"A:B"`` -> (A, B), the file's frames A..B (0-based, inclusive).

    Raises:
        ArgumentError: not two non-negative integers with A <= B.
    """
    m = re.fullmatch(r"\s*(\d+)\s*:\s*(\d+)\s*", text)
    if m is None or int(m.group(1)) > int(m.group(2)):
        raise ArgumentError(f"--frames {text!r}: expected A:B, the file's frames A to B (0-based, both "
                            "included, A <= B), e.g. 0:299")
    return int(m.group(1)), int(m.group(2))


def _check_betas(values, where: str) -> np.ndarray:
    arr = np.asarray(values, dtype=np.float64).reshape(-1)
    if arr.size > NUM_BETAS or not np.all(np.isfinite(arr)):
        raise ArgumentError(f"{where}: expected at most {NUM_BETAS} finite shape coefficients, got {arr.size}")
    return np.pad(arr, (0, NUM_BETAS - arr.size))


# ------------------------------------------------------------------------- import
def import_motion(
    source: str | os.PathLike,
    output: str | os.PathLike,
    *,
    garments: Sequence[str | os.PathLike] = (),
    betas: Sequence[float] | np.ndarray | None = None,
    gender: str | None = None,
    fps: float | None = None,
    frames: tuple[int, int] | str | None = None,
    joint_map: str | os.PathLike | dict[str, str] | None = None,
    force: bool = False,
    start: float = DEFAULT_START,
    body_model: str | os.PathLike | None = None,
) -> ImportResult:
    """Write a new shot holding an SMPL character that performs ``source``.

    Args:
        source: a BVH file (rigs of :data:`cloth_usd.datagen.bvh.BVH_RIGS`, or any rig
            with ``joint_map``) or an AMASS-style ``.npz`` (``poses``, ``trans``,
            ``mocap_framerate``, optionally ``betas`` and ``gender``).
        output: the stage to write (``.usda``, ``.usdc`` or ``.usd``); written to a
            temporary file beside it and renamed into place.
        garments: USD files each holding garment Meshes (``cloth:category``); each is
            referenced under ``/Character`` and bound to the skeleton. A garment must
            have been made for the body these betas give (its points are the garment
            worn at rest).
        betas: (<= 10,) shape coefficients; None takes the AMASS file's, else the
            betas of the garments' own skeletons (which must agree), else zeros.
        gender: ``neutral``, ``female`` or ``male``; None takes the AMASS file's, else
            ``neutral``. It picks the body model when ``body_model`` is a folder.
        fps: the stage's frame rate [1/s]; None is :data:`DEFAULT_FPS`. The motion is
            resampled (slerp per joint).
        frames: the file's frames to use, ``(A, B)`` or ``"A:B"`` (0-based, inclusive,
            at the file's rate); None uses all of them, except the synthetic T-pose
            that CMU's cgspeed conversions (``cmu-mb``, ``cmu-daz``) put in frame 0.
        joint_map: ``{BVH joint: SMPL joint}`` (a JSON/TOML file or a dict); its
            entries replace the rig's for the same SMPL joints.
        force: replace an existing ``output``.
        start: the first time code.
        body_model: SMPL-format file or folder for the rest joints; None is embedded.

    Raises:
        MotionFileError: the file is missing or malformed, its rig is unknown and no
            joint map is given, or a needed joint is missing (the message names both).
        OutputExistsError: ``output`` exists and ``force`` is false.
        ArgumentError, GarmentError: a bad argument or garment file.
    """
    from .datagen.motion import resample

    source = Path(source)
    if source.suffix.lower() not in _SUFFIXES:
        raise ArgumentError(f"{source}: unknown motion file type {source.suffix!r}; valid: .bvh (BVH) and "
                            ".npz (AMASS)")
    if not source.is_file():
        raise MotionFileError(f"{source}: no such motion file")
    output = check_output_path(output, force=force)
    if fps is not None and not (np.isfinite(fps) and fps > 0):
        raise ArgumentError(f"--fps {fps}: must be a positive number of frames per second")
    out_fps = DEFAULT_FPS if fps is None else float(fps)
    if isinstance(frames, str):
        frames = parse_source_frames(frames)
    if gender is not None and gender not in _GENDERS:
        raise ArgumentError(f"gender {gender!r}: valid values are {', '.join(_GENDERS)}")
    sources = [_garment_source(Path(g)) for g in garments]

    is_bvh = source.suffix.lower() == ".bvh"
    file_betas, file_gender = (None, None) if is_bvh else _amass_shape(source)
    if betas is not None:
        shape = _check_betas(betas, "betas")
    elif file_betas is not None:
        shape = file_betas
    else:
        shape = _garment_betas(sources)
    gender = gender or file_gender or "neutral"
    joints = shape_body(load_body_model(body_model, gender=gender), shape)[1]

    if is_bvh:
        poses, root, rig, used = bvh_motion(source, joints, out_fps, frames, joint_map)
    else:
        poses, root, rate, used = _amass_motion(source, frames)
        poses, root = resample(poses, root, rate, out_fps)
        rig = "amass"
    times = float(start) + np.arange(len(poses), dtype=np.float64)
    provenance = {"cloth_usd": {"tool_version": __version__, "imported_from": source.name, "rig": rig,
                                "source_frames": f"{used[0]}:{used[1]}"}}
    paths = write_motion_stage(output, skeleton_path=SKELETON_PATH, poses=poses, root_positions=joints[0] + root,
                               times=times, fps=out_fps, betas=shape, gender=gender, joints=joints,
                               garments=sources, custom_data=provenance)
    log.info("%s: %s, file frames %d:%d -> %d frames at %g fps in %s", source, rig, used[0], used[1],
             len(times), out_fps, output)
    return ImportResult(output=output, rig=rig, source_frames=used, frames=len(times), fps=out_fps,
                        start=float(start), betas=shape, gender=gender, garments=paths)


def bvh_motion(source: Path, joints: np.ndarray, fps: float, frames: tuple[int, int] | None, joint_map
               ) -> tuple[np.ndarray, np.ndarray, str, tuple[int, int]]:
    """A BVH clip as ``import-motion`` reads it: its known rig (or ``joint_map``), frames
    ``frames`` (default: all but a CMU conversion's synthetic T-pose frame), retargeted at
    ``fps`` onto the rest joints ``joints`` (24, 3) [m], not eased in.

    Returns:
        poses (T, 72) [rad], root offsets (T, 3) [m], the rig's name and the frames used.
    """
    from .datagen.bvh import read_rigged_bvh, retarget_bvh, trim_bvh

    user = as_joint_map(joint_map)
    entries = None if user is None else {k: JOINT_NAMES[v] for k, v in user.entries.items()}
    bvh, rig, mapping, first = read_rigged_bvh(source, entries, hint="; pass --joint-map FILE, a JSON object "
                                                                      "{\"bvh joint\": \"SMPL joint\"}")
    name = rig if user is None else ("joint map" if rig is None else f"{rig} + joint map")
    if bvh.num_frames == 0:
        raise MotionFileError(f"{source}: the file has no frames")
    if frames is None:
        frames = (first, bvh.num_frames - 1)
    elif frames[1] >= bvh.num_frames:
        raise ArgumentError(f"--frames {frames[0]}:{frames[1]}: {source} has frames 0:{bvh.num_frames - 1}")
    bvh = trim_bvh(bvh, *frames)
    poses, root = retarget_bvh(bvh, mapping=mapping, fps=fps, up_axis=None, blend_seconds=0.0,
                               smpl_joints=joints)
    return poses, root, name, frames


def _amass_shape(source: Path) -> tuple[np.ndarray | None, str | None]:
    """The betas (10,) and gender an AMASS file holds, None where it holds none."""
    from .datagen.amass import load_amass_betas

    with np.load(source, allow_pickle=False) as npz:
        names = set(npz.files)
        gender = None
        if "gender" in names:
            try:
                raw = npz["gender"]
            except ValueError:  # a pickled object array
                raw = None
            if raw is not None and raw.dtype.kind in "SU" and raw.size == 1:
                value = raw.reshape(-1)[0]
                value = (value.decode() if isinstance(value, bytes) else str(value)).strip().lower()
                if value not in _GENDERS:
                    raise MotionFileError(f"{source}: key 'gender' is {value!r}; valid: {', '.join(_GENDERS)}")
                gender = value
    betas = load_amass_betas(source) if "betas" in names else None
    return betas, gender


def _amass_motion(source: Path, frames: tuple[int, int] | None
                  ) -> tuple[np.ndarray, np.ndarray, float, tuple[int, int]]:
    """Poses (T, 72) [rad] and root offsets (T, 3) [m] at the file's rate, that rate and the frames used."""
    from .datagen.amass import load_amass

    poses, root = load_amass(source, blend_seconds=0.0)
    with np.load(source, allow_pickle=False) as npz:
        key = next(k for k in ("mocap_framerate", "mocap_frame_rate") if k in npz.files)
        rate = float(np.asarray(npz[key]).reshape(-1)[0])
    if frames is None:
        frames = (0, len(poses) - 1)
    elif frames[1] >= len(poses):
        raise ArgumentError(f"--frames {frames[0]}:{frames[1]}: {source} has frames 0:{len(poses) - 1}")
    a, b = frames
    return poses[a:b + 1], root[a:b + 1] - root[a], rate, frames


# ------------------------------------------------------------------------- garments
def _garment_source(path: Path) -> GarmentSource:
    """A garment file's garments, their skeletons' betas checked."""
    src = read_garment_source(path)
    for body, betas in zip(src.body_paths, src.betas):
        if betas is not None:
            _check_betas(betas, f"{body}.smpl:betas")
    return src


def _garment_betas(sources: Sequence[GarmentSource]) -> np.ndarray:
    """The betas the garments were made for (they must agree), or zeros."""
    found = [(s.file, _check_betas(b, "")) for s in sources for b in s.betas if b is not None]
    for file, b in found[1:]:
        if not np.allclose(b, found[0][1], atol=1e-6):
            raise ArgumentError(f"--garment {found[0][0]} and {file} were made for different bodies "
                                "(their skeletons' smpl:betas differ); pass --betas")
    if found:
        log.info("betas %s from the garments' skeleton", np.round(found[0][1], 3).tolist())
        return found[0][1]
    return np.zeros(NUM_BETAS)

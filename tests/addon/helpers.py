"""Constants and shot builders shared by the add-on tests (no bpy needed here)."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

ROOT = Path(__file__).resolve().parents[2]
ADDON_ID = "cloth_usd_blender"
REPO = "cloth_usd_dev"
MODULE = f"bl_ext.{REPO}.{ADDON_ID}"
"""The add-on's module name when enabled from the test extension repository."""


def _tube(body_vertices: np.ndarray, joints: np.ndarray, rings: int = 8, segments: int = 24,
          ease: float = 0.02) -> tuple[np.ndarray, np.ndarray]:
    """A quad tube around the torso, from below the pelvis to the chest.

    Returns (N, 3) float64 points [m] in the body's rest frame and (M, 4) int quads.
    """
    centre_x = joints[0, 0]
    points = []
    for y in np.linspace(joints[0, 1] - 0.05, joints[12, 1] - 0.08, rings):
        band = body_vertices[(np.abs(body_vertices[:, 1] - y) < 0.02)
                             & (np.abs(body_vertices[:, 0] - centre_x) < 0.17)]
        centre = band.mean(axis=0)
        radius = np.abs(band - centre).max(axis=0) + ease
        a = np.linspace(0.0, 2.0 * np.pi, segments, endpoint=False)
        points.append(np.stack([centre[0] + radius[0] * np.cos(a), np.full(segments, y),
                                centre[2] + radius[2] * np.sin(a)], axis=1))
    quads = [[r * segments + s, r * segments + (s + 1) % segments,
              (r + 1) * segments + (s + 1) % segments, (r + 1) * segments + s]
             for r in range(rings - 1) for s in range(segments)]
    return np.concatenate(points), np.array(quads)


def _walk(frames: int) -> tuple[np.ndarray, np.ndarray]:
    """A simple walk: swinging hips and shoulders, a torso twist, and the root moving
    forward (+Z). Returns (T, 72) axis-angle poses [rad] and (T, 3) root offsets [m]."""
    from cloth_usd.core.smpl import JOINT_NAMES

    j = {name: i for i, name in enumerate(JOINT_NAMES)}
    s = np.sin(2.0 * np.pi * np.arange(frames) / 24.0)
    poses = np.zeros((frames, 24, 3))
    poses[:, j["left_hip"], 0], poses[:, j["right_hip"], 0] = -0.4 * s, 0.4 * s
    poses[:, j["spine1"], 1], poses[:, j["spine3"], 1] = 0.1 * s, -0.12 * s
    poses[:, j["left_shoulder"], 2], poses[:, j["right_shoulder"], 2] = -1.1, 1.1
    poses[:, j["left_shoulder"], 0], poses[:, j["right_shoulder"], 0] = 0.4 * s, -0.4 * s
    root = np.zeros((frames, 3))
    root[:, 2] = 0.045 * np.arange(frames)
    return poses.reshape(frames, 72), root


def make_tube_shot(path: Path, *, up: str = "Y", meters_per_unit: float = 1.0, frames: int = 24,
                   broken: str | None = None, ease: float = 0.02) -> Path:
    """A walking character wearing a tube, saved at ``path``; time codes 1001...

    ``broken``: ``"nan"`` makes a garment point NaN, ``"joint"`` renames the left elbow
    joint, so that a bake must fail. ``ease`` [m]: the tube's clearance over the body (a
    negative one puts it in the body).
    """
    from pxr import Usd, UsdGeom, UsdSkel, Vt

    from cloth_usd.core.body import load_body_model, shape_body
    from cloth_usd.errors import BodyModelError
    from cloth_usd.usd.author import author_garment, author_skeleton, set_stage_metadata

    try:
        body = load_body_model()
    except BodyModelError as exc:
        pytest.skip(f"needs the embedded body model: {exc}")
    betas = np.zeros(10)
    betas[:2] = [0.5, -0.3]
    vertices, joints = shape_body(body, betas)
    poses, root = _walk(frames)
    times = 1001.0 + np.arange(frames)
    points, quads = _tube(vertices, joints, ease=ease)
    path.parent.mkdir(parents=True, exist_ok=True)
    stage = Usd.Stage.CreateNew(str(path))
    set_stage_metadata(stage, up_axis=up, meters_per_unit=meters_per_unit, fps=24.0,
                       start=times[0], end=times[-1])
    skel = author_skeleton(stage, "/Character/Skeleton", joint_positions=joints, betas=betas,
                           poses=poses, root_positions=joints[0] + root, times=times)
    tube = author_garment(stage, "/Character/Tube", points=points, faces=quads, body_path=skel)
    if broken == "nan":
        attr = UsdGeom.Mesh.Get(stage, tube).GetPointsAttr()
        values = np.array(attr.Get(), dtype=np.float32)
        values[7] = np.nan
        attr.Set(Vt.Vec3fArray.FromNumpy(values))
    elif broken == "joint":
        attr = UsdSkel.Skeleton.Get(stage, skel).GetJointsAttr()
        attr.Set([str(j).replace("left_elbow", "elbow_L") for j in attr.Get()])
    elif broken is not None:
        raise ValueError(f"broken={broken!r}")
    stage.GetRootLayer().Save()
    return path

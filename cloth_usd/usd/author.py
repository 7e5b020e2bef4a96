"""Writing SMPL characters and garments INTO a new stage, as the scene contract asks.

Used by samples, tests and the data factory to build scenes; never used to edit a
user's source layers. Inputs are in cloth_usd's internal frame (metres, Y-up, SMPL's
axes) and are converted to the stage's ``upAxis`` and ``metersPerUnit``, which the
caller sets first (see :func:`set_stage_metadata`).

Conventions of what is authored:

- A Skeleton's joint space is the internal frame in stage units: joint translations
  are internal positions divided by ``metersPerUnit`` and every rest rotation is the
  identity (SMPL's T-pose). The up-axis change is an ``xformOp:transform`` on the
  Skeleton prim itself (for Z-up stages, +90 degrees about X), so exporters and
  viewers see an ordinary Y-up rig placed on a Z-up stage.
- Garment points are authored in the garment prim's own space and stage units.

Shape letters: T frames, N garment vertices, J joints (24).
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np
from pxr import Gf, Sdf, Usd, UsdGeom, UsdSkel, Vt

from cloth_usd.core.scene import Category, Tier
from cloth_usd.core.smpl import JOINT_NAMES, NUM_BETAS, NUM_JOINTS, PARENTS, POSE_DIM
from cloth_usd.errors import ArgumentError
from cloth_usd.usd.read import stage_to_internal

__all__ = ["set_stage_metadata", "author_skeleton", "author_garment", "smpl_joint_paths"]

_GENDERS = ("neutral", "female", "male")
_EARLIEST = Usd.TimeCode.EarliestTime()


def set_stage_metadata(
    stage: Usd.Stage,
    *,
    up_axis: str = "Y",
    meters_per_unit: float = 1.0,
    fps: float = 24.0,
    start: float | None = None,
    end: float | None = None,
) -> None:
    """Author ``upAxis``, ``metersPerUnit``, time codes and frames per second (both
    ``fps``) and, when given, the start and end time codes on the root layer."""
    if up_axis not in ("Y", "Z"):
        raise ArgumentError(f"up_axis is {up_axis!r}; valid values are Y, Z")
    if not meters_per_unit > 0.0:
        raise ArgumentError(f"meters_per_unit is {meters_per_unit}; pass a positive number")
    if not fps > 0.0:
        raise ArgumentError(f"fps is {fps}; pass a positive number")
    UsdGeom.SetStageUpAxis(stage, UsdGeom.Tokens.y if up_axis == "Y" else UsdGeom.Tokens.z)
    UsdGeom.SetStageMetersPerUnit(stage, float(meters_per_unit))
    stage.SetTimeCodesPerSecond(float(fps))
    stage.SetFramesPerSecond(float(fps))
    if start is not None:
        stage.SetStartTimeCode(float(start))
    if end is not None:
        stage.SetEndTimeCode(float(end))


def smpl_joint_paths() -> list[str]:
    """The 24 SMPL joint paths in SMPL order: ``"pelvis"``, ``"pelvis/left_hip"``, ..."""
    paths: list[str] = []
    for j, name in enumerate(JOINT_NAMES):
        paths.append(name if PARENTS[j] < 0 else f"{paths[PARENTS[j]]}/{name}")
    return paths


def author_skeleton(
    stage: Usd.Stage,
    path: str | Sdf.Path,
    *,
    joint_positions: np.ndarray,
    betas: np.ndarray,
    gender: str = "neutral",
    poses: np.ndarray | None = None,
    root_positions: np.ndarray | None = None,
    times: np.ndarray | None = None,
) -> str:
    """Define an SMPL Skeleton (and its SkelRoot and animation) at ``path``.

    The parent of ``path`` becomes a ``SkelRoot`` unless it or an ancestor already
    is one (so ``/Char/Skel`` gives SkelRoot ``/Char``). The Skeleton gets SMPL's
    joint paths, rest and bind transforms, ``smpl:betas`` and ``smpl:gender``. With
    ``poses``, a ``UsdSkel.Animation`` child ``<path>/Motion`` is bound through
    ``skel:animationSource``, with rotations and translations sampled at ``times``
    and constant unit scales.

    Args:
        path: Skeleton prim path, with a parent below the pseudo-root.
        joint_positions: (24, 3) float rest joint positions [m], internal frame
            (e.g. the body model's ``J(betas)``).
        betas: (B,) float shape coefficients, B <= 10.
        gender: ``neutral``, ``female`` or ``male``.
        poses: (T, 72) float axis-angle [rad], SMPL's; None for no animation.
        root_positions: (T, 3) float posed pelvis positions [m], internal frame;
            None keeps the pelvis at its rest position.
        times: (T,) float time codes; None means 0, 1, ..., T-1.

    Returns:
        The Skeleton's path as a string.
    """
    path = _check_path(path, "path")
    joints = _check_array(joint_positions, (NUM_JOINTS, 3), "joint_positions")
    betas_arr = np.asarray(betas, dtype=np.float64).reshape(-1)
    if betas_arr.size > NUM_BETAS or not np.isfinite(betas_arr).all():
        raise ArgumentError(f"betas must be at most {NUM_BETAS} finite values, got {betas_arr.size}")
    if gender not in _GENDERS:
        raise ArgumentError(f"gender is {gender!r}; valid values are {', '.join(_GENDERS)}")
    _ensure_skel_root(stage, path.GetParentPath())
    skel = UsdSkel.Skeleton.Define(stage, path)
    _set_skeleton_xform(stage, skel)
    scale = 1.0 / _meters_per_unit(stage)
    local_rest = _local_translations(joints) * scale
    skel.CreateJointsAttr(smpl_joint_paths())
    skel.CreateRestTransformsAttr(_translation_matrices(local_rest))
    skel.CreateBindTransformsAttr(_translation_matrices(joints * scale))
    prim = skel.GetPrim()
    prim.CreateAttribute("smpl:betas", Sdf.ValueTypeNames.FloatArray).Set(
        Vt.FloatArray.FromNumpy(betas_arr.astype(np.float32))
    )
    token, uniform = Sdf.ValueTypeNames.Token, Sdf.VariabilityUniform
    prim.CreateAttribute("smpl:gender", token, variability=uniform).Set(gender)
    if poses is not None:
        anim_path = path.AppendChild("Motion")
        _author_animation(stage, anim_path, local_rest, poses, root_positions, times, scale)
        UsdSkel.BindingAPI.Apply(prim).CreateAnimationSourceRel().SetTargets([anim_path])
    return str(path)


def author_garment(
    stage: Usd.Stage,
    path: str | Sdf.Path,
    *,
    points: np.ndarray,
    faces: np.ndarray | Sequence[Sequence[int]],
    category: str | Category = "tshirt",
    body_path: str | Sdf.Path,
    tier: str | Tier | None = None,
    enabled: bool = True,
) -> str:
    """Define a garment Mesh at ``path`` as the scene contract describes it.

    Points are converted from the internal frame into the prim's own space (its
    local-to-world at the earliest time, and the stage's units and up axis).

    Args:
        points: (N, 3) float rest-pose points [m], internal frame.
        faces: (M, 3) int triangles, or a list of polygons (each >= 3 indices).
        category: ``tshirt``, ``dress`` or ``trousers``.
        body_path: the character's Skeleton prim (``cloth:body`` target).
        tier: optional ``cloth:tier`` override: ``skinning``, ``coarse`` or ``detail``.
        enabled: authored as ``cloth:enabled``.

    Returns:
        The Mesh's path as a string.
    """
    path = _check_path(path, "path")
    body = _check_path(body_path, "body_path")
    pts = _check_array(points, (None, 3), "points")
    counts, indices = _polygons(faces, len(pts))
    category = _choice(category, Category, "category")
    tier = None if tier is None else _choice(tier, Tier, "tier")
    mesh = UsdGeom.Mesh.Define(stage, path)
    to_local = np.linalg.inv(stage_to_internal(stage) @ _local_to_world(stage, mesh.GetPrim()))
    local = pts @ to_local[:3, :3].T + to_local[:3, 3]
    mesh.CreatePointsAttr(Vt.Vec3fArray.FromNumpy(local.astype(np.float32)))
    mesh.CreateFaceVertexCountsAttr(Vt.IntArray.FromNumpy(counts))
    mesh.CreateFaceVertexIndicesAttr(Vt.IntArray.FromNumpy(indices))
    mesh.CreateExtentAttr(Vt.Vec3fArray.FromNumpy(np.stack([local.min(0), local.max(0)]).astype(np.float32)))
    mesh.CreateSubdivisionSchemeAttr(UsdGeom.Tokens.none)
    prim = mesh.GetPrim()
    token = Sdf.ValueTypeNames.Token
    prim.CreateAttribute("cloth:category", token, variability=Sdf.VariabilityUniform).Set(category.value)
    if tier is not None:
        prim.CreateAttribute("cloth:tier", token, variability=Sdf.VariabilityUniform).Set(tier.value)
    prim.CreateAttribute("cloth:enabled", Sdf.ValueTypeNames.Bool).Set(bool(enabled))
    prim.CreateRelationship("cloth:body").SetTargets([body])
    return str(path)


# ------------------------------------------------------------------------- helpers


def _ensure_skel_root(stage: Usd.Stage, parent: Sdf.Path) -> None:
    """Make ``parent`` a SkelRoot unless it or an ancestor already is one."""
    if parent == Sdf.Path.absoluteRootPath:
        raise ArgumentError(
            "path must have a parent to become the SkelRoot, e.g. /Char/Skel, not a root prim"
        )
    for ancestor in parent.GetPrefixes():
        prim = stage.GetPrimAtPath(ancestor)
        if prim and prim.IsA(UsdSkel.Root):
            return
    prim = stage.GetPrimAtPath(parent)
    if prim and prim.GetTypeName() not in ("", "Xform", "Scope"):
        raise ArgumentError(
            f"<{parent}> is a {prim.GetTypeName()}; the Skeleton's parent must be a SkelRoot, "
            "an Xform or a new prim"
        )
    UsdSkel.Root.Define(stage, parent)


def _set_skeleton_xform(stage: Usd.Stage, skel: UsdSkel.Skeleton) -> None:
    """Give the Skeleton prim the transform that makes its space internal axes in stage units.

    The Skeleton's local-to-world becomes the rotation from internal to stage axes
    (identity for Y-up, +90 degrees about X for Z-up), compensating for any parent
    transform at the earliest time. Nothing is authored when that is the identity.
    """
    stage_to_internal_axes = stage_to_internal(stage)[:3, :3] / _meters_per_unit(stage)
    world = np.eye(4)
    world[:3, :3] = stage_to_internal_axes.T
    local = np.linalg.inv(_local_to_world(stage, skel.GetPrim().GetParent())) @ world
    if not np.allclose(local, np.eye(4), atol=1e-12):
        skel.MakeMatrixXform().Set(Gf.Matrix4d(local.T.tolist()))


def _author_animation(
    stage: Usd.Stage,
    path: Sdf.Path,
    local_rest: np.ndarray,
    poses: np.ndarray,
    root_positions: np.ndarray | None,
    times: np.ndarray | None,
    scale: float,
) -> None:
    """A UsdSkel.Animation with rotations/translations sampled at each time code.

    Args:
        local_rest: (24, 3) local rest translations [stage units].
        poses: (T, 72) axis-angle [rad]; root_positions (T, 3) [m] or None;
        times: (T,) or None; scale: stage units per metre.
    """
    poses = _check_array(poses, (None, POSE_DIM), "poses")
    num_frames = len(poses)
    if times is None:
        times = np.arange(num_frames, dtype=np.float64)
    times = _check_array(times, (num_frames,), "times")
    if root_positions is not None:
        root_positions = _check_array(root_positions, (num_frames, 3), "root_positions")
    anim = UsdSkel.Animation.Define(stage, path)
    anim.CreateJointsAttr(smpl_joint_paths())
    anim.CreateScalesAttr(Vt.Vec3hArray.FromNumpy(np.ones((NUM_JOINTS, 3), dtype=np.float16)))
    quats = _axis_angle_to_quat_xyzw(poses.reshape(num_frames, NUM_JOINTS, 3))
    rot_attr = anim.CreateRotationsAttr()
    trans_attr = anim.CreateTranslationsAttr()
    for i, t in enumerate(times):
        tc = Usd.TimeCode(float(t))
        translations = local_rest.copy()
        if root_positions is not None:
            translations[0] = root_positions[i] * scale
        rot_attr.Set(Vt.QuatfArray.FromNumpy(quats[i].astype(np.float32)), tc)
        trans_attr.Set(Vt.Vec3fArray.FromNumpy(translations.astype(np.float32)), tc)


def _axis_angle_to_quat_xyzw(aa: np.ndarray) -> np.ndarray:
    """(..., 3) axis-angle [rad] -> (..., 4) unit quaternions (x, y, z, w), Gf's memory order."""
    theta = np.linalg.norm(aa, axis=-1, keepdims=True)
    xyz = aa * (0.5 * np.sinc(theta / (2.0 * np.pi)))  # axis * sin(theta / 2)
    return np.concatenate([xyz, np.cos(0.5 * theta)], axis=-1)


def _local_translations(joints: np.ndarray) -> np.ndarray:
    """(24, 3) joint offsets from their SMPL parent (the root keeps its position)."""
    local = joints.copy()
    local[1:] -= joints[PARENTS[1:]]
    return local


def _translation_matrices(translations: np.ndarray) -> Vt.Matrix4dArray:
    """(J, 3) translations -> Vt.Matrix4dArray of pure translations (row convention)."""
    m = np.tile(np.eye(4), (len(translations), 1, 1))
    m[:, 3, :3] = translations
    return Vt.Matrix4dArray.FromNumpy(m)


def _polygons(faces, num_points: int) -> tuple[np.ndarray, np.ndarray]:
    """Faces -> (F,) int32 faceVertexCounts and flat int32 faceVertexIndices."""
    if isinstance(faces, np.ndarray) and faces.ndim == 2:  # (M, K) faces of K vertices each
        counts = np.full(len(faces), faces.shape[1], dtype=np.int32)
        indices = faces.reshape(-1).astype(np.int64)
    else:
        polys = [np.asarray(f, dtype=np.int64).reshape(-1) for f in faces]
        counts = np.array([len(p) for p in polys], dtype=np.int32)
        indices = np.concatenate(polys) if polys else np.zeros(0, dtype=np.int64)
    if counts.size == 0:
        raise ArgumentError("faces is empty; pass (M, 3) triangles or a list of polygons")
    if counts.min() < 3:
        face = int(np.argmin(counts))
        raise ArgumentError(f"face {face} has {counts[face]} vertices; each needs at least 3")
    if indices.min() < 0 or indices.max() >= num_points:
        raise ArgumentError(f"faces index outside the {num_points} points")
    return counts, indices.astype(np.int32)


def _choice(value, enum_cls: type, name: str):
    """``value`` as a member of ``enum_cls``; ArgumentError listing the valid values."""
    try:
        return enum_cls(value)
    except ValueError:
        valid = ", ".join(e.value for e in enum_cls)
        raise ArgumentError(f"{name} is {value!r}; valid values are {valid}") from None


def _check_array(value, shape: tuple, name: str) -> np.ndarray:
    """float64 array of ``shape`` (None = any size), finite; ArgumentError otherwise."""
    arr = np.asarray(value, dtype=np.float64)
    if arr.ndim != len(shape) or any(s is not None and s != a for s, a in zip(shape, arr.shape)):
        want = "(" + ", ".join("any" if s is None else str(s) for s in shape) + ")"
        raise ArgumentError(f"{name} must have shape {want}, got {arr.shape}")
    if not np.isfinite(arr).all():
        raise ArgumentError(f"{name} has non-finite values")
    return arr


def _check_path(path, name: str) -> Sdf.Path:
    """An absolute prim path; ArgumentError otherwise."""
    p = Sdf.Path(str(path))
    if not (p.IsAbsolutePath() and p.IsPrimPath()):
        raise ArgumentError(f"{name} is {str(path)!r}; pass an absolute prim path such as /Char/Skel")
    return p


def _meters_per_unit(stage: Usd.Stage) -> float:
    """The stage's metersPerUnit (0.01 when unauthored, as USD says)."""
    return float(UsdGeom.GetStageMetersPerUnit(stage))


def _local_to_world(stage: Usd.Stage, prim: Usd.Prim) -> np.ndarray:
    """(4, 4) local-to-world at the earliest time, column convention (identity at the root)."""
    if not prim or prim.GetPath() == Sdf.Path.absoluteRootPath:
        return np.eye(4)
    return np.array(UsdGeom.XformCache(_EARLIEST).GetLocalToWorldTransform(prim)).T

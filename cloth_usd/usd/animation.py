"""Reading a baked shot (or a cache and its scene) as plain arrays for the game exports.

``cloth-usd convert`` and ``cloth-usd preview`` take what ``bake`` wrote: a shot layer
(``bake --shot``, which sublayers the cache above the scene) or the cache layer alone,
whose provenance names the scene it was baked from. The garment's points at every
time sample of the cache come back in the internal frame (metres, Y-up), which is also
glTF's, with its triangles and UVs.

Shape letters: T frames, N garment vertices, M triangles.
"""

from __future__ import annotations

import logging
import os
from pathlib import Path

import numpy as np
from pxr import Sdf, Usd, UsdGeom

from ..core.animation import MeshAnimation, SkinnedAnimation, axis_angle_to_quaternion
from ..core.body import load_body_model, shape_body
from ..core.frames import canonical_motion
from ..core.smpl import JOINT_NAMES
from ..errors import ArgumentError, GarmentError, SceneError
from .read import garment_from_internal, open_stage, read_motion, read_scene
from .write import cache_layer_info

__all__ = ["open_baked_stage", "read_garment_animation", "read_body_animation"]

_log = logging.getLogger(__name__)


def open_baked_stage(path: str | os.PathLike, *, scene: str | os.PathLike | None = None) -> Usd.Stage:
    """The composed stage of a bake: a shot layer as it is, or a cache over its scene.

    Args:
        path: a shot layer (``bake --shot``), any stage whose garments have time-sampled
            points, or a cache layer (``bake -o``).
        scene: the scene a cache was baked from; default: the ``source_layer`` its
            provenance records (relative to the working folder, then to the cache).

    Raises:
        SceneError: the file is not a stage, or a cache whose scene cannot be found.
    """
    path = Path(path)
    info = cache_layer_info(path)
    source = ((info.provenance.get("cloth_usd") or {}).get("source_layer") if info else None)
    layer = Sdf.Layer.FindOrOpen(str(path)) if info else None
    is_cache = bool(source) and layer is not None and not list(layer.subLayerPaths) and not any(
        spec.specifier == Sdf.SpecifierDef for spec in layer.rootPrims)
    if not is_cache and scene is None:
        return open_stage(path)
    scene_path = Path(scene) if scene is not None else _find_source(Path(source), path)
    if not scene_path.is_file():
        raise SceneError(f"{path}: a cache layer; its scene {scene_path} does not exist; pass the shot layer "
                         "(bake --shot) or --scene SCENE.usda")
    scene_stage = open_stage(scene_path)
    root = Sdf.Layer.CreateAnonymous("baked.usda")
    root.subLayerPaths.append(str(path.resolve()))
    root.subLayerPaths.append(str(scene_path.resolve()))
    stage = Usd.Stage.Open(root)
    for key in ("upAxis", "metersPerUnit", "timeCodesPerSecond", "framesPerSecond"):
        if scene_stage.HasAuthoredMetadata(key):
            stage.SetMetadata(key, scene_stage.GetMetadata(key))
    return stage


def _find_source(source: Path, cache: Path) -> Path:
    """The cache's recorded source layer, as given, else relative to the cache's folder."""
    if source.is_absolute() or source.is_file():
        return source
    beside = cache.parent / source
    return beside if beside.is_file() else source


def read_garment_animation(stage: Usd.Stage, *, garment: str | None = None) -> MeshAnimation:
    """A garment's baked points at every time sample, with its triangles and UVs.

    Args:
        garment: prim path of the garment; default: the only garment with time-sampled
            points (an error when there are several).

    Raises:
        GarmentError: no baked garment, several and none chosen, or a garment whose points
            have fewer than 2 time samples or change count between samples.
    """
    scene = read_scene(stage)
    where = stage.GetRootLayer().identifier
    baked = [g for g in scene.garments
             if UsdGeom.Mesh(stage.GetPrimAtPath(g.prim_path)).GetPointsAttr().GetNumTimeSamples() >= 2]
    if garment is not None:
        chosen = [g for g in scene.garments if g.prim_path == garment]
        if not chosen:
            names = ", ".join(g.prim_path for g in scene.garments) or "none"
            raise ArgumentError(f"--garment {garment}: no garment at this path in {where} (garments: {names})")
        g = chosen[0]
    elif len(baked) == 1:
        g = baked[0]
    elif not baked:
        raise GarmentError(f"{where}: no garment has baked (time-sampled) points; pass a shot or cache "
                           "written by `cloth-usd bake`")
    else:
        raise ArgumentError(f"{where}: several baked garments; pick one with --garment "
                            f"({', '.join(b.prim_path for b in baked)})")
    prim = stage.GetPrimAtPath(g.prim_path)
    mesh = UsdGeom.Mesh(prim)
    attr = mesh.GetPointsAttr()
    codes = np.asarray(attr.GetTimeSamples(), dtype=np.float64)
    if codes.size < 2:
        raise GarmentError(f"{where} <{g.prim_path}>: points have {codes.size} time samples; bake the "
                           "garment first (cloth-usd bake SCENE -o CACHE --shot SHOT)")
    n = g.rest_points.shape[0]
    local = np.empty((codes.size, n, 3))
    for i, t in enumerate(codes):
        value = attr.Get(float(t))
        if value is None or len(value) != n:
            got = 0 if value is None else len(value)
            raise GarmentError(f"{where} <{g.prim_path}>: points at time code {t:g} have {got} entries, the "
                               f"mesh has {n}; re-bake the cache for this scene")
        local[i] = np.asarray(value, dtype=np.float64)
    to_internal = np.linalg.inv(garment_from_internal(stage, g.prim_path, codes))  # (T, 4, 4)
    points = np.einsum("tij,tnj->tni", to_internal[:, :3, :3], local) + to_internal[:, None, :3, 3]
    triangles, corners = _triangles_and_corners(mesh)
    if str(mesh.GetOrientationAttr().Get()) == "leftHanded":
        triangles, corners = triangles[:, ::-1].copy(), corners[:, ::-1].copy()
    uvs, vertex_map, triangles = _uvs(mesh, triangles, corners, n, f"{where} <{g.prim_path}>")
    if vertex_map is not None:
        points = points[:, vertex_map]
    tcps = float(stage.GetTimeCodesPerSecond())
    return MeshAnimation(name=g.prim_path, points=points, triangles=triangles, times=(codes - codes[0]) / tcps,
                         time_codes=codes, fps=tcps, uvs=uvs, vertex_map=vertex_map, body_path=g.body_path)


def _triangles_and_corners(mesh: UsdGeom.Mesh) -> tuple[np.ndarray, np.ndarray]:
    """Fan triangles (M, 3) of point indices and (M, 3) of face-vertex (corner) indices."""
    counts = np.asarray(mesh.GetFaceVertexCountsAttr().Get(), dtype=np.int64)
    indices = np.asarray(mesh.GetFaceVertexIndicesAttr().Get(), dtype=np.int64)
    per_face = counts - 2
    face = np.repeat(np.arange(counts.size), per_face)
    k = np.arange(face.size) - np.repeat(np.cumsum(per_face) - per_face, per_face) + 1
    first = (np.cumsum(counts) - counts)[face]
    corners = np.stack([first, first + k, first + k + 1], axis=1)
    return indices[corners], corners


def _uvs(mesh: UsdGeom.Mesh, triangles: np.ndarray, corners: np.ndarray, n: int, where: str):
    """``(uvs (N', 2) or None, vertex_map (N',) or None, triangles)`` from ``primvars:st``.

    Vertex or varying UVs keep the points as they are; face-varying UVs split a point
    into one vertex per distinct UV (``vertex_map`` says which point each vertex is).
    """
    primvar = UsdGeom.PrimvarsAPI(mesh.GetPrim()).GetPrimvar("st")
    if not primvar or not primvar.HasValue():
        return None, None, triangles
    values = np.asarray(primvar.ComputeFlattened(), dtype=np.float64).reshape(-1, 2)
    interp = primvar.GetInterpolation()
    if interp in (UsdGeom.Tokens.vertex, UsdGeom.Tokens.varying) and values.shape[0] == n:
        return values, None, triangles
    if interp == UsdGeom.Tokens.faceVarying and values.shape[0] > corners.max():
        corner_uv = values[corners.ravel()]
        key = np.concatenate([triangles.reshape(-1, 1).astype(np.float64), corner_uv], axis=1)
        unique, inverse = np.unique(key, axis=0, return_inverse=True)
        return unique[:, 1:], unique[:, 0].astype(np.int64), inverse.reshape(-1, 3).astype(np.int64)
    _log.warning("%s: primvars:st has %s interpolation and %d values; UVs left out", where, interp,
                 values.shape[0])
    return None, None, triangles


def read_body_animation(stage: Usd.Stage, body_path: str, time_codes: np.ndarray, *,
                        body_model: str | os.PathLike | None = None) -> SkinnedAnimation:
    """A character's SMPL body as a skinned mesh posed at ``time_codes`` (see
    :class:`~cloth_usd.core.animation.SkinnedAnimation`; SMPL's pose correctives are left out).

    Args:
        body_path: the Skeleton prim (a garment's ``cloth:body``).
        time_codes: (T,) time codes.
        body_model: SMPL-format file or folder (default: the embedded model).
    """
    scene = read_scene(stage)
    chars = [c for c in scene.characters if c.prim_path == body_path]
    if not chars:
        raise SceneError(f"{stage.GetRootLayer().identifier} <{body_path}>: no SMPL character at this path")
    char = chars[0]
    codes = np.asarray(time_codes, dtype=np.float64)
    body = load_body_model(body_model, gender=char.gender)
    v_shaped, joints = shape_body(body, char.betas)
    motion = canonical_motion(char, read_motion(stage, char, codes), joints)
    t = codes.shape[0]
    return SkinnedAnimation(
        name=char.prim_path, rest_vertices=np.asarray(v_shaped, dtype=np.float64),
        triangles=np.asarray(body.faces, dtype=np.int64), weights=np.asarray(body.weights, dtype=np.float64),
        rest_joints=np.asarray(joints, dtype=np.float64), parents=np.asarray(body.parents, dtype=np.int64),
        joint_names=tuple(JOINT_NAMES), rotations=axis_angle_to_quaternion(motion.poses.reshape(t, -1, 3)),
        root_translation=motion.transl + joints[0],
        times=(codes - codes[0]) / float(stage.GetTimeCodesPerSecond()))

"""The USD side of ``import-motion``: garment files read, the imported shot authored.

:func:`read_garment_source` finds the garment Meshes of a garment file and how their
parents' space maps into the internal frame; :func:`write_motion_stage` authors the shot
(the SMPL character, its motion, the garments referenced and bound) and writes it
atomically. The motion itself is read and retargeted in :mod:`cloth_usd.motion_import`.

Shape letters: T frames, J joints.
"""

from __future__ import annotations

import os
import tempfile
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Mapping, Sequence

import numpy as np
from pxr import Gf, Sdf, Tf, Usd, UsdGeom

from ..errors import ArgumentError, GarmentError, OutputWriteError, SceneError
from .author import author_skeleton, set_stage_metadata
from .read import open_stage, stage_to_internal

__all__ = ["GarmentSource", "read_garment_source", "write_motion_stage"]


@dataclass(frozen=True)
class GarmentSource:
    """The garment Meshes of one garment file."""

    file: Path
    prim_paths: tuple[str, ...]
    """Garment Mesh prims in ``file``."""
    to_internal: tuple[np.ndarray, ...]
    """(4, 4) float64 per prim: its parent's space -> the internal frame (column convention)."""
    body_paths: tuple[str | None, ...]
    """Per prim: the Skeleton its ``cloth:body`` targets in ``file``, None without one."""
    betas: tuple[np.ndarray | None, ...]
    """Per prim: (B,) float64 ``smpl:betas`` of that skeleton as authored (not checked),
    None if unauthored."""


def read_garment_source(path: Path) -> GarmentSource:
    """The garment Meshes (``cloth:category``) of a garment file: its default prim when that
    is one, else all of them.

    Raises:
        ArgumentError: no such file. GarmentError: unreadable, or it holds no garment.
    """
    if not path.is_file():
        raise ArgumentError(f"--garment {path}: no such file")
    try:
        stage = open_stage(path)
    except SceneError as exc:
        raise GarmentError(f"--garment {path}: {exc}") from None
    meshes = [p for p in stage.Traverse() if p.IsA(UsdGeom.Mesh) and p.HasAttribute("cloth:category")]
    default = stage.GetDefaultPrim()
    chosen = [default] if default and default in meshes else meshes
    if not chosen:
        raise GarmentError(f"--garment {path}: holds no garment (a Mesh with a cloth:category attribute, "
                           "e.g. one written by cloth_usd.usd.author.author_garment)")
    cache = UsdGeom.XformCache(Usd.TimeCode.EarliestTime())
    s2i = stage_to_internal(stage)
    to_internal, bodies, betas = [], [], []
    for prim in chosen:
        parent = prim.GetParent()
        world = np.eye(4) if parent.IsPseudoRoot() else np.array(cache.GetLocalToWorldTransform(parent)).T
        to_internal.append(s2i @ world)
        body, value = _body_betas(stage, prim)
        bodies.append(body)
        betas.append(value)
    return GarmentSource(file=path, prim_paths=tuple(str(p.GetPath()) for p in chosen),
                         to_internal=tuple(to_internal), body_paths=tuple(bodies), betas=tuple(betas))


def _body_betas(stage, prim) -> tuple[str | None, np.ndarray | None]:
    rel = prim.GetRelationship("cloth:body")
    targets = rel.GetTargets() if rel else []
    body = stage.GetPrimAtPath(targets[0]) if len(targets) == 1 else None
    attr = body.GetAttribute("smpl:betas") if body else None
    value = attr.Get() if attr and attr.HasAuthoredValue() else None
    path = str(body.GetPath()) if body else None
    return path, None if value is None else np.asarray(list(value), dtype=np.float64)


def write_motion_stage(output: Path, *, skeleton_path: str, poses: np.ndarray, root_positions: np.ndarray,
                       times: np.ndarray, fps: float, betas: np.ndarray, gender: str, joints: np.ndarray,
                       garments: Sequence[GarmentSource], custom_data: Mapping[str, Any]) -> tuple[str, ...]:
    """Author the shot and write it atomically (Y up, metres); returns the garments'
    prim paths.

    Args:
        skeleton_path: the Skeleton, under its SkelRoot (the default prim).
        poses: (T, 72) float64 axis-angle [rad]; root_positions: (T, 3) pelvis [m]; times: (T,).
        betas: (10,) float64; joints: (J, 3) the rest joints [m].
        garments: referenced under the SkelRoot and bound to the skeleton, each in an Xform
            holding its ``to_internal`` where that is not the identity.
        custom_data: the root layer's ``customLayerData``.
    Raises:
        OutputWriteError: USD could not write the file.
    """
    # Authored in a temporary file beside the output, so that the garments' relative
    # references resolve as they will in the output (in memory, USD warns it cannot open them).
    fd, tmp = tempfile.mkstemp(prefix=f".{output.stem}.", suffix=f".tmp{output.suffix}", dir=output.parent)
    os.close(fd)
    os.unlink(tmp)
    try:
        try:
            stage = Usd.Stage.CreateNew(tmp)
        except Tf.ErrorException as exc:
            raise OutputWriteError(f"{output}: USD could not create the stage (at {tmp}): {exc}") from None
        placed = _author_shot(stage, output, skeleton_path=skeleton_path, poses=poses, root_positions=root_positions,
                              times=times, fps=fps, betas=betas, gender=gender, joints=joints, garments=garments)
        layer = stage.GetRootLayer()
        layer.customLayerData = dict(custom_data)
        if not layer.Save():
            raise OutputWriteError(f"{output}: USD could not write the stage (to {tmp}); check the folder's "
                                   "permissions and free space")
        del stage, layer
        os.replace(tmp, output)
    finally:
        if os.path.exists(tmp):
            os.unlink(tmp)
    return placed


def _author_shot(stage: Usd.Stage, output: Path, *, skeleton_path: str, poses: np.ndarray, root_positions: np.ndarray,
                 times: np.ndarray, fps: float, betas: np.ndarray, gender: str, joints: np.ndarray,
                 garments: Sequence[GarmentSource]) -> tuple[str, ...]:
    """The character, its motion and the garments on ``stage``; the garments' prim paths."""
    set_stage_metadata(stage, up_axis="Y", meters_per_unit=1.0, fps=fps, start=times[0], end=times[-1])
    skel = author_skeleton(stage, skeleton_path, joint_positions=joints, betas=betas, gender=gender,
                           poses=poses, root_positions=root_positions, times=times)
    root = Sdf.Path(skeleton_path).GetParentPath()
    stage.SetDefaultPrim(stage.GetPrimAtPath(root))
    taken = {Sdf.Path(skeleton_path).name}
    placed: list[str] = []
    for src in garments:
        asset = os.path.relpath(src.file.resolve(), output.resolve().parent).replace(os.sep, "/")
        for prim_path, to_internal in zip(src.prim_paths, src.to_internal):
            name = _unique(Sdf.Path(prim_path).name, taken)
            parent = root
            if not np.allclose(to_internal, np.eye(4), atol=1e-9):  # the garment's units or axes differ
                xf = UsdGeom.Xform.Define(stage, parent.AppendChild(name + "_space"))
                xf.MakeMatrixXform().Set(Gf.Matrix4d(to_internal.T.tolist()))
                parent = xf.GetPath()
            prim = stage.DefinePrim(parent.AppendChild(name))
            prim.GetReferences().AddReference(asset, Sdf.Path(prim_path))
            prim.CreateRelationship("cloth:body", custom=True).SetTargets([Sdf.Path(skel)])
            placed.append(str(prim.GetPath()))
    return tuple(placed)


def _unique(name: str, taken: set[str]) -> str:
    out, k = name, 1
    while out in taken or out + "_space" in taken:
        out, k = f"{name}_{k}", k + 1
    taken.add(out)
    return out

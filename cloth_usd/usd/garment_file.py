"""Write a made garment as a USD file per the scene contract: the T-posed character it was
made for (a Skeleton with its betas) and the garment Mesh worn by it, with UVs from the
sewing pattern as an indexed face-varying ``primvars:st``.

The file is written under a temporary name and renamed into place. Shape letters: K garment
vertices, M triangles, N pattern (UV) vertices.
"""

from __future__ import annotations

import os
from pathlib import Path
from typing import Mapping

import numpy as np
from pxr import Sdf, Usd, UsdGeom, Vt

from ..errors import OutputWriteError
from .author import author_garment, author_skeleton, set_stage_metadata
from .write import _temp_path, check_output_path

__all__ = ["write_garment_file"]


def write_garment_file(path: str | Path, *, points: np.ndarray, faces, st: np.ndarray | None,
                       st_indices: np.ndarray | None, category: str, betas: np.ndarray, joints: np.ndarray,
                       prim_name: str | None = None, custom: Mapping | None = None,
                       force: bool = False) -> Path:
    """Author ``/Character/Skeleton`` (rest pose) and ``/Character/<Category>`` into a new layer.

    Args:
        points: (K, 3) float garment worn at rest [m], canonical body frame (Y up, metres).
        faces: (M, 3) int triangles, or a list of polygons (each >= 3 vertex indices).
        st: (N, 2) float UV coordinates, or None for no ``primvars:st``.
        st_indices: (M, 3) int the UV index of each triangle corner, or (C,) of each polygon
            corner in order (face-varying).
        betas: (10,) the body's shape; joints: (24, 3) its rest joints [m].
        custom: JSON-able values for the layer's ``customLayerData`` (how it was made).
        force: replace an existing file.
    Returns:
        The path written.
    """
    path = check_output_path(path, force=force)
    tmp = _temp_path(path)
    try:
        stage = Usd.Stage.CreateNew(str(tmp))
        set_stage_metadata(stage, up_axis="Y", meters_per_unit=1.0, fps=24.0)
        skel = author_skeleton(stage, "/Character/Skeleton", joint_positions=joints, betas=betas)
        name = prim_name or category.capitalize()
        mesh_path = author_garment(stage, f"/Character/{name}", points=points, faces=faces, category=category,
                                   body_path=skel)
        if st is not None:
            mesh = UsdGeom.Mesh(stage.GetPrimAtPath(mesh_path))
            primvar = UsdGeom.PrimvarsAPI(mesh).CreatePrimvar("st", Sdf.ValueTypeNames.TexCoord2fArray,
                                                              UsdGeom.Tokens.faceVarying)
            primvar.Set(Vt.Vec2fArray.FromNumpy(np.asarray(st, dtype=np.float32)))
            primvar.SetIndices(Vt.IntArray.FromNumpy(np.asarray(st_indices, dtype=np.int32).ravel()))
        stage.SetDefaultPrim(stage.GetPrimAtPath("/Character"))
        if custom:
            stage.GetRootLayer().customLayerData = {"cloth_usd": dict(custom)}
        stage.GetRootLayer().Save()
        del stage
        os.replace(tmp, path)
    except Exception as exc:
        if tmp.exists():
            tmp.unlink()
        if isinstance(exc, OSError):
            raise OutputWriteError(f"{path}: could not write ({exc})") from exc
        raise
    return path

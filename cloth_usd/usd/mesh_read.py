"""Read any polygon mesh from a USD file, as modelled (for ``cloth-usd garment fit``): the
first Mesh prim (or the one named), its points in world space and stage units, its
polygons and its ``primvars:st``.

Shape letters: N vertices, C polygon corners, U UV coordinates.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
from pxr import Usd, UsdGeom

from ..garments.source import GarmentFitError, SourceMesh

__all__ = ["read_usd_mesh"]


def read_usd_mesh(path: str | Path, prim_path: str | None = None) -> SourceMesh:
    """The Mesh at ``prim_path`` (default: the first Mesh in the stage) of a USD file."""
    path = Path(path)
    try:
        stage = Usd.Stage.Open(str(path))
    except Exception as exc:  # pxr raises Tf.ErrorException
        raise GarmentFitError(f"{path}: not a readable USD file ({str(exc).splitlines()[0][:120]})") from exc
    if stage is None:
        raise GarmentFitError(f"{path}: not a readable USD file")
    if prim_path:
        prim = stage.GetPrimAtPath(prim_path)
        if not prim or not prim.IsA(UsdGeom.Mesh):
            raise GarmentFitError(f"{path}: no Mesh prim at {prim_path}")
    else:
        prim = next((p for p in stage.Traverse() if p.IsA(UsdGeom.Mesh)), None)
        if prim is None:
            raise GarmentFitError(f"{path}: the stage holds no Mesh prim")
    mesh = UsdGeom.Mesh(prim)
    time = Usd.TimeCode.EarliestTime()
    points = np.asarray(mesh.GetPointsAttr().Get(time) or [], dtype=np.float64).reshape(-1, 3)
    if len(points):
        xf = np.asarray(UsdGeom.Xformable(prim).ComputeLocalToWorldTransform(time), dtype=np.float64)
        points = points @ xf[:3, :3] + xf[3, :3]  # USD matrices act on row vectors
    counts = np.asarray(mesh.GetFaceVertexCountsAttr().Get() or [], dtype=np.int64)
    indices = np.asarray(mesh.GetFaceVertexIndicesAttr().Get() or [], dtype=np.int64)
    uv = uv_indices = None
    primvar = UsdGeom.PrimvarsAPI(prim).GetPrimvar("st")
    if primvar and primvar.HasValue():
        values = np.asarray(primvar.Get(time), dtype=np.float64).reshape(-1, 2)
        idx = np.asarray(primvar.GetIndices(time), dtype=np.int64) if primvar.IsIndexed() else None
        interp = primvar.GetInterpolation()
        if interp == UsdGeom.Tokens.faceVarying:
            uv, uv_indices = values, idx if idx is not None else np.arange(len(indices))
        elif interp in (UsdGeom.Tokens.vertex, UsdGeom.Tokens.varying):
            uv, uv_indices = values, (idx[indices] if idx is not None else indices)
        if uv_indices is not None and (len(uv_indices) != len(indices)
                                       or (len(uv_indices) and uv_indices.max() >= len(uv))):
            uv = uv_indices = None
    up = str(UsdGeom.GetStageUpAxis(stage))
    return SourceMesh(points=points, face_counts=counts, face_indices=indices, uv=uv, uv_indices=uv_indices,
                      meters_per_unit=float(UsdGeom.GetStageMetersPerUnit(stage)),
                      up_axis=up if up in ("Y", "Z") else None, source=str(path))

"""A user's garment mesh as it was modelled: polygons, UVs, and what the file says about its
units and up axis. OBJ is read here (vertex order kept, as a MakeHuman ``.mhclo`` binding
indexes it), glTF binary through trimesh, USD in :mod:`cloth_usd.usd.mesh_read`.

Shape letters: N vertices, C polygon corners, U UV coordinates.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import numpy as np

from ..errors import ClothUsdError

__all__ = ["GarmentFitError", "SourceMesh", "read_garment_mesh", "read_obj", "read_glb", "MESH_SUFFIXES"]

#: File types ``cloth-usd garment fit`` reads.
MESH_SUFFIXES = (".obj", ".glb", ".gltf", ".usd", ".usda", ".usdc")


class GarmentFitError(ClothUsdError):
    """A garment mesh cannot be read or cannot be fitted to the body."""


@dataclass(frozen=True)
class SourceMesh:
    """A polygon mesh as its file holds it."""

    points: np.ndarray
    """(N, 3) float64 vertex positions in the file's own units and axes."""
    face_counts: np.ndarray
    """(P,) int64 corners of each polygon."""
    face_indices: np.ndarray
    """(C,) int64 vertex of each corner, polygon after polygon."""
    uv: np.ndarray | None
    """(U, 2) float64 texture coordinates, or None."""
    uv_indices: np.ndarray | None
    """(C,) int64 UV of each corner (face-varying), or None."""
    meters_per_unit: float | None
    """Metres per file unit when the file says (USD ``metersPerUnit``, glTF: 1); None for OBJ."""
    up_axis: str | None
    """``Y`` or ``Z`` when the file says (USD ``upAxis``, glTF: Y); None for OBJ."""
    source: str = ""

    @property
    def num_vertices(self) -> int:
        return int(len(self.points))


def read_obj(path: str | Path) -> SourceMesh:
    """Read a Wavefront OBJ: ``v``, ``vt`` and ``f`` records (any polygon size, negative
    indices allowed); vertex order is kept as in the file."""
    path = Path(path)
    points, uvs, counts, corners, corner_uv = [], [], [], [], []
    try:
        text = path.read_text(encoding="utf-8", errors="replace")
    except OSError as exc:
        raise GarmentFitError(f"{path}: cannot read ({exc.strerror or exc})") from exc
    for number, line in enumerate(text.splitlines(), 1):
        parts = line.split()
        if not parts:
            continue
        try:
            if parts[0] == "v":
                points.append([float(x) for x in parts[1:4]])
            elif parts[0] == "vt":
                uvs.append([float(x) for x in parts[1:3]])
            elif parts[0] == "f":
                face = [p.split("/") for p in parts[1:]]
                idx = [int(f[0]) for f in face]
                counts.append(len(idx))
                corners.extend(i - 1 if i > 0 else len(points) + i for i in idx)
                corner_uv.extend((int(f[1]) - 1 if int(f[1]) > 0 else len(uvs) + int(f[1]))
                                 if len(f) > 1 and f[1] else -1 for f in face)
        except (ValueError, IndexError) as exc:
            raise GarmentFitError(f"{path}:{number}: malformed OBJ record '{line.strip()[:60]}'") from exc
    pts = np.asarray(points, dtype=np.float64).reshape(-1, 3)
    idx = np.asarray(corners, dtype=np.int64)
    if len(idx) and (idx.min() < 0 or idx.max() >= len(pts)):
        raise GarmentFitError(f"{path}: a face indexes a vertex that is not in the file")
    uv_idx = np.asarray(corner_uv, dtype=np.int64)
    has_uv = len(uvs) > 0 and len(uv_idx) > 0 and uv_idx.min() >= 0 and uv_idx.max() < len(uvs)
    return SourceMesh(points=pts, face_counts=np.asarray(counts, dtype=np.int64), face_indices=idx,
                      uv=np.asarray(uvs, dtype=np.float64) if has_uv else None,
                      uv_indices=uv_idx if has_uv else None, meters_per_unit=None, up_axis=None,
                      source=str(path))


def read_glb(path: str | Path) -> SourceMesh:
    """Read a glTF file's meshes (through trimesh; every mesh of the scene, in world space,
    concatenated). glTF is metres and Y-up by its specification."""
    import trimesh

    path = Path(path)
    try:
        scene = trimesh.load(str(path), force="scene", process=False)
    except Exception as exc:  # trimesh raises many kinds for a file it cannot parse
        raise GarmentFitError(f"{path}: not a readable glTF file ({exc})") from exc
    meshes = [g for g in scene.dump() if isinstance(g, trimesh.Trimesh)] if len(scene.geometry) else []
    points, faces, uvs, offset = [], [], [], 0
    for m in meshes:
        points.append(np.asarray(m.vertices, dtype=np.float64))
        faces.append(np.asarray(m.faces, dtype=np.int64) + offset)
        uv = getattr(m.visual, "uv", None)
        uvs.append(np.asarray(uv, dtype=np.float64) if uv is not None and len(uv) == len(m.vertices) else None)
        offset += len(m.vertices)
    pts = np.concatenate(points) if points else np.zeros((0, 3))
    tri = np.concatenate(faces) if faces else np.zeros((0, 3), dtype=np.int64)
    has_uv = bool(uvs) and all(u is not None for u in uvs)
    # glTF splits a vertex wherever its UV (or normal) changes; the cloth must not tear there,
    # so vertices at one position become one (their UVs stay per corner)
    welded, index = _weld(pts)
    return SourceMesh(points=welded, face_counts=np.full(len(tri), 3, dtype=np.int64),
                      face_indices=index[tri.ravel()], uv=np.concatenate(uvs) if has_uv else None,
                      uv_indices=tri.ravel() if has_uv else None, meters_per_unit=1.0, up_axis="Y",
                      source=str(path))


def _weld(points: np.ndarray, tolerance: float = 1e-6) -> tuple[np.ndarray, np.ndarray]:
    """``(unique points (N', 3), (N,) index of each point in them)``: points closer than
    ``tolerance`` times the mesh's size merged, in order of first appearance."""
    if not len(points):
        return points, np.zeros(0, dtype=np.int64)
    size = float(np.ptp(points, axis=0).max()) or 1.0
    keys = np.round(points / (tolerance * size)).astype(np.int64)
    _, first, inverse = np.unique(keys, axis=0, return_index=True, return_inverse=True)
    order = np.argsort(first)  # number the merged points in order of first appearance
    rank = np.empty_like(order)
    rank[order] = np.arange(len(order))
    return points[first[order]], rank[inverse.ravel()]


def read_garment_mesh(path: str | Path) -> SourceMesh:
    """Read a garment mesh by its suffix (:data:`MESH_SUFFIXES`)."""
    path = Path(path)
    if not path.is_file():
        raise GarmentFitError(f"{path}: no such file")
    suffix = path.suffix.lower()
    if suffix == ".obj":
        return read_obj(path)
    if suffix in (".glb", ".gltf"):
        return read_glb(path)
    if suffix in (".usd", ".usda", ".usdc"):
        from ..usd.mesh_read import read_usd_mesh

        return read_usd_mesh(path)
    raise GarmentFitError(f"{path}: unknown mesh type '{suffix}' (valid: {', '.join(MESH_SUFFIXES)})")

"""Reading a baked garment for the exports: fan triangles with their corners, and UVs
(vertex UVs kept, face-varying UVs split into one vertex per point and UV)."""

from __future__ import annotations

import numpy as np
from pxr import Sdf, Usd, UsdGeom, Vt

from cloth_usd.usd.animation import _triangles_and_corners, _uvs


_STAGES: list[Usd.Stage] = []


def _quad_strip(interpolation: str | None):
    """Two quads sharing an edge (6 points); face-varying UVs give the shared edge a seam."""
    stage = Usd.Stage.CreateInMemory()
    mesh = UsdGeom.Mesh.Define(stage, "/M")
    mesh.CreatePointsAttr([(0, 0, 0), (1, 0, 0), (2, 0, 0), (0, 1, 0), (1, 1, 0), (2, 1, 0)])
    mesh.CreateFaceVertexCountsAttr([4, 4])
    mesh.CreateFaceVertexIndicesAttr([0, 1, 4, 3, 1, 2, 5, 4])
    if interpolation == "vertex":
        st = [(0, 0), (0.5, 0), (1, 0), (0, 1), (0.5, 1), (1, 1)]
    elif interpolation == "faceVarying":  # the second quad's UVs are an island of their own
        st = [(0, 0), (0.4, 0), (0.4, 1), (0, 1), (0.6, 0), (1, 0), (1, 1), (0.6, 1)]
    if interpolation:
        pv = UsdGeom.PrimvarsAPI(mesh.GetPrim()).CreatePrimvar("st", Sdf.ValueTypeNames.TexCoord2fArray,
                                                                  interpolation)
        pv.Set(Vt.Vec2fArray(st))
    _STAGES.append(stage)  # a schema object does not keep its in-memory stage alive
    return mesh


def test_fan_triangles_and_their_corners():
    tris, corners = _triangles_and_corners(_quad_strip(None))
    np.testing.assert_array_equal(tris, [[0, 1, 4], [0, 4, 3], [1, 2, 5], [1, 5, 4]])
    np.testing.assert_array_equal(corners, [[0, 1, 2], [0, 2, 3], [4, 5, 6], [4, 6, 7]])


def test_vertex_uvs_are_kept_and_no_uvs_are_none():
    mesh = _quad_strip("vertex")
    tris, corners = _triangles_and_corners(mesh)
    uvs, vertex_map, out = _uvs(mesh, tris, corners, 6, "test")
    assert vertex_map is None and out is tris and uvs.shape == (6, 2)
    mesh = _quad_strip(None)
    assert _uvs(mesh, tris, corners, 6, "test")[0] is None


def test_face_varying_uvs_split_the_seam():
    mesh = _quad_strip("faceVarying")
    tris, corners = _triangles_and_corners(mesh)
    uvs, vertex_map, out = _uvs(mesh, tris, corners, 6, "test")
    assert uvs.shape == (8, 2) and vertex_map.shape == (8,)  # points 1 and 4 are on the seam: 2 vertices each
    np.testing.assert_array_equal(np.sort(vertex_map), [0, 1, 1, 2, 3, 4, 4, 5])
    # every triangle corner keeps its point and gets its own UV
    np.testing.assert_array_equal(vertex_map[out], tris)
    st = np.asarray(UsdGeom.PrimvarsAPI(mesh.GetPrim()).GetPrimvar("st").Get(), dtype=np.float64)
    np.testing.assert_allclose(uvs[out], st[corners], atol=1e-7)

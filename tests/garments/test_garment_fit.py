"""``cloth-usd garment fit``: readers, the MakeHuman binding, the fit by shape (units, up
axis, arm pose, unposing), which pieces a category keeps, and the one-line refusals. Two
tests drape (Newton, a few frames): a piece the body does not hold keeps its place, and the
command end to end."""

from __future__ import annotations

import importlib.util
import json

import numpy as np
import pytest

from cloth_usd.cli import main
from cloth_usd.core.body import lbs, load_body_model, shape_body
from cloth_usd.garments.fit import FitConfig, fit_garment, triangulate_polygons
from cloth_usd.errors import ArgumentError
from cloth_usd.garments.sew import lift_off_skin
from cloth_usd.garments.mhclo import Mhclo, bind_mhclo, load_hm08_map, read_mhclo
from cloth_usd.garments.source import GarmentFitError, SourceMesh, read_glb, read_obj

NEWTON = importlib.util.find_spec("newton") is not None


@pytest.fixture(scope="module")
def body():
    return load_body_model()


@pytest.fixture(scope="module")
def hmap():
    m = load_hm08_map()
    assert m is not None, "models/garments/hm08_map.npz is shipped with the package"
    return m


def _region_mesh(body, joints_wanted, lift=0.01, pose=None):
    """A garment-like patch of the body: its faces whose corners are all mostly skinned to
    ``joints_wanted``, lifted ``lift`` along the normals, posed by ``pose``. Returns
    (rest points (N, 3) lifted in the T-pose, posed points (N, 3), triangles (M, 3))."""
    from cloth_usd.core.features import vertex_normals

    v, j = shape_body(body, np.zeros(10))
    dominant = np.argmax(body.weights, axis=1)
    inside = np.isin(dominant, joints_wanted)
    faces = body.faces[np.all(inside[body.faces], axis=1)]
    used, faces = np.unique(faces, return_inverse=True)
    faces = faces.reshape(-1, 3)
    rest = v[used] + lift * vertex_normals(v, body.faces)[used]
    if pose is None:
        return rest, rest, faces
    skinned = lbs(body, v + lift * vertex_normals(v, body.faces), j, pose[None])[0][0][used]
    return rest, skinned, faces


# --------------------------------------------------------------------------- readers


def test_read_obj_keeps_order_polygons_and_uvs(tmp_path):
    path = tmp_path / "g.obj"
    path.write_text("# a quad and a triangle\nv 0 0 0\nv 1 0 0\nv 1 1 0\nv 0 1 0\nv 2 0 0\n"
                    "vt 0 0\nvt 1 0\nvt 1 1\nvt 0 1\ng shirt\nf 1/1 2/2 3/3 4/4\nf -4/2 -1/1 -3/3\n")
    m = read_obj(path)
    assert m.points.shape == (5, 3) and m.meters_per_unit is None and m.up_axis is None
    np.testing.assert_array_equal(m.face_counts, [4, 3])
    np.testing.assert_array_equal(m.face_indices, [0, 1, 2, 3, 1, 4, 2])
    np.testing.assert_array_equal(m.uv_indices, [0, 1, 2, 3, 1, 0, 2])


def test_read_obj_bad_index_is_one_line(tmp_path):
    path = tmp_path / "bad.obj"
    path.write_text("v 0 0 0\nf 1 2 3\n")
    with pytest.raises(GarmentFitError, match="indexes a vertex"):
        read_obj(path)


def test_triangulate_polygons_fans():
    tri, owner = triangulate_polygons(np.array([4, 3, 5]), np.arange(12))
    assert len(tri) == 2 + 1 + 3
    np.testing.assert_array_equal(np.sort(owner), [0, 0, 1, 2, 2, 2])
    assert {tuple(t) for t in tri[owner == 0]} == {(0, 1, 2), (0, 2, 3)}


def test_read_glb_is_metres_y_up(tmp_path):
    trimesh = pytest.importorskip("trimesh")
    pts = np.array([[0, 0, 0], [0.5, 0, 0], [0, 0.5, 0.1]], dtype=np.float64)
    trimesh.Trimesh(pts, [[0, 1, 2]], process=False).export(tmp_path / "g.glb")
    m = read_glb(tmp_path / "g.glb")
    assert m.meters_per_unit == 1.0 and m.up_axis == "Y"
    np.testing.assert_allclose(m.points, pts, atol=1e-6)


def test_read_usd_mesh_world_space_and_metadata(tmp_path):
    from pxr import Gf, Usd, UsdGeom, Vt

    from cloth_usd.usd.mesh_read import read_usd_mesh

    path = tmp_path / "g.usda"
    stage = Usd.Stage.CreateNew(str(path))
    UsdGeom.SetStageUpAxis(stage, "Z")
    UsdGeom.SetStageMetersPerUnit(stage, 0.01)
    xf = UsdGeom.Xform.Define(stage, "/Root")
    xf.AddTranslateOp().Set(Gf.Vec3d(10, 0, 0))
    mesh = UsdGeom.Mesh.Define(stage, "/Root/Shirt")
    mesh.GetPointsAttr().Set(Vt.Vec3fArray([(0, 0, 0), (1, 0, 0), (1, 1, 0), (0, 1, 0)]))
    mesh.GetFaceVertexCountsAttr().Set([4])
    mesh.GetFaceVertexIndicesAttr().Set([0, 1, 2, 3])
    stage.GetRootLayer().Save()
    m = read_usd_mesh(path)
    assert m.up_axis == "Z" and m.meters_per_unit == pytest.approx(0.01)
    np.testing.assert_allclose(m.points[:, 0], [10, 11, 11, 10])
    assert m.uv is None


# --------------------------------------------------------------------------- MakeHuman binding


def test_read_mhclo(tmp_path):
    path = tmp_path / "g.mhclo"
    path.write_text("# comment\nbasemesh hm08\nx_scale 1 2 1.5\ny_scale 3 4 2.0\nz_scale 5 6 0.5\n"
                    "verts 0\n10 11 12 0.2 0.3 0.5 0.01 0.02 0.03\n7\ndelete_verts\n1 2 3\n")
    m = read_mhclo(path)
    np.testing.assert_array_equal(m.refs, [[10, 11, 12], [7, 7, 7]])
    np.testing.assert_allclose(m.weights, [[0.2, 0.3, 0.5], [1, 0, 0]])
    np.testing.assert_allclose(m.offsets[0], [0.01, 0.02, 0.03])
    assert m.scales[1] == (3, 4, 2.0) and m.basemesh == "hm08"


def test_hm08_map_is_close_to_the_body(hmap):
    # hm08's skin against our body fitted to it (scripts/build_hm08_map.py): measured 6.3 mm p50
    assert hmap.distance_mm["p50"] < 10.0 and hmap.distance_mm["p95"] < 35.0
    assert np.all(np.abs(hmap.lift[hmap.hm_index < 13380]) < 0.06)


def test_binding_puts_a_forearm_sleeve_along_the_t_posed_forearm(body, hmap):
    """Garment vertices bound to hm08 vertices on the left forearm (MakeHuman's A-pose: the
    forearm points down and forward) land, once unposed, beside our T-posed forearm (+X)."""
    from cloth_usd.garments.fit import _unpose

    corner_w = body.weights[body.faces[hmap.triangle]].mean(axis=1)
    forearm = np.flatnonzero((np.argmax(corner_w, axis=1) == 18) & (hmap.hm_index < 13380))[:200]
    refs = np.repeat(hmap.hm_index[forearm][:, None], 3, axis=1)
    scales = tuple((int(hmap.hm_index[0]), int(hmap.hm_index[1]), 1.0) for _ in range(3))
    mh = Mhclo(refs=refs, weights=np.tile([1.0, 0.0, 0.0], (len(refs), 1)), offsets=np.zeros((len(refs), 3)),
               scales=scales, basemesh="hm08")
    posed, weights = bind_mhclo(mh, hmap, body, np.zeros(10))
    v, j = shape_body(body, np.zeros(10))
    assert np.median(posed[:, 1]) < j[18, 1] - 0.1  # A-pose: below the T-posed elbow
    rest = _unpose(posed, weights, j, hmap.pose, body.parents)
    assert np.all(rest[:, 0] > j[18, 0] - 0.02) and np.all(rest[:, 0] < j[20, 0] + 0.02)
    assert np.all(np.linalg.norm(rest[:, 1:] - j[18, 1:], axis=1) < 0.08)  # within a forearm's radius


# --------------------------------------------------------------------------- fit by shape


@pytest.mark.parametrize("up", ["Y", "Z"])
def test_fit_by_shape_recovers_units_axis_pose(body, hmap, up):
    """The body's own torso and arms, 1 cm out, posed into MakeHuman's A-pose, given in
    centimetres (Y or Z up) and shifted: the fit finds the units, the axis and the pose and
    unposes it back to where it was made, within 1 cm (median) and 3 cm (p95)."""
    rest, posed, faces = _region_mesh(body, [3, 6, 9, 13, 14, 16, 17, 18, 19], pose=hmap.pose)
    pts = (posed + [0.05, 0.3, -0.02]) * 100.0
    if up == "Z":
        pts = pts @ np.array([[1.0, 0.0, 0.0], [0.0, 0.0, -1.0], [0.0, 1.0, 0.0]]).T  # (x, y, z) -> (x, -z, y)
    src = SourceMesh(points=pts, face_counts=np.full(len(faces), 3), face_indices=faces.ravel(), uv=None,
                     uv_indices=None, meters_per_unit=None, up_axis=None, source="synthetic")
    fitted = fit_garment(src, "tshirt", np.zeros(10), body=body, config=FitConfig(drape_frames=0))
    r = fitted.report
    assert (r["method"], r["units_m"], r["up_axis"], r["arm_pose"]) == ("shape", 0.01, up, 1.0)
    err = np.linalg.norm(fitted.points - rest, axis=1)
    assert np.median(err) < 0.01 and np.percentile(err, 95) < 0.03, (np.median(err), np.percentile(err, 95))
    assert r["inside_fraction"] < 0.01


def test_fit_keeps_a_t_posed_garment_t_posed(body):
    rest, _, faces = _region_mesh(body, [3, 6, 9, 16, 17, 18, 19])
    src = SourceMesh(points=rest, face_counts=np.full(len(faces), 3), face_indices=faces.ravel(), uv=None,
                     uv_indices=None, meters_per_unit=1.0, up_axis="Y", source="synthetic")
    fitted = fit_garment(src, "tshirt", np.zeros(10), body=body, config=FitConfig(drape_frames=0))
    assert fitted.report["arm_pose"] == 0.0
    assert np.median(np.linalg.norm(fitted.points - rest, axis=1)) < 0.01


def test_tshirt_drops_the_trousers_piece(body):
    top, _, top_f = _region_mesh(body, [3, 6, 9, 16, 17])
    legs, _, leg_f = _region_mesh(body, [4, 5])
    pts = np.concatenate([top, legs])
    faces = np.concatenate([top_f, leg_f + len(top)])
    src = SourceMesh(points=pts, face_counts=np.full(len(faces), 3), face_indices=faces.ravel(), uv=None,
                     uv_indices=None, meters_per_unit=1.0, up_axis="Y", source="synthetic")
    fitted = fit_garment(src, "tshirt", np.zeros(10), body=body, config=FitConfig(drape_frames=0))
    assert len(fitted.points) == len(top) and fitted.report["pieces_dropped"] == 2  # one per leg


def test_a_shirt_with_legs_is_fitted_and_said_to_have_them(body, caplog):
    # a suit in one piece, shirt and trousers (torso, upper arms, thighs and shins): a T-shirt or a
    # dress bundle's models were trained on no such garment
    suit, _, suit_f = _region_mesh(body, [0, 1, 2, 3, 4, 5, 6, 9, 16, 17])
    top, _, top_f = _region_mesh(body, [3, 6, 9, 16, 17])
    for pts, faces, legs in ((suit, suit_f, True), (top, top_f, False)):
        src, _ = _pieces_source((pts, faces))
        for category in ("tshirt", "dress", "trousers"):
            caplog.clear()
            with caplog.at_level("WARNING", logger="cloth_usd"):
                try:
                    fitted = fit_garment(src, category, np.zeros(10), body=body, config=FitConfig(drape_frames=0))
                except GarmentFitError:  # trousers: the top has no piece with legs
                    assert category == "trousers" and not legs
                    continue
            said = [r.getMessage() for r in caplog.records if "it has legs" in r.getMessage()]
            expect = legs and category != "trousers"
            assert len(said) == int(expect), (category, legs, said)
            assert fitted.report.get("legs", False) is expect
            if expect:
                assert said[0].startswith("synthetic: ") and "train-garment" in said[0] and category in said[0]


def _pieces_source(*pieces):
    pts = np.concatenate([p for p, _ in pieces])
    starts = np.cumsum([0] + [len(p) for p, _ in pieces])[:-1]
    faces = np.concatenate([f + k for (_, f), k in zip(pieces, starts)])
    return SourceMesh(points=pts, face_counts=np.full(len(faces), 3), face_indices=faces.ravel(), uv=None,
                      uv_indices=None, meters_per_unit=1.0, up_axis="Y", source="synthetic"), starts


def _button(points, faces, near):
    """A small separate piece: the faces around the vertex nearest ``near``, 3 mm further out."""
    sel = np.any(faces == np.argmin(np.linalg.norm(points - near, axis=1)), axis=1)
    used, tri = np.unique(faces[sel], return_inverse=True)
    return points[used] + [0.0, 0.0, 0.003], tri.reshape(-1, 3)


def test_trousers_keep_the_piece_with_legs_and_its_buttons(body):
    # a bib overall (one piece from the chest down to the knees), a jacket, a button on each
    overall, _, overall_f = _region_mesh(body, [0, 1, 2, 3, 4, 5, 6])
    jacket, _, jacket_f = _region_mesh(body, [9, 13, 14, 16, 17])
    on_overall = _button(overall, overall_f, overall[np.argmax(overall[:, 2])])
    on_jacket = _button(jacket, jacket_f, jacket[np.argmax(jacket[:, 2])])
    src, starts = _pieces_source((jacket, jacket_f), (overall, overall_f), on_overall, on_jacket)
    assert len(on_overall[0]) >= 4 and len(on_jacket[0]) >= 4
    fitted = fit_garment(src, "trousers", np.zeros(10), body=body, config=FitConfig(drape_frames=0))
    assert len(fitted.points) == len(overall) + len(on_overall[0])
    assert fitted.report["pieces_dropped"] == 2  # the jacket and its button
    # as a T-shirt: the jacket and its button (this overall's centre is below the hips)
    fitted = fit_garment(src, "tshirt", np.zeros(10), body=body, config=FitConfig(drape_frames=0))
    assert len(fitted.points) == len(jacket) + len(on_jacket[0]) and fitted.report["pieces_dropped"] == 2


@pytest.mark.skipif(not NEWTON, reason="newton is not installed")
def test_a_piece_the_body_does_not_hold_keeps_its_place(body):
    from cloth_usd.garments.fit import _hang

    sleeves, _, sleeves_f = _region_mesh(body, [16, 17])  # on the arms
    legs, _, legs_f = _region_mesh(body, [4, 5], lift=0.05)  # two tubes wider than the knees
    src, starts = _pieces_source((sleeves, sleeves_f), (legs, legs_f))
    tri = src.face_indices.reshape(-1, 3)
    draped, undraped = _hang(body, np.zeros(10), src.points, tri, 4, "synthetic")
    assert undraped == 2  # one tube per leg fell, and is where it was
    np.testing.assert_array_equal(draped[starts[1]:], legs)
    assert np.median(src.points[:starts[1], 1] - draped[:starts[1], 1]) < 0.03  # the sleeves hang on the arms
    assert not np.array_equal(draped[:starts[1]], sleeves)


def test_flat_and_empty_meshes_are_refused(body):
    plane = SourceMesh(points=np.array([[0, 0, 0], [1, 0, 0], [1, 1, 0], [0, 1, 0.0]]),
                       face_counts=np.array([4]), face_indices=np.arange(4), uv=None, uv_indices=None,
                       meters_per_unit=1.0, up_axis="Y", source="plane.obj")
    with pytest.raises(GarmentFitError, match="flat"):
        fit_garment(plane, "tshirt", np.zeros(10), body=body, config=FitConfig(drape_frames=0))
    empty = SourceMesh(points=np.zeros((0, 3)), face_counts=np.zeros(0, dtype=np.int64),
                       face_indices=np.zeros(0, dtype=np.int64), uv=None, uv_indices=None, meters_per_unit=None,
                       up_axis=None, source="empty.obj")
    with pytest.raises(GarmentFitError, match="no polygons"):
        fit_garment(empty, "tshirt", np.zeros(10), body=body, config=FitConfig(drape_frames=0))


def test_a_mesh_far_from_any_body_shape_is_refused(body):
    """A closed box the size of a torso fits no body: its vertices stay far from the skin."""
    corners = np.array([[x, y, z] for x in (-1, 1) for y in (-1, 1) for z in (-1, 1)], dtype=float) * [0.6, 0.2, 0.5]
    quads = np.array([[0, 1, 3, 2], [4, 6, 7, 5], [0, 4, 5, 1], [2, 3, 7, 6], [0, 2, 6, 4], [1, 5, 7, 3]])
    src = SourceMesh(points=corners, face_counts=np.full(6, 4), face_indices=quads.ravel(), uv=None, uv_indices=None,
                     meters_per_unit=1.0, up_axis="Y", source="box.obj")
    with pytest.raises(GarmentFitError, match="does not fit the body"):
        fit_garment(src, "tshirt", np.zeros(10), body=body, config=FitConfig(drape_frames=0))


# --------------------------------------------------------------------------- the command


@pytest.mark.parametrize("text,message", [("", "no polygons"),
                                          ("v 0 0 0\nv 1 0 0\nv 1 1 0\nv 0 1 0\nf 1 2 3 4\n", "flat")])
def test_cli_refuses_in_one_line(tmp_path, capsys, text, message):
    path = tmp_path / "in.obj"
    path.write_text(text)
    code = main(["garment", "fit", str(path), "-o", str(tmp_path / "out.usda"), "--category", "tshirt"])
    err = capsys.readouterr().err.strip()
    assert code == 2 and len(err.splitlines()) == 1 and message in err
    assert not (tmp_path / "out.usda").exists()


@pytest.mark.skipif(not NEWTON, reason="newton is not installed")
def test_cli_fits_and_drapes_a_small_obj(tmp_path, body, capsys):
    from pxr import Usd, UsdGeom

    rest, _, faces = _region_mesh(body, [16, 17])  # the upper arms' skin: two short sleeves
    keep = np.arange(len(rest))
    assert 100 < len(keep) < 800
    lines = [f"v {x * 10:.5f} {y * 10:.5f} {z * 10:.5f}" for x, y, z in rest]  # decimetres
    lines += [f"vt {u:.4f} {v:.4f}" for u, v in rest[:, :2]]
    lines += [f"f {a + 1}/{a + 1} {b + 1}/{b + 1} {c + 1}/{c + 1}" for a, b, c in faces]
    (tmp_path / "sleeves.obj").write_text("\n".join(lines) + "\n")
    out = tmp_path / "sleeves.usda"
    code = main(["garment", "fit", str(tmp_path / "sleeves.obj"), "-o", str(out), "--category", "tshirt",
                 "--drape-frames", "2"])
    assert code == 0
    said = capsys.readouterr().out
    assert "body vertices (" in said and "before the lift)" in said, said  # the skin through it, lifted
    stage = Usd.Stage.Open(str(out))
    report = json.loads(stage.GetRootLayer().customLayerData["cloth_usd"]["garment_fit"])
    assert 0 <= report["skin_through"] <= report["skin_through_before"], report
    mesh = UsdGeom.Mesh(stage.GetPrimAtPath("/Character/Tshirt"))
    pts = np.asarray(mesh.GetPointsAttr().Get())
    assert pts.shape == rest.shape
    assert mesh.GetPrim().GetAttribute("cloth:category").Get() == "tshirt"
    assert UsdGeom.PrimvarsAPI(mesh).GetPrimvar("st").HasValue()
    assert stage.GetPrimAtPath("/Character/Skeleton").IsValid()
    # 2 frames of drape move it little: the sleeves stay on the arms
    assert np.median(np.linalg.norm(pts - rest, axis=1)) < 0.02


def test_read_glb_welds_vertices_split_at_uv_seams(tmp_path):
    trimesh = pytest.importorskip("trimesh")
    from trimesh.visual import TextureVisuals

    # two triangles sharing an edge, the shared vertices duplicated (as glTF does at a UV seam)
    pts = np.array([[0, 0, 0], [1, 0, 0], [0, 1, 0], [1, 0, 0], [0, 1, 0], [1, 1, 0.2]], dtype=np.float64)
    uv = np.array([[0, 0], [0.5, 0], [0, 0.5], [0.6, 0], [0.6, 0.5], [1, 1]], dtype=np.float64)
    mesh = trimesh.Trimesh(pts, [[0, 1, 2], [3, 5, 4]], visual=TextureVisuals(uv=uv), process=False)
    mesh.export(tmp_path / "seam.glb")
    m = read_glb(tmp_path / "seam.glb")
    assert m.num_vertices == 4
    tri, _ = triangulate_polygons(m.face_counts, m.face_indices)
    assert len(set(tri[0]) & set(tri[1])) == 2  # the two triangles share an edge again
    np.testing.assert_allclose(m.uv[m.uv_indices[3:]], uv[[3, 5, 4]], atol=1e-6)  # UVs per corner kept


# --------------------------------------------------------------------------- a real MakeHuman top

DATA = __import__("pathlib").Path(__file__).parent / "data"


def _sleeves(points: np.ndarray, joints: np.ndarray) -> np.ndarray:
    """(N,) bool: vertices beyond a shoulder joint along the T-posed arm (+-X)."""
    return np.abs(points[:, 0]) > joints[16, 0] + 0.04


@pytest.mark.parametrize("use_mhclo", [True, False])
def test_makehuman_top_sleeves_lie_along_the_t_posed_arms(body, use_mhclo):
    """MakeHuman's sportsuit top (A-pose, decimetres) fitted by its binding and by shape:
    its sleeves end up along the T-posed arms, at shoulder height, the shirt on the skin."""
    from cloth_usd.garments.source import read_garment_mesh

    src = read_garment_mesh(DATA / "makehuman_top.obj")
    mh = read_mhclo(DATA / "makehuman_top.mhclo") if use_mhclo else None
    fitted = fit_garment(src, "tshirt", np.zeros(10), body=body, mhclo=mh, config=FitConfig(drape_frames=0))
    r = fitted.report
    assert r["method"] == ("mhclo" if use_mhclo else "shape") and r["vertices"] == 911
    if not use_mhclo:
        assert (r["units_m"], r["up_axis"], r["arm_pose"]) == (0.1, "Y", 1.0)
    _, j = shape_body(body, np.zeros(10))
    pts = fitted.points
    sleeve = _sleeves(pts, j)
    assert sleeve.sum() > 50 and np.abs(pts[:, 0]).max() > j[16, 0] + 0.08  # sleeves reach along the arms
    assert np.all(np.abs(pts[sleeve, 1] - j[16, 1]) < 0.12)  # at shoulder height, not hanging down
    assert np.all(np.linalg.norm(pts[sleeve][:, 1:] - j[16, 1:], axis=1) < 0.13)
    assert r["inside_fraction"] < 0.01 and r["median_distance_mm"] < 15.0


def test_makehuman_binding_and_shape_fit_agree(body):
    from cloth_usd.garments.source import read_garment_mesh

    src = read_garment_mesh(DATA / "makehuman_top.obj")
    cfg = FitConfig(drape_frames=0)
    bound = fit_garment(src, "tshirt", np.zeros(10), body=body, mhclo=read_mhclo(DATA / "makehuman_top.mhclo"),
                        config=cfg)
    shaped = fit_garment(src, "tshirt", np.zeros(10), body=body, config=cfg)
    gap = np.linalg.norm(bound.points - shaped.points, axis=1)
    # measured: 34 mm median, mostly height: the alignment by shape sets this tight top 28 mm
    # higher on the torso than its binding does (a torso constrains sliding along it weakly)
    assert np.median(gap) < 0.04, np.median(gap)


def test_makehuman_binding_follows_the_betas(body):
    """The binding places the garment on the body of the given shape: a taller, heavier body
    gets a longer, wider top that still does not enter it."""
    from cloth_usd.garments.source import read_garment_mesh

    src = read_garment_mesh(DATA / "makehuman_top.obj")
    mh = read_mhclo(DATA / "makehuman_top.mhclo")
    cfg = FitConfig(drape_frames=0)
    mean = fit_garment(src, "tshirt", np.zeros(10), body=body, mhclo=mh, config=cfg)
    big = fit_garment(src, "tshirt", np.array([2.0, 2.0]), body=body, mhclo=mh, config=cfg)
    assert np.ptp(big.points[:, 0]) > np.ptp(mean.points[:, 0]) + 0.01
    assert big.report["inside_fraction"] < 0.01


def test_cli_fits_a_usd_mesh_z_up_centimetres(tmp_path, body, hmap):
    """A USD garment (Z-up, centimetres, under a transform, A-posed, with UVs) through the
    command, no drape: the file's units and axis are used and the garment comes out T-posed
    on the body, with its polygons and UVs."""
    from pxr import Gf, Sdf, Usd, UsdGeom, Vt

    rest, posed, faces = _region_mesh(body, [3, 6, 9, 13, 14, 16, 17, 18, 19], pose=hmap.pose)
    path = tmp_path / "shirt.usda"
    stage = Usd.Stage.CreateNew(str(path))
    UsdGeom.SetStageUpAxis(stage, "Z")
    UsdGeom.SetStageMetersPerUnit(stage, 0.01)
    UsdGeom.Xform.Define(stage, "/Asset").AddTranslateOp().Set(Gf.Vec3d(0.0, 0.0, 30.0))
    UsdGeom.Mesh.Define(stage, "/Asset/Other").GetPointsAttr().Set(Vt.Vec3fArray([(0, 0, 0)]))
    mesh = UsdGeom.Mesh.Define(stage, "/Asset/Shirt")
    zup = posed * 100.0 @ np.array([[1.0, 0.0, 0.0], [0.0, 0.0, -1.0], [0.0, 1.0, 0.0]]).T
    mesh.GetPointsAttr().Set(Vt.Vec3fArray.FromNumpy((zup - [0.0, 0.0, 30.0]).astype(np.float32)))
    mesh.GetFaceVertexCountsAttr().Set(Vt.IntArray.FromNumpy(np.full(len(faces), 3, dtype=np.int32)))
    mesh.GetFaceVertexIndicesAttr().Set(Vt.IntArray.FromNumpy(faces.ravel().astype(np.int32)))
    st = UsdGeom.PrimvarsAPI(mesh).CreatePrimvar("st", Sdf.ValueTypeNames.TexCoord2fArray, UsdGeom.Tokens.vertex)
    st.Set(Vt.Vec2fArray.FromNumpy(rest[:, :2].astype(np.float32)))
    stage.GetRootLayer().Save()
    out = tmp_path / "fitted.usda"
    assert main(["garment", "fit", str(path), "--prim", "/Asset/Shirt", "-o", str(out), "--category", "tshirt",
                 "--drape-frames", "0"]) == 0
    fitted = Usd.Stage.Open(str(out))
    result = UsdGeom.Mesh(fitted.GetPrimAtPath("/Character/Tshirt"))
    pts = np.asarray(result.GetPointsAttr().Get(), dtype=np.float64)
    assert np.median(np.linalg.norm(pts - rest, axis=1)) < 0.01
    primvar = UsdGeom.PrimvarsAPI(result).GetPrimvar("st")
    uv = np.asarray(primvar.Get())[np.asarray(primvar.GetIndices())]
    corners = np.asarray(result.GetFaceVertexIndicesAttr().Get())
    np.testing.assert_allclose(uv, rest[corners, :2], atol=1e-5)  # each corner keeps its vertex's UV


def test_cli_prim_is_for_usd_only(tmp_path, capsys):
    (tmp_path / "g.obj").write_text("v 0 0 0\n")
    code = main(["garment", "fit", str(tmp_path / "g.obj"), "--prim", "/X", "-o", str(tmp_path / "o.usda"),
                 "--category", "tshirt"])
    assert code == 2 and "--prim /X: only for a USD file" in capsys.readouterr().err


def test_binding_applies_only_where_it_can(body, hmap):
    """The binding needs hm08, the body the map was built for, one line per vertex and
    hm08 vertices the map covers; otherwise the fit says why and falls back to shape."""
    import dataclasses

    from cloth_usd.garments.mhclo import mhclo_applies

    mh = read_mhclo(DATA / "makehuman_top.mhclo")
    assert mhclo_applies(mh, hmap, body, len(mh.refs)) is None
    assert "not hm08" in mhclo_applies(dataclasses.replace(mh, basemesh="hm07"), hmap, body, len(mh.refs))
    assert "not the one" in mhclo_applies(mh, hmap, dataclasses.replace(body, sha256="0" * 64), len(mh.refs))
    assert "the mesh has 5" in mhclo_applies(mh, hmap, body, 5)
    far = dataclasses.replace(mh, refs=np.full_like(mh.refs, 19000))  # an eyelash helper: not mapped
    assert "does not cover" in mhclo_applies(far, hmap, body, len(mh.refs))
    assert mhclo_applies(mh, None, body, len(mh.refs)) == "no hm08 map is installed"


def test_a_fitted_garment_fits_again_in_place(body):
    """A garment already T-posed on the body (a fit's output, short sleeves) is taken as
    T-posed and barely moves: fitting is idempotent."""
    from cloth_usd.garments.source import read_garment_mesh

    src = read_garment_mesh(DATA / "makehuman_top.obj")
    cfg = FitConfig(drape_frames=0)
    first = fit_garment(src, "tshirt", np.zeros(10), body=body, mhclo=read_mhclo(DATA / "makehuman_top.mhclo"),
                        config=cfg)
    again = SourceMesh(points=first.points, face_counts=first.face_counts, face_indices=first.face_indices,
                       uv=first.uv, uv_indices=first.uv_indices, meters_per_unit=1.0, up_axis="Y", source="fitted")
    second = fit_garment(again, "tshirt", np.zeros(10), body=body, config=cfg)
    assert second.report["arm_pose"] == 0.0
    moved = np.linalg.norm(second.points - first.points, axis=1)
    assert np.median(moved) < 0.01, np.median(moved)


@pytest.mark.parametrize("turn", [30.0, 90.0, 137.0, 180.0, 270.0, 344.0])
def test_fit_by_shape_turns_a_garment_that_faces_another_way(body, turn):
    """The body's own torso and arms, turned about the up axis: the fit turns it back, to
    about a degree at angles off its 30-degree grid (before that grid, only quarter turns)."""
    from cloth_usd.core.heading import yaw_matrices

    rest, _, faces = _region_mesh(body, [3, 6, 9, 13, 14, 16, 17, 18, 19])
    src = SourceMesh(points=rest @ yaw_matrices(np.deg2rad(-turn)).T, face_counts=np.full(len(faces), 3),
                     face_indices=faces.ravel(),
                     uv=None, uv_indices=None, meters_per_unit=1.0, up_axis="Y", source="synthetic")
    fitted = fit_garment(src, "tshirt", np.zeros(10), body=body, config=FitConfig(drape_frames=0))
    assert abs((fitted.report["turned_deg"] - turn + 180.0) % 360.0 - 180.0) <= 1.0, fitted.report["turned_deg"]
    err = np.linalg.norm(fitted.points - rest, axis=1)
    assert np.median(err) < 0.01, np.median(err)


def _tube(centre, radius, top, bottom, around=48, rows=12):
    """A vertical open cylinder (points (A * R, 3), triangles) about ``centre`` (x, z) [m]."""
    a = np.linspace(0.0, 2.0 * np.pi, around, endpoint=False)
    y = np.linspace(top, bottom, rows)
    pts = np.array([[centre[0] + radius * np.cos(t), h, centre[1] + radius * np.sin(t)] for h in y for t in a])
    faces = [f for j in range(rows - 1) for i in range(around)
             for f in ((j * around + i, j * around + (i + 1) % around, (j + 1) * around + i),
                       (j * around + (i + 1) % around, (j + 1) * around + (i + 1) % around, (j + 1) * around + i))]
    return pts, np.array(faces)


def _assert_legs_kept_and_skirt_dropped(body, left, right, skirt):
    """Two leg tubes (points, triangles) hung from a waist tube above the crotch make one piece
    with legs, which trousers keep; the ``skirt`` has none and goes."""
    from cloth_usd.core.plausibility import has_legs
    from cloth_usd.garments.fit import _keep_pieces

    _, joints = shape_body(body, np.zeros(10))
    pelvis = joints[0]
    waist = _tube((pelvis[0], pelvis[2]), 0.17, pelvis[1] + 0.1, pelvis[1] - 0.1)
    src, starts = _pieces_source(waist, left, right, skirt)
    tri = src.face_indices.reshape(-1, 3)
    tri = np.concatenate([tri, [[0, starts[1], starts[2]]]])  # the legs hang from the waist: one piece
    trousers = np.zeros(len(src.points), bool)
    trousers[:starts[3]] = True
    assert has_legs(src.points, tri, trousers, pelvis)
    assert not has_legs(src.points, tri, ~trousers, pelvis)
    keep, dropped = _keep_pieces(src.points, tri, "trousers", joints, "synthetic")
    np.testing.assert_array_equal(keep, trousers)
    assert dropped == 1


def test_trousers_on_touching_thighs_keep_their_legs_and_a_skirt_goes(body):
    pelvis = shape_body(body, np.zeros(10))[1][0]
    # two leg tubes whose inner sides come 3 mm from the midline (thighs that touch), joined
    # above the crotch by a waist tube; and a skirt round both legs
    _assert_legs_kept_and_skirt_dropped(
        body, _tube((pelvis[0] + 0.073, pelvis[2]), 0.07, pelvis[1] - 0.1, pelvis[1] - 0.7),
        _tube((pelvis[0] - 0.073, pelvis[2]), 0.07, pelvis[1] - 0.1, pelvis[1] - 0.7),
        _tube((pelvis[0], pelvis[2]), 0.2, pelvis[1] - 0.05, pelvis[1] - 0.5))


def test_hot_pants_keep_their_short_legs_and_a_short_skirt_or_a_slit_shirt_goes(body):
    """Legs that end 15 cm below the hip joints (above where trousers' legs are looked for) are
    found at their openings, a hem of one row of vertices included; a skirt that ends there, and
    a shirt whose side slits part its hem into a front and a back panel, have none."""
    from cloth_usd.core.plausibility import has_legs

    pelvis = shape_body(body, np.zeros(10))[1][0]
    # each leg two rows 5 cm apart: within 2 cm of the hem lies one row, no whole triangle
    _assert_legs_kept_and_skirt_dropped(
        body, _tube((pelvis[0] + 0.09, pelvis[2]), 0.08, pelvis[1] - 0.1, pelvis[1] - 0.15, rows=2),
        _tube((pelvis[0] - 0.09, pelvis[2]), 0.08, pelvis[1] - 0.1, pelvis[1] - 0.15, rows=2),
        _tube((pelvis[0], pelvis[2]), 0.2, pelvis[1] - 0.05, pelvis[1] - 0.15))

    # a tunic to 20 cm below the hips whose bottom 6 cm are slit at both sides: a front and a back flap
    shirt, shirt_f = _tube((pelvis[0], pelvis[2]), 0.18, pelvis[1] + 0.4, pelvis[1] - 0.2, around=48, rows=13)
    a = np.arctan2(shirt[:, 2] - pelvis[2], shirt[:, 0] - pelvis[0])
    low = shirt[:, 1] < pelvis[1] - 0.14
    side = np.abs(np.cos(a)) > 0.97  # the columns at the left and the right
    flaps = shirt_f[~np.any((low & side)[shirt_f], axis=1)]
    whole = np.ones(len(shirt), bool)
    assert not has_legs(shirt, flaps, whole, pelvis)


# --------------------------------------------------------------------------- the lift off the skin


def _grid(n, size, height):
    """A square grid of n x n vertices, ``size`` [m] wide, facing +z, its heights ``height(points)``."""
    xs = np.linspace(-size / 2, size / 2, n)
    x, y = np.meshgrid(xs, xs, indexing="ij")
    points = np.stack([x.ravel(), y.ravel(), np.zeros(n * n)], axis=1)
    i = (np.arange(n - 1)[:, None] * n + np.arange(n - 1)[None]).ravel()
    faces = np.concatenate([np.stack([i, i + n, i + n + 1], 1), np.stack([i, i + n + 1, i + 1], 1)])
    points[:, 2] = height(points)
    return points, faces


def test_lift_off_skin_lifts_a_coarse_garment_off_a_bump_between_its_vertices():
    """A bump of the skin 5 mm high between the vertices of a cloth 2 mm over the skin (3.75 cm apart): it
    lies in front of the cloth's triangles until the lift, then at least the margin behind them; the cloth
    away from the bump stays where it was."""
    from cloth_usd.core.features import vertex_normals
    from cloth_usd.core.postprocess import body_ahead, inner_triangles

    def bump(p):
        return 0.005 * np.exp(-((p[:, 0] - 0.013) ** 2 + (p[:, 1] - 0.007) ** 2) / (2 * 0.01 ** 2))

    skin, skin_faces = _grid(61, 0.3, bump)
    cloth, cloth_faces = _grid(9, 0.3, lambda p: np.full(len(p), 0.002))
    lifted, (before, after) = lift_off_skin(cloth, cloth_faces, skin, skin_faces, margin=0.002)
    assert before > 0 and after == 0, (before, after)
    inner, ring = inner_triangles(cloth_faces, len(cloth))
    ahead = body_ahead(lifted, inner, ring, skin, vertex_normals(skin, skin_faces))[0]
    assert np.nanmax(ahead) <= -0.002 + 1e-9
    ahead_unlifted = body_ahead(cloth, inner, ring, skin, vertex_normals(skin, skin_faces))[0]
    assert np.nanmax(ahead_unlifted) > 0.001  # the test's bump does poke through
    moved = np.linalg.norm(lifted - cloth, axis=1)
    far = np.linalg.norm(cloth[:, :2] - [0.013, 0.007], axis=1) > 0.08
    assert moved[far].max() < 1e-6 and moved.max() > 0.003
    # bounded at the edges' lengths (a sewn garment's bound is its pattern's): a lift lengthens every edge it
    # moves, so none is kept
    held, (before, after) = lift_off_skin(cloth, cloth_faces, skin, skin_faces, margin=0.002, stretch=1.0)
    assert after == before > 0 and np.abs(held - cloth).max() < 1e-9
    with pytest.raises(ArgumentError, match="rest lengths"):
        lift_off_skin(cloth, cloth_faces, skin, skin_faces, margin=0.002, rest_lengths=np.ones(3))


def test_fit_lifts_a_makehuman_top_off_the_skin_between_its_vertices(body):
    """MakeHuman's top fitted without the lift lets body vertices through its triangles; with it (the default)
    fewer, each vertex moved at most 2 cm and no edge stretched past 1.5 x its length unlifted."""
    from cloth_usd.core.postprocess import mesh_edges
    from cloth_usd.garments.source import read_garment_mesh

    src = read_garment_mesh(DATA / "makehuman_top.obj")
    mh = read_mhclo(DATA / "makehuman_top.mhclo")
    plain, lifted = (fit_garment(src, "tshirt", np.zeros(10), body=body, mhclo=mh,
                                 config=FitConfig(drape_frames=0, lift_rounds=rounds)) for rounds in (0, 2))
    assert "skin_through" not in plain.report
    assert lifted.report["skin_through"] < lifted.report["skin_through_before"], lifted.report
    tri, _ = triangulate_polygons(plain.face_counts, plain.face_indices)
    v_rest = shape_body(body, np.zeros(10))[0]
    _, (before, after) = lift_off_skin(plain.points, tri, v_rest, body.faces, margin=0.002, rounds=0)
    assert before == after == lifted.report["skin_through_before"]  # the count is of the unlifted garment
    assert np.linalg.norm(lifted.points - plain.points, axis=1).max() < 0.02
    e = mesh_edges(tri)
    length = [np.linalg.norm(p[e[:, 1]] - p[e[:, 0]], axis=1) for p in (plain.points, lifted.points)]
    assert (length[1] / length[0]).max() <= 1.5 + 1e-9

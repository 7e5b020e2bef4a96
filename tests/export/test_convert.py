"""`cloth-usd convert` and `preview` on the real sample: a baked shot or its cache alone,
glTF within the error asked for and valid, the body as the body model poses it, VAT,
units and axes, and one-line errors."""

from __future__ import annotations

import dataclasses
import json
from pathlib import Path

import numpy as np
import pytest

from cloth_usd.cli import main
from cloth_usd.core.body import lbs, load_body_model
from cloth_usd.export.convert import read_baked
from cloth_usd.export.gltf import _top4, read_glb
from tests.export.helpers import ROOT, chromium, pixel_fractions, play_gltf, validate

WALK = ROOT / "samples" / "walk_tshirt" / "scene.usda"
ZUP = ROOT / "samples" / "walk_tshirt_zup_cm" / "scene.usda"

pytestmark = pytest.mark.slow


@pytest.fixture(scope="module")
def baked(tmp_path_factory) -> tuple[Path, Path]:
    """The sample walk baked (skinning tier, every 2nd frame: 48 frames): (shot, cache)."""
    out = tmp_path_factory.mktemp("baked")
    assert main(["bake", str(WALK), "-o", str(out / "cache.usdc"), "--shot", str(out / "shot.usda"),
                 "--frames", "1001:1096:2", "--no-progress"]) == 0
    return out / "shot.usda", out / "cache.usdc"


def test_glb_with_body_is_the_cache_and_the_posed_body(baked, tmp_path, capsys):
    shot, _ = baked
    out = tmp_path / "walk.glb"
    assert main(["convert", str(shot), "-o", str(out), "--with-body", "--max-error", "0.5"]) == 0
    said = capsys.readouterr().out
    assert "48 frames, 3516 vertices as" in said and f"wrote {out}" in said
    (report,) = validate(out)
    assert report["errors"] == 0 and report["warnings"] == 0, report["messages"]

    anim, body = read_baked(shot, with_body=True)
    doc, blob = read_glb(out.read_bytes())
    # glTF skinning has no pose correctives and 4 joints a vertex: the reference poses the
    # body model so, and the full model is measured against it below.
    full = load_body_model()
    joints, weights = _top4(full.weights)
    top4 = np.zeros_like(full.weights)
    for k in range(4):  # zero-weight entries name joint 0: add, not assign
        np.add.at(top4, (np.arange(top4.shape[0]), joints[:, k].astype(np.int64)), weights[:, k])
    model = dataclasses.replace(full, posedirs=None, weights=top4)
    worst = 0.0

    for frame in (0, 20, 47):
        shown = play_gltf(doc, blob, frame)
        assert np.linalg.norm(shown["Tshirt"] - anim.points[frame], axis=1).max() <= 0.5e-3 + 2e-6
        poses = np.concatenate([_axis_angle(body.rotations[frame])])[None]
        verts, _ = lbs(model, body.rest_vertices, body.rest_joints, poses,
                       (body.root_translation[frame] - body.rest_joints[0])[None])
        np.testing.assert_allclose(shown["body"], verts[0], atol=2e-4)
        exact, _ = lbs(full, body.rest_vertices, body.rest_joints, poses,
                       (body.root_translation[frame] - body.rest_joints[0])[None])
        worst = max(worst, float(np.linalg.norm(shown["body"] - exact[0], axis=1).max()))
    assert worst < 0.03  # what the 4-joint, corrective-free glTF body costs against SMPL
    assert np.ptp(anim.points[:, :, 2].mean(axis=1)) > 1.0  # the walk goes somewhere


def _axis_angle(q: np.ndarray) -> np.ndarray:
    """(J, 4) quaternions -> (72,) axis-angle."""
    w = np.clip(q[:, 3], -1, 1)
    angle = 2 * np.arccos(np.abs(w))
    axis = q[:, :3] * np.sign(w)[:, None]
    norm = np.linalg.norm(axis, axis=1, keepdims=True)
    return (np.where(norm > 1e-12, axis / np.maximum(norm, 1e-12), 0) * angle[:, None]).ravel()


def test_cache_alone_reads_its_scene_from_provenance(baked, tmp_path, capsys):
    shot, cache = baked
    assert main(["convert", str(cache), "-o", str(tmp_path / "a.glb"), "--targets", "16"]) == 0
    assert main(["convert", str(shot), "-o", str(tmp_path / "b.glb"), "--targets", "16"]) == 0
    a, b = (read_glb((tmp_path / n).read_bytes()) for n in ("a.glb", "b.glb"))
    np.testing.assert_array_equal(play_gltf(*a, 30)["Tshirt"], play_gltf(*b, 30)["Tshirt"])
    assert "16 morph targets" in capsys.readouterr().out


def test_zup_centimetre_shot_comes_out_in_metres_y_up(tmp_path):
    assert main(["bake", str(ZUP), "-o", str(tmp_path / "c.usdc"), "--shot", str(tmp_path / "s.usda"),
                 "--frames", "1001:1011", "--no-progress"]) == 0
    zup, _ = read_baked(tmp_path / "s.usda")
    assert main(["bake", str(WALK), "-o", str(tmp_path / "y.usdc"), "--shot", str(tmp_path / "ys.usda"),
                 "--frames", "1001:1011", "--no-progress"]) == 0
    yup, _ = read_baked(tmp_path / "ys.usda")
    # Another body and shirt (scripts/make_samples.py), so about the same size, not the same:
    # a metre-sized T-shirt standing up (a unit slip would be 100x, an axis slip would put
    # its depth, about 0.3 m, on y).
    size, reference = np.ptp(zup.points[0], axis=0), np.ptp(yup.points[0], axis=0)
    assert 0.4 < size[1] < 1.0 and size[2] < 0.45
    np.testing.assert_allclose(size[1], reference[1], rtol=0.15)


def test_vat_folder_from_the_cli(baked, tmp_path, capsys):
    shot, _ = baked
    assert main(["convert", str(shot), "--format", "vat", "-o", str(tmp_path / "vat"), "--vat-format", "png16"]) == 0
    said = capsys.readouterr().out
    max_mm = float(said.split("max ")[1].split(" mm")[0])
    assert max_mm < 0.2  # 16 bits over a ~4 m walk: 0.06 mm steps
    data = json.loads((tmp_path / "vat" / "Tshirt_data.json").read_text())
    assert data["frames"] == 48 and data["texture"]["width"] == 3516
    assert data["fps"] == data["material"]["Houdini FPS"] == 12.0  # every 2nd frame of a 24 fps shot


def test_preview_page_from_the_cli(baked, tmp_path, capsys):
    shot, _ = baked
    page = tmp_path / "p.html"
    assert main(["preview", str(shot), "-o", str(page)]) == 0
    text = page.read_text(encoding="utf-8")
    assert '"frames": 48' in text and "Tshirt" in text
    assert main(["preview", str(shot), "-o", str(page)]) == 2
    assert "already exists; pass --force" in capsys.readouterr().err
    # The walk goes 4 m: garment and body are on screen at its start, middle and end (a
    # body culled by its rest-pose bounds, or the end wrapping to the start, would not be).
    for frame in (1, 24, 48):
        png = tmp_path / f"frame{frame}.png"
        chromium(page, tmp_path, screenshot=png, size="480,360", budget_ms=1500, fragment=f"#frame={frame}")
        garment, skin = pixel_fractions(png)
        assert garment > 0.005 and skin > 0.005, (frame, garment, skin)


@pytest.mark.parametrize("args, message", [
    (["--format", "vat", "--targets", "8"], "apply to glTF only"),
    (["--max-error", "-1"], "--max-error -1 mm: must be a positive number"),
])
def test_bad_arguments_are_one_line(baked, tmp_path, capsys, args, message):
    shot, _ = baked
    out = tmp_path / ("v" if "vat" in args else "x.glb")
    assert main(["convert", str(shot), "-o", str(out), *args]) == 2
    err = capsys.readouterr().err
    assert message in err and err.count("\n") == 1
    assert not out.exists()


def test_unbaked_scene_and_lost_scene_are_one_line(baked, tmp_path, capsys):
    assert main(["convert", str(WALK), "-o", str(tmp_path / "x.glb")]) == 2
    assert "no garment has baked (time-sampled) points" in capsys.readouterr().err
    _, cache = baked
    moved = tmp_path / "cache.usdc"
    moved.write_bytes(cache.read_bytes())
    layer_json = tmp_path / "nowhere"
    assert main(["convert", str(moved), "-o", str(tmp_path / "y.glb"), "--scene", str(layer_json)]) == 2
    err = capsys.readouterr().err
    assert "its scene" in err and "does not exist" in err and err.count("\n") == 1
    assert main(["convert", str(moved), "-o", str(tmp_path / "y.glb"), "--scene", str(WALK)]) == 0


def test_face_varying_uvs_survive_on_the_sample(tmp_path):
    """The sample shirt given face-varying UVs with a seam: the glb keeps them, splitting
    the seam's points, and every split vertex moves with its point."""
    from pxr import Sdf, Usd, UsdGeom, Vt

    from cloth_usd.export.gltf import read_accessor

    scene = tmp_path / "scene.usda"
    scene.write_text(WALK.read_text())
    stage = Usd.Stage.Open(str(scene))
    mesh = UsdGeom.Mesh(stage.GetPrimAtPath("/Character/Tshirt"))
    points = np.asarray(mesh.GetPointsAttr().Get(), dtype=np.float64)
    indices = np.asarray(mesh.GetFaceVertexIndicesAttr().Get())
    counts = np.asarray(mesh.GetFaceVertexCountsAttr().Get())
    face = np.repeat(np.arange(counts.size), counts)
    centroid_z = np.bincount(face, weights=points[indices, 2]) / counts
    st = np.column_stack([points[indices, 0] + 0.5, points[indices, 1] - 0.5])
    st[:, 0] += np.where(centroid_z[face] > np.median(centroid_z), 1.0, 0.0)  # front and back: two islands
    primvar = UsdGeom.PrimvarsAPI(mesh.GetPrim()).CreatePrimvar("st", Sdf.ValueTypeNames.TexCoord2fArray,
                                                                 UsdGeom.Tokens.faceVarying)
    primvar.Set(Vt.Vec2fArray.FromNumpy(st.astype(np.float32)))
    stage.GetRootLayer().Save()
    assert main(["bake", str(scene), "-o", str(tmp_path / "c.usdc"), "--shot", str(tmp_path / "s.usda"),
                 "--frames", "1001:1010", "--no-progress"]) == 0
    assert main(["convert", str(tmp_path / "s.usda"), "-o", str(tmp_path / "s.glb"), "--max-error", "0.1"]) == 0
    anim, _ = read_baked(tmp_path / "s.usda")
    doc, blob = read_glb((tmp_path / "s.glb").read_bytes())
    uv = read_accessor(doc, blob, doc["meshes"][0]["primitives"][0]["attributes"]["TEXCOORD_0"])
    assert anim.vertex_map is not None and points.shape[0] < uv.shape[0] == anim.vertex_map.shape[0]
    assert set(np.unique(np.floor(uv[:, 0]))) == {0.0, 1.0}  # both islands, u as given
    shot = Usd.Stage.Open(str(tmp_path / "s.usda"))
    cache = np.asarray(UsdGeom.Mesh(shot.GetPrimAtPath("/Character/Tshirt")).GetPointsAttr().Get(1005),
                       dtype=np.float64)
    shown = play_gltf(doc, blob, 4)["Tshirt"]
    assert np.linalg.norm(shown - cache[anim.vertex_map], axis=1).max() < 0.1e-3 + 2e-6  # metres, Y-up stage
    (report,) = validate(tmp_path / "s.glb")
    assert report["errors"] == 0 and report["warnings"] == 0, report["messages"]

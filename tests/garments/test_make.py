"""A garment sewn and draped with Newton (slow), written per the scene contract with UVs,
and the command's errors."""

from __future__ import annotations

import json

import numpy as np
import pytest
from pxr import Usd, UsdGeom

from cloth_usd.cli import main
from cloth_usd.core.body import load_body_model, shape_body
from cloth_usd.usd.garment_file import write_garment_file
from cloth_usd.usd.read import open_stage, read_scene


def test_a_garment_file_reads_back_as_a_contract_garment_with_face_varying_uvs(tmp_path):
    body = load_body_model()
    betas = np.zeros(10)
    verts, joints = shape_body(body, betas)
    points = np.array([[0.0, 0.3, 0.2], [0.1, 0.3, 0.2], [0.0, 0.4, 0.2], [0.1, 0.4, 0.2]])
    faces = np.array([[0, 1, 2], [2, 1, 3]])
    st = np.array([[0.0, 0.0], [1.0, 0.0], [0.0, 1.0], [1.0, 1.0], [0.5, 0.5]])
    st_indices = np.array([[0, 1, 2], [2, 4, 3]])  # a seam: vertex 1 has two UVs
    path = write_garment_file(tmp_path / "g.usda", points=points, faces=faces, st=st, st_indices=st_indices,
                              category="dress", betas=betas, joints=joints, custom={"garment": "{}"})
    scene = read_scene(open_stage(path))
    (garment,), (char,) = scene.garments, scene.characters
    assert garment.category.value == "dress" and garment.body_path == char.prim_path
    np.testing.assert_allclose(garment.rest_points, points, atol=1e-6)
    np.testing.assert_allclose(char.rest_joints, joints, atol=1e-5)
    stage = Usd.Stage.Open(str(path))
    mesh = UsdGeom.Mesh(stage.GetPrimAtPath("/Character/Dress"))
    primvar = UsdGeom.PrimvarsAPI(mesh).GetPrimvar("st")
    assert primvar.GetInterpolation() == UsdGeom.Tokens.faceVarying and primvar.IsIndexed()
    np.testing.assert_allclose(np.array(primvar.ComputeFlattened()), st[st_indices.ravel()], atol=1e-6)
    with pytest.raises(Exception, match="--force"):
        write_garment_file(path, points=points, faces=faces, st=st, st_indices=st_indices, category="dress",
                           betas=betas, joints=joints)
    assert not list(tmp_path.glob(".g.*"))  # no temporary file left


def test_command_errors_are_one_line_before_any_work(tmp_path, capsys):
    out = tmp_path / "g.usda"
    assert main(["garment", "make", "tshirt", "-o", str(out), "--param", "sleeves=2"]) == 2
    assert "not a tshirt parameter" in capsys.readouterr().err
    assert main(["garment", "make", "dress", "-o", str(out), "--preset", "ballgown"]) == 2
    assert "a-line" in capsys.readouterr().err
    assert main(["garment", "make", "trousers", "-o", str(out), "--param", "length"]) == 2
    assert "NAME=VALUE" in capsys.readouterr().err
    out.write_text("keep")
    assert main(["garment", "make", "trousers", "-o", str(out)]) == 2
    assert "--force" in capsys.readouterr().err and out.read_text() == "keep"
    assert main(["garment", "presets"]) == 0
    assert "--preset v-neck" in capsys.readouterr().out


@pytest.mark.slow
# p99 at 400 vertices before the relax and settle phases: 1.035, 1.023, 1.052 (largest edge
# 1.10); with them 1.022, 1.007, 1.038 (1.05).
@pytest.mark.parametrize("category, preset", [("tshirt", "classic"), ("dress", "a-line"), ("trousers", "shorts")])
def test_made_garment_is_sewn_closed_and_drapes_to_its_pattern(tmp_path, capsys, category, preset):
    pytest.importorskip("newton")
    out, report = tmp_path / "g.usda", tmp_path / "g.json"
    assert main(["garment", "make", category, "--preset", preset, "-o", str(out), "--vertices", "400",
                 "--betas", "0.5", "-0.3", "--report", str(report)]) == 0
    said = capsys.readouterr().out
    assert "stretch" in said
    figures = json.loads(report.read_text())
    assert figures["stretch_p99"] <= 1.05 and figures["stretch_max"] < 1.08
    # lifted off the skin between its vertices, within 1.05 x the pattern (at 1.5 x the draped lengths the
    # shorts' p99 went to 1.065): 97 -> 8, 133 -> 73, 73 -> 28 body vertices through
    assert figures["skin_through"] < figures["skin_through_before"]
    assert "before the lift)" in said
    scene = read_scene(open_stage(out))
    (garment,) = scene.garments
    assert garment.category.value == category and np.all(np.isfinite(garment.rest_points))
    tri = garment.triangles
    e = np.sort(np.concatenate([tri[:, [0, 1]], tri[:, [1, 2]], tri[:, [2, 0]]]), axis=1)
    _, counts = np.unique(e, axis=0, return_counts=True)
    assert counts.max() == 2  # seams merged into a manifold
    assert main(["inspect", str(out)]) == 0
    assert "warnings    0" in capsys.readouterr().out


@pytest.mark.slow
def test_trousers_hang_from_a_waistband_held_where_it_was_sewn():
    """Unheld, the trousers slid 8-16 cm down the body while draping until the band was
    stretched over the hips (p99 up to 1.11); held, the band stays and the legs hang from it."""
    pytest.importorskip("newton")
    from cloth_usd.core.body import load_body_model
    from cloth_usd.garments.make import make_garment

    made = make_garment("trousers", np.r_[1.0, 0.3, np.zeros(8)], body=load_body_model(), preset="wide",
                        target_vertices=400)
    assert made.pattern.held == ("band_front", "band_back") and made.mesh.held == made.pattern.held
    band = np.isin(np.asarray(made.mesh.panel_names)[made.mesh.panel], made.mesh.held)
    sewn_y = np.median(made.mesh.placed[band, 1])
    draped_y = np.median(made.points[made.sewn.vertex_of[band], 1])
    assert abs(draped_y - sewn_y) < 0.02, (sewn_y, draped_y)
    legs = ~band
    assert np.median(made.points[made.sewn.vertex_of[legs], 1]) < draped_y - 0.2  # the legs hang below it

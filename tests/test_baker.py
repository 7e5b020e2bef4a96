"""The bake on hand-built stages: placement in the world, tiers, garment selection."""

from __future__ import annotations

import numpy as np
import pytest
from pxr import Sdf, Usd, UsdGeom

from cloth_usd.baker import FrameRange, bake, parse_frames
from cloth_usd.core.body import load_body_model, shape_body
from cloth_usd.datagen import TShirtParams, make_tshirt, walk_cycle
from cloth_usd.usd.author import author_garment, author_skeleton, set_stage_metadata


@pytest.fixture(scope="module")
def character():
    body = load_body_model()
    betas = np.array([1.0, -0.5, 0, 0, 0, 0, 0, 0, 0, 0])
    _, joints = shape_body(body, betas)
    verts, faces = make_tshirt(body, betas, TShirtParams(target_vertices=1200))
    poses, root = walk_cycle(10)
    return betas, joints, verts, faces, poses, joints[0] + root


def _stage(path, character, *, turn_deg=0.0, offset=(0.0, 0.0, 0.0), up="Y", mpu=1.0):
    betas, joints, verts, faces, poses, root = character
    stage = Usd.Stage.CreateNew(str(path))
    set_stage_metadata(stage, up_axis=up, meters_per_unit=mpu, fps=24, start=1, end=10)
    skel = author_skeleton(stage, "/Char/Skel", joint_positions=joints, betas=betas, poses=poses,
                           root_positions=root, times=np.arange(1.0, 11.0))
    author_garment(stage, "/Char/Shirt", points=verts, faces=faces, body_path=skel)
    author_garment(stage, "/Char/Spare", points=verts[:, :] + [0, 0, 0.01], faces=faces,
                   body_path=skel, enabled=False)
    xf = UsdGeom.Xformable(stage.GetPrimAtPath("/Char"))
    xf.AddTranslateOp().Set(tuple(offset))
    xf.AddRotateYOp().Set(turn_deg)
    stage.GetRootLayer().Save()
    return path


def _local(cache, prim="/Char/Shirt"):
    layer = Sdf.Layer.FindOrOpen(str(cache))
    attr = f"{prim}.points"
    return np.stack([np.array(layer.QueryTimeSample(attr, t)) for t in layer.ListTimeSamplesForPath(attr)])


def test_a_character_turned_and_moved_in_the_world_bakes_the_same_local_points(tmp_path, character):
    plain = _stage(tmp_path / "plain.usda", character)
    turned = _stage(tmp_path / "turned.usda", character, turn_deg=70.0, offset=(3.0, 0.5, -2.0))
    bake(plain, tmp_path / "a.usdc")
    bake(turned, tmp_path / "b.usdc")
    a, b = _local(tmp_path / "a.usdc"), _local(tmp_path / "b.usdc")
    assert a.shape == (10, character[2].shape[0], 3)
    np.testing.assert_allclose(b, a, atol=2e-5)
    assert np.abs(a[-1] - a[0]).max() > 0.05  # it did move


def test_disabled_garments_are_skipped_unless_named(tmp_path, character):
    scene = _stage(tmp_path / "s.usda", character)
    result = bake(scene, tmp_path / "a.usdc", frames="1:2")
    assert [g.prim_path for g in result.garments] == ["/Char/Shirt"]
    result = bake(scene, tmp_path / "b.usdc", frames="1:2", garments=["/Char/Spare"])
    assert [g.prim_path for g in result.garments] == ["/Char/Spare"]
    assert Sdf.Layer.FindOrOpen(str(tmp_path / "b.usdc")).GetPrimAtPath("/Char/Shirt") is None


def test_garment_tier_override_is_honoured(tmp_path, character):
    scene = _stage(tmp_path / "s.usda", character)
    stage = Usd.Stage.Open(str(scene))
    stage.GetPrimAtPath("/Char/Shirt").CreateAttribute("cloth:tier", Sdf.ValueTypeNames.Token,
                                                       custom=True, variability=Sdf.VariabilityUniform).Set("detail")
    stage.GetRootLayer().Save()
    from cloth_usd.errors import ArgumentError

    (tmp_path / "no_bundles").mkdir()
    with pytest.raises(ArgumentError, match="/Char/Shirt: tier 'detail'"):
        bake(scene, tmp_path / "a.usdc", tier="skinning", models=tmp_path / "no_bundles")
    assert not (tmp_path / "a.usdc").exists()
    pytest.importorskip("onnxruntime")
    result = bake(scene, tmp_path / "a.usdc", tier="skinning", frames="1:2")  # the shipped bundle
    assert result.garments[0].tier.value == "detail" and result.garments[0].bundle is not None


def test_frame_ranges():
    assert parse_frames("1:5:2").times().tolist() == [1.0, 3.0, 5.0]
    assert parse_frames("1001:1001").times().tolist() == [1001.0]
    assert FrameRange(0.0, 1.0, 0.25).times().tolist() == [0.0, 0.25, 0.5, 0.75, 1.0]

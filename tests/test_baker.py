"""The bake on hand-built stages: placement in the world, tiers, garment selection."""

from __future__ import annotations

import numpy as np
import pytest
from pxr import Sdf, Usd, UsdGeom

from cloth_usd.baking import bake
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


def test_shot_and_output_naming_one_file_are_refused_up_front(tmp_path, character):
    import os

    from cloth_usd.errors import ArgumentError

    scene = _stage(tmp_path / "s.usda", character)
    out = tmp_path / "x.usda"
    out.write_bytes(b"keep me")
    os.symlink(out, tmp_path / "link.usda")
    for shot in (out, tmp_path / "." / "x.usda", tmp_path / "link.usda"):
        with pytest.raises(ArgumentError, match=r"--shot .*: is the same file as -o .*x.usda"):
            bake(scene, out, shot=shot, force=True)
    assert out.read_bytes() == b"keep me"


def test_a_cache_too_large_is_refused_before_anything_is_computed(tmp_path, character):
    from cloth_usd.baking import cache_bytes
    from cloth_usd.errors import ArgumentError

    scene = _stage(tmp_path / "s.usda", character)
    n = character[2].shape[0]
    assert cache_bytes(10, [n]) == 10 * (12 * n + 24)
    with pytest.raises(ArgumentError, match=r"--frames 1:10: 10 frames x \d+ garment vertices make a cache of "
                                            r"about .* [GM]iB, more than .*--chunk-frames"):
        bake(scene, tmp_path / "a.usdc", frames="1:10", max_cache_bytes=cache_bytes(10, [n]) - 1)
    assert list(tmp_path.iterdir()) == [tmp_path / "s.usda"]
    bake(scene, tmp_path / "a.usdc", frames="1:10", max_cache_bytes=cache_bytes(10, [n]))
    with pytest.raises(ArgumentError, match=r"1000000000 frames .* more than the 16 GiB a single bake builds"):
        bake(scene, tmp_path / "b.usdc", frames="1:1000000000")  # refused at once, no 8 GB of time codes


def test_bake_removes_the_stale_temporary_files_of_its_targets(tmp_path, character):
    scene = _stage(tmp_path / "s.usda", character)
    stale = [tmp_path / ".a.k3Jd9_x2.tmp.usdc", tmp_path / ".shot.Zz00aa11.tmp.usda"]
    other = tmp_path / ".b.k3Jd9_x2.tmp.usdc"  # another target's: not ours to remove
    for p in (*stale, other):
        p.write_bytes(b"left by a killed bake")
    bake(scene, tmp_path / "a.usdc", shot=tmp_path / "shot.usda", frames="1:2")
    assert not any(p.exists() for p in stale) and other.exists()


def test_betas_beyond_the_body_models_shape_components_are_an_error(tmp_path, character):
    from dataclasses import replace

    from cloth_usd.baking import ModelCache
    from cloth_usd.errors import BodyModelError

    scene = _stage(tmp_path / "s.usda", character)  # betas (1.0, -0.5, 0, ...)
    body = load_body_model()
    one = replace(body, shapedirs=body.shapedirs[:, :, :1])
    cache = ModelCache()
    cache._bodies[("", "neutral")] = one
    with pytest.raises(BodyModelError, match=r"</Char/Skel>: smpl:betas\[1\] is -0.5, but the body model .* "
                                             r"has only 1 shape components \(the stage's betas use 2\)"):
        bake(scene, tmp_path / "a.usdc", frames="1:2", cache=cache)
    cache._bodies[("", "neutral")] = replace(body, shapedirs=body.shapedirs[:, :, :2])
    assert bake(scene, tmp_path / "a.usdc", frames="1:2", cache=cache).garments  # the extras are all zero


@pytest.mark.parametrize("sample, prim, largest", [("walk_dress", "/Character/Dress", 2.5),
                                                    ("walk_trousers", "/Character/Trousers", 2.5)])
def test_the_dress_and_trousers_samples_bake_without_tearing(tmp_path, sample, prim, largest):
    """A real walk (CMU 10_04) in a sewn a-line dress and straight trousers: the lowest 40% of
    the garment (the skirt, the legs) keeps every edge within 2.5x its rest length. Bound to
    each vertex's nearest body point, the skirt tore between the legs (11.8x)."""
    from pathlib import Path

    root = Path(__file__).resolve().parents[1] / "samples" / sample
    out = tmp_path / "cache.usdc"
    bake(root / "scene.usda", out)
    stage = Usd.Stage.Open(str(root / "scene.usda"))
    mesh = UsdGeom.Mesh(stage.GetPrimAtPath(prim))
    rest = np.array(mesh.GetPointsAttr().Get(), float)
    f = np.array(mesh.GetFaceVertexIndicesAttr().Get()).reshape(-1, 3)
    e = np.unique(np.sort(np.concatenate([f[:, [0, 1]], f[:, [1, 2]], f[:, [2, 0]]]), axis=1), axis=0)
    low = rest[:, 1] < np.quantile(rest[:, 1], 0.4)
    e = e[low[e[:, 0]] & low[e[:, 1]]]
    layer = Sdf.Layer.FindOrOpen(str(out))
    times = layer.ListTimeSamplesForPath(f"{prim}.points")
    assert len(times) == 138
    worst = 0.0
    for t in times:
        x = np.array(layer.QueryTimeSample(f"{prim}.points", t), float)
        ratio = np.linalg.norm(x[e[:, 0]] - x[e[:, 1]], axis=1) / np.linalg.norm(rest[e[:, 0]] - rest[e[:, 1]], axis=1)
        worst = max(worst, float(ratio.max()))
    assert worst < largest, worst

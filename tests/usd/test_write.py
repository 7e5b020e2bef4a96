import numpy as np
import pytest
from pxr import Sdf, Usd

from cloth_usd.core.scene import StageInfo
from cloth_usd.errors import ArgumentError, OutputExistsError
from cloth_usd.usd.write import CacheLayerWriter, write_shot_layer


def _info(**kw):
    base = dict(identifier="scene.usda", up_axis="Z", meters_per_unit=0.01, meters_per_unit_authored=True,
                time_codes_per_second=24.0, frames_per_second=24.0, start_time_code=1.0,
                end_time_code=3.0, stage_to_internal=np.eye(4))
    base.update(kw)
    return StageInfo(**base)


def _write(path, force=False, provenance=None):
    times = np.array([1.0, 2.0, 3.0])
    pts = np.random.default_rng(0).normal(size=(3, 5, 3))
    with CacheLayerWriter(path, stage=_info(), start=1, end=3, force=force) as w:
        w.add_points("/Char/Geo/Shirt", times, pts)
        w.commit(provenance or {"cloth_usd": {"tier": "skinning"}})
    return times, pts


def test_cache_layer_holds_only_overs_with_time_samples(tmp_path):
    path = tmp_path / "cache.usdc"
    times, pts = _write(path)
    layer = Sdf.Layer.FindOrOpen(str(path))
    for prim_path in ("/Char", "/Char/Geo", "/Char/Geo/Shirt"):
        spec = layer.GetPrimAtPath(prim_path)
        assert spec.specifier == Sdf.SpecifierOver and spec.typeName == ""
    shirt = layer.GetPrimAtPath("/Char/Geo/Shirt")
    assert set(shirt.attributes.keys()) == {"points", "extent"}
    attr = "/Char/Geo/Shirt.points"
    assert list(layer.ListTimeSamplesForPath(attr)) == list(times)
    np.testing.assert_allclose(np.array(layer.QueryTimeSample(attr, 2.0)), pts[1], rtol=1e-6)
    ext = np.array(layer.QueryTimeSample("/Char/Geo/Shirt.extent", 3.0))
    np.testing.assert_allclose(ext, [pts[2].min(0), pts[2].max(0)], rtol=1e-6)
    assert (layer.startTimeCode, layer.endTimeCode, layer.timeCodesPerSecond) == (1.0, 3.0, 24.0)
    assert layer.pseudoRoot.GetInfo("upAxis") == "Z"
    assert layer.pseudoRoot.GetInfo("metersPerUnit") == 0.01
    assert layer.customLayerData["cloth_usd"]["tier"] == "skinning"
    assert [p.name for p in tmp_path.iterdir()] == ["cache.usdc"]  # no temporary left


def test_refuses_to_overwrite_without_force(tmp_path):
    path = tmp_path / "cache.usdc"
    path.write_bytes(b"precious")
    with pytest.raises(OutputExistsError, match="cache.usdc.*--force"):
        _write(path)
    assert path.read_bytes() == b"precious"
    _write(path, force=True)
    assert Sdf.Layer.FindOrOpen(str(path)) is not None


def test_failure_mid_write_leaves_nothing(tmp_path):
    path = tmp_path / "cache.usdc"
    with pytest.raises(RuntimeError):
        with CacheLayerWriter(path, stage=_info(), start=1, end=3) as w:
            w.add_points("/Shirt", np.array([1.0]), np.zeros((1, 4, 3)))
            raise RuntimeError("killed")
    assert list(tmp_path.iterdir()) == []


def test_non_finite_points_are_refused(tmp_path):
    pts = np.zeros((2, 4, 3))
    pts[1, 2, 0] = np.nan
    with pytest.raises(ArgumentError, match=r"c\.usdc: </Shirt> has non-finite points at time code 2"):
        with CacheLayerWriter(tmp_path / "c.usdc", stage=_info(), start=1, end=2) as w:
            w.add_points("/Shirt", np.array([1.0, 2.0]), pts)
    assert list(tmp_path.iterdir()) == []


def test_bad_paths(tmp_path):
    with pytest.raises(ArgumentError, match=".usdc"):
        _write(tmp_path / "cache.abc")
    with pytest.raises(ArgumentError, match="does not exist"):
        _write(tmp_path / "missing" / "cache.usdc")
    src = tmp_path / "scene.usda"
    src.write_text("#usda 1.0\n")
    with pytest.raises(ArgumentError, match="source"):
        CacheLayerWriter(src, stage=_info(), start=1, end=3, force=True, protected=[str(src)])


def test_shot_layer_puts_the_cache_above_the_scene(tmp_path):
    scene = tmp_path / "scene.usda"
    stage = Usd.Stage.CreateNew(str(scene))
    stage.DefinePrim("/Shirt", "Mesh").GetAttribute("points").Set([(0, 0, 0)] * 5)
    stage.GetRootLayer().Save()
    cache = tmp_path / "cache.usdc"
    _, pts = _write(cache)
    # A cache for /Shirt composed above a scene that holds a default value.
    layer = Sdf.Layer.FindOrOpen(str(cache))
    layer.Clear()
    spec = Sdf.CreatePrimInLayer(layer, "/Shirt")
    attr = Sdf.AttributeSpec(spec, "points", Sdf.ValueTypeNames.Point3fArray)
    layer.SetTimeSample(attr.path, 2.0, [(1, 2, 3)] * 5)
    layer.Save()
    shot = write_shot_layer(tmp_path / "shot.usda", cache=cache, scene=scene, stage=_info(), start=1, end=3)
    assert Sdf.Layer.FindOrOpen(str(shot)).subLayerPaths == ["cache.usdc", "scene.usda"]
    shot_stage = Usd.Stage.Open(str(shot))
    composed = shot_stage.GetPrimAtPath("/Shirt").GetAttribute("points")
    assert tuple(composed.Get(2.0)[0]) == (1, 2, 3)


def test_a_layer_usd_cannot_create_or_save_is_an_output_write_error(tmp_path, monkeypatch):
    from types import SimpleNamespace

    from cloth_usd.errors import OutputWriteError
    from cloth_usd.usd import write

    class Unsaved:
        def Save(self):
            return False

    with pytest.raises(OutputWriteError, match=r"cache\.usdc: USD could not save the layer"):
        write._commit(Unsaved(), tmp_path / ".cache.x.tmp.usdc", tmp_path / "cache.usdc", False)
    monkeypatch.setattr(write, "Sdf", SimpleNamespace(Layer=SimpleNamespace(CreateNew=lambda path: None)))
    with pytest.raises(OutputWriteError, match=r"cache\.usdc: USD could not create a layer"):
        CacheLayerWriter(tmp_path / "cache.usdc", stage=_info(), start=1, end=2)
    assert list(tmp_path.iterdir()) == []

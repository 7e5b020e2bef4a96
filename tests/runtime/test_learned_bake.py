"""End to end: the coarse and detail tiers bake the sample with a tiny random bundle."""

from __future__ import annotations

import time
from pathlib import Path

import numpy as np
import pytest
from pxr import Sdf, Usd, UsdGeom

from cloth_usd.cli import main

from bundle_helpers import write_tiny_bundle

WALK = Path(__file__).resolve().parents[2] / "samples" / "walk_tshirt" / "scene.usda"
PRIM = "/Character/Tshirt"
FRAMES = "1001:1004"


def _points(cache: Path) -> np.ndarray:
    stage = Usd.Stage.Open(str(cache))
    attr = UsdGeom.Mesh(stage.GetPrimAtPath(PRIM)).GetPointsAttr()
    return np.stack([np.array(attr.Get(1001.0 + i)) for i in range(4)])


@pytest.fixture(scope="module")
def skinned(tmp_path_factory) -> np.ndarray:
    cache = tmp_path_factory.mktemp("skin") / "cache.usdc"
    assert main(["bake", str(WALK), "-o", str(cache), "--frames", FRAMES, "--no-progress"]) == 0
    return _points(cache)


@pytest.mark.parametrize("tier", ["coarse", "detail"])
def test_learned_tier_bakes_the_sample(tier, tiny_bundle, skinned, tmp_path, capsys):
    cache = tmp_path / "cache.usdc"
    began = time.perf_counter()
    assert main(["bake", str(WALK), "-o", str(cache), "--frames", FRAMES, "--tier", tier,
                 "--models", str(tiny_bundle.parent), "--no-progress"]) == 0
    seconds = time.perf_counter() - began
    out = capsys.readouterr().out
    assert f"tier {tier}" in out and "post-process moved" in out and "bundle tiny-tshirt" in out
    pts = _points(cache)
    assert pts.shape == skinned.shape and np.isfinite(pts).all()
    # The stage is in metres; random tiny weights put the garment on the body (+ a few mm)
    # where skinning keeps its rest offset: a few cm apart at most (the detail tier's strain limit
    # then shortens the random garment's stretched edges, which moves it a little further).
    gap = np.linalg.norm(pts - skinned, axis=-1)
    assert gap.mean() < (0.03 if tier == "coarse" else 0.04) and gap.max() < 0.12, (gap.mean(), gap.max())
    prov = Sdf.Layer.FindOrOpen(str(cache)).customLayerData["cloth_usd"]
    manifest_sha = __import__("hashlib").sha256((tiny_bundle / "manifest.json").read_bytes()).hexdigest()
    assert prov["model_bundle"] == {"name": "tiny-tshirt", "sha256": manifest_sha}
    g = prov["garments"][PRIM]
    assert g["tier"] == tier and g["model_bundle"] == "tiny-tshirt"
    assert len([float(a) for a in g["fit"].split()]) == 3
    assert g["postprocess_moved"] > 0  # the garment sits on the body: the post-process lifts it
    print(f"{tier}: {seconds / 4 * 1000:.0f} ms/frame end to end (4 frames, tiny width)")


def test_tampered_bundle_is_refused_before_anything_is_written(exported_models, tmp_path, capsys):
    folder = write_tiny_bundle(tmp_path / "models" / "bad", exported_models)
    data = bytearray((folder / "coarse.onnx").read_bytes())
    data[len(data) // 2] ^= 0xFF
    (folder / "coarse.onnx").write_bytes(bytes(data))
    cache = tmp_path / "out" / "cache.usdc"
    cache.parent.mkdir()
    assert main(["bake", str(WALK), "-o", str(cache), "--frames", FRAMES, "--tier", "coarse",
                 "--models", str(folder.parent), "--shot", str(tmp_path / "out" / "shot.usda")]) == 2
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1 and "coarse.onnx" in err and str(folder) in err
    assert list(cache.parent.iterdir()) == []


def test_no_bundle_for_the_category(tmp_path, capsys):
    (tmp_path / "empty").mkdir()
    assert main(["bake", str(WALK), "-o", str(tmp_path / "c.usdc"), "--tier", "detail",
                 "--models", str(tmp_path / "empty")]) == 2
    err = capsys.readouterr().err
    assert "needs a trained model bundle for category 'tshirt', none found in" in err
    assert "empty (available: skinning)" in err

"""Model bundles: write + load round trip, and every way a bundle can be broken."""

from __future__ import annotations

import json
import shutil
from pathlib import Path

import numpy as np
import pytest

from cloth_usd.core.heading import Heading
from cloth_usd.core.pipeline import CoarseBase, CoarseFeatures, CoarseForm
from cloth_usd.core.scene import Category, Tier
from cloth_usd.errors import ArgumentError, BundleError, ClothUsdError
from cloth_usd.runtime import find_bundle, load_bundle

from bundle_helpers import load_make_bundle, write_tiny_bundle


@pytest.fixture
def fake_exported(tmp_path):
    """Stand-in files: load_bundle only hashes them (no session is made in these tests)."""
    from cloth_usd.core.fit import FitModel

    (tmp_path / "c.onnx").write_bytes(b"coarse model bytes")
    (tmp_path / "d.onnx").write_bytes(b"detail model bytes")
    FitModel(anchors=np.arange(4), mean=np.zeros(4), loadings=np.ones((4, 3)),
             noise_variance=np.ones(4)).save(tmp_path / "fit.npz")
    return tmp_path / "c.onnx", tmp_path / "d.onnx", tmp_path / "fit.npz", {"coarse": {"width": 0.125}}


def test_round_trip(tmp_path, fake_exported):
    folder = write_tiny_bundle(tmp_path / "b", fake_exported)
    b = load_bundle(folder)
    assert (b.name, b.category, b.tiers) == ("tiny-tshirt", Category.TSHIRT, (Tier.COARSE, Tier.DETAIL))
    assert len(b.sha256) == 64 and b.fit.anchors.tolist() == [0, 1, 2, 3]
    m = json.loads((folder / "manifest.json").read_text())
    assert m["format_version"] == 1 and m["opset"] == 18
    assert sorted(m["files"]) == ["coarse.onnx", "detail.onnx", "fit.npz"]
    assert m["models"]["coarse"]["inputs"] == ["features", "nbr", "nbr_mask"]
    assert m["models"]["coarse"]["config"] == {"width": 0.125}
    assert m["training_data"]["description"] and m["metrics"] == {"note": "untrained"}
    assert m["models"]["coarse"]["base"] == "body" and b.form.base is CoarseBase.BODY
    del m["models"]["coarse"]["base"]  # a bundle from before the field: METHOD.md's base
    (folder / "manifest.json").write_text(json.dumps(m))
    assert load_bundle(folder).form.base is CoarseBase.BODY
    assert m["models"]["coarse"]["features"] == "body"
    del m["models"]["coarse"]["features"]  # a bundle from before the field (tshirt-v1..v5): docs/method.md's features
    (folder / "manifest.json").write_text(json.dumps(m))
    assert load_bundle(folder).form.features is CoarseFeatures.BODY
    coarse_only = load_bundle(write_tiny_bundle(tmp_path / "c", fake_exported, detail=False))
    assert coarse_only.tiers == (Tier.COARSE,)
    with pytest.raises(BundleError, match="no 'detail' model"):
        coarse_only.session("detail")


def test_skinned_coarse_base_is_recorded(tmp_path, fake_exported):
    from cloth_usd.runtime.bundle import write_bundle

    coarse, det, fit, configs = fake_exported
    folder = write_bundle(tmp_path / "s", name="s", category="tshirt", coarse_onnx=coarse, detail_onnx=det,
                          fit_npz=fit, configs=configs, training_data={}, metrics={}, opset=18,
                          form=CoarseForm("skinned", features="contact"))
    assert load_bundle(folder).form == CoarseForm(CoarseBase.SKINNED, Heading.WORLD, CoarseFeatures.CONTACT)
    assert {"base", "features"}.isdisjoint(json.loads((folder / "manifest.json").read_text())["models"]["detail"])


def test_find_bundle_by_category(tmp_path, fake_exported):
    write_tiny_bundle(tmp_path / "models" / "b", fake_exported)
    assert find_bundle("tshirt", [tmp_path / "models"]).name == "tiny-tshirt"
    assert find_bundle("tshirt", [tmp_path / "models" / "b"]).name == "tiny-tshirt"  # a bundle itself
    assert find_bundle("dress", [tmp_path / "models"]) is None
    with pytest.raises(ArgumentError, match="--models .*nope: no such folder"):
        find_bundle("tshirt", [tmp_path / "nope"])


def test_a_folders_defaults_file_picks_the_bundle_tried_first(tmp_path, fake_exported):
    models = tmp_path / "models"
    write_tiny_bundle(models / "a-old", fake_exported, name="old")
    write_tiny_bundle(models / "b-new", fake_exported, name="new")
    assert find_bundle("tshirt", [models]).name == "old"  # name order without a defaults file
    (models / "defaults.json").write_text('{"tshirt": "b-new"}')
    assert find_bundle("tshirt", [models]).name == "new"
    (models / "defaults.json").write_text('{"tshirt": "gone"}')
    with pytest.raises(BundleError, match=r"defaults.json: the default tshirt bundle 'gone' is not a bundle folder"):
        find_bundle("tshirt", [models])
    (models / "defaults.json").write_text('{"tshirt": ')
    with pytest.raises(BundleError, match=r"defaults.json: unreadable"):
        find_bundle("tshirt", [models])


def test_a_garments_own_bundle_comes_first_for_its_garment_alone(tmp_path, fake_exported):
    """In a folder of bundles, the bundle trained for this garment (train-garment) wins over the
    category's default; another garment passes it by; a folder that is the bundle is the bundle."""
    from cloth_usd.core.garment_inputs import faces_sha256
    from cloth_usd.runtime.bundle import GarmentIdentity, write_bundle

    coarse, det, fit, configs = fake_exported
    faces = np.array([[0, 1, 2], [0, 2, 3]])
    models = tmp_path / "models"
    write_tiny_bundle(models / "tshirt-v9", fake_exported, name="category")
    (models / "defaults.json").write_text('{"tshirt": "tshirt-v9"}')
    own = write_bundle(models / "a-own", name="own", category="tshirt", coarse_onnx=coarse, detail_onnx=det,
                       fit_npz=fit, configs=configs, training_data={}, metrics={}, opset=18,
                       garment=GarmentIdentity(4, faces_sha256(faces)), detail_adds_coarse=True)
    assert load_bundle(own).detail_adds_coarse
    assert find_bundle("tshirt", [models], worn=(4, faces)).name == "own"
    assert find_bundle("tshirt", [models], worn=(4, faces[::-1])).name == "category"  # other triangles
    assert find_bundle("tshirt", [models]).name == "category"
    assert find_bundle("dress", [models], worn=(4, faces)) is None  # its category only
    (models / "defaults.json").unlink()  # name order: the own bundle ("a-own") is passed by all the same
    assert find_bundle("tshirt", [models], worn=(5, faces)).name == "category"
    assert find_bundle("tshirt", [own], worn=(5, faces)).name == "own"  # named: the bake refuses it, in one line
    with pytest.raises(ArgumentError, match="only a garment's own bundle"):
        write_bundle(tmp_path / "x", name="x", category="tshirt", coarse_onnx=coarse, detail_onnx=det, fit_npz=fit,
                     configs={}, training_data={}, metrics={}, opset=18, detail_adds_coarse=True)
    m = json.loads((own / "manifest.json").read_text())
    m["models"]["detail"]["adds"] = "skinning"
    (own / "manifest.json").write_text(json.dumps(m))
    with pytest.raises(BundleError, match="models.detail.adds 'skinning'"):
        load_bundle(own)
    # the rest garment it was trained on travels with it, checked
    rest = np.arange(12.0).reshape(4, 3)
    kept = write_bundle(models / "b-own", name="kept", category="tshirt", coarse_onnx=coarse, detail_onnx=det,
                        fit_npz=fit, configs=configs, training_data={}, metrics={}, opset=18,
                        garment=GarmentIdentity(4, faces_sha256(faces)), garment_rest=(rest, np.ones(10)))
    got = load_bundle(kept).garment_rest
    np.testing.assert_array_equal(got[0], rest)
    np.testing.assert_array_equal(got[1], np.ones(10))
    kept_bundle = load_bundle(kept)  # the rest it was trained on, on that body alone (missing betas are zeros)
    assert kept_bundle.trained_rest(np.r_[np.ones(10), 0.0, 0.0]) is kept_bundle.garment_rest[0]
    assert kept_bundle.trained_rest(np.zeros(10)) is None
    assert load_bundle(models / "tshirt-v9").trained_rest(np.ones(10)) is None  # a category's bundle records none
    np.savez(kept / "rest.npz", vertices=rest[:3], betas=np.ones(10))
    _replace_file(kept, "rest.npz", (kept / "rest.npz").read_bytes())
    with pytest.raises(BundleError, match="rest.npz holds"):
        load_bundle(kept)
    with pytest.raises(ArgumentError, match="garment_rest"):
        write_bundle(tmp_path / "y", name="y", category="tshirt", coarse_onnx=coarse, detail_onnx=det, fit_npz=fit,
                     configs={}, training_data={}, metrics={}, opset=18, garment_rest=(rest, np.ones(10)))


def test_tampered_file_names_the_file(tmp_path, fake_exported):
    folder = write_tiny_bundle(tmp_path / "b", fake_exported)
    data = bytearray((folder / "coarse.onnx").read_bytes())
    data[3] ^= 0x01
    (folder / "coarse.onnx").write_bytes(bytes(data))
    with pytest.raises(BundleError, match=r"b: bundle file coarse.onnx fails its sha256 check") as info:
        load_bundle(folder)
    assert isinstance(info.value, ClothUsdError) and str(folder) in str(info.value)


def test_missing_file(tmp_path, fake_exported):
    folder = write_tiny_bundle(tmp_path / "b", fake_exported)
    (folder / "fit.npz").unlink()
    with pytest.raises(BundleError, match="bundle file fit.npz is missing"):
        load_bundle(folder)
    shutil.rmtree(folder)
    with pytest.raises(BundleError, match="not a model bundle"):
        load_bundle(folder)


@pytest.mark.parametrize("edit, expect", [
    (lambda m: m.update(format_version=2), "format_version 2 is not supported"),
    (lambda m: m.update(category="hat"), "unknown category 'hat'"),
    (lambda m: m.update(tiers=["detail", "ultra"]), "unknown tier"),
    (lambda m: m["models"]["coarse"].update(inputs=["x"]), "do not match this runtime"),
    (lambda m: m["files"].update({"../evil": "0"}), "plain relative name"),
    (lambda m: m["models"]["coarse"].update(base="hips"), "models.coarse.base 'hips' is not one of body, skinned"),
    (lambda m: m["models"]["coarse"].update(features="cloth"),
     "models.coarse.features 'cloth' is not one of body, contact"),
    (lambda m: m["training_data"].update(poses={"frames": 3, "euler_deg": {"pelvis": [[0, 1]] * 3}}),
     "training_data.poses: euler_deg lacks the joints left_hip"),
    (lambda m: m["training_data"].update(bodies={"count": 1, "betas": [[1.0, -1.0]]}),
     r"training_data.bodies: expected .*low <= high"),
])
def test_bad_manifest(tmp_path, fake_exported, edit, expect):
    folder = write_tiny_bundle(tmp_path / "b", fake_exported)
    m = json.loads((folder / "manifest.json").read_text())
    edit(m)
    (folder / "manifest.json").write_text(json.dumps(m))
    with pytest.raises(BundleError, match=expect):
        load_bundle(folder)


def test_the_training_poses_a_bundle_records_are_its_pose_limits(tmp_path, fake_exported):
    """(And the shipped T-shirt bundle records its training bodies: betas within +-2.)"""
    from cloth_usd.core.limits import pose_range, pose_range_record
    from cloth_usd.datagen import walk_cycle
    from cloth_usd.runtime.bundle import write_bundle

    coarse, det, fit, configs = fake_exported
    poses = walk_cycle(48)[0]
    folder = write_bundle(tmp_path / "p", name="p", category="tshirt", coarse_onnx=coarse, detail_onnx=det,
                          fit_npz=fit, configs=configs, training_data={"poses": pose_range_record(poses)},
                          metrics={}, opset=18)
    np.testing.assert_allclose(load_bundle(folder).pose_limits, pose_range(poses), atol=np.deg2rad(0.006))
    assert load_bundle(folder).betas_limits is None  # no bodies recorded
    assert load_bundle(write_tiny_bundle(tmp_path / "b", fake_exported)).pose_limits is None  # none recorded
    bad = pose_range_record(poses)
    bad["euler_deg"]["left_elbow"][1] = [10.0, -10.0]  # low above high
    with pytest.raises(ArgumentError, match="training_data.poses: euler_deg must give each joint three finite"):
        write_bundle(tmp_path / "q", name="q", category="tshirt", coarse_onnx=coarse, detail_onnx=det,
                     fit_npz=fit, configs=configs, training_data={"poses": bad}, metrics={}, opset=18)
    assert not (tmp_path / "q").exists()
    shipped = find_bundle("tshirt")
    np.testing.assert_array_equal(shipped.betas_limits[:3], [[-2.0, 2.0], [-2.0, 2.0], [0.0, 0.0]])


def test_make_bundle_script(tmp_path, fake_exported, capsys):
    coarse, _, fit, _ = fake_exported
    (tmp_path / "metrics.json").write_text('{"coarse_mm": 3.0}')
    script = load_make_bundle()
    argv = [str(tmp_path / "out"), "--name", "x", "--category", "tshirt", "--coarse", str(coarse),
            "--fit", str(fit), "--metrics", str(tmp_path / "metrics.json"),
            "--training-manifest", str(tmp_path / "metrics.json")]
    assert script.main(argv) == 0
    assert load_bundle(tmp_path / "out").manifest["metrics"] == {"coarse_mm": 3.0}
    assert script.main(argv) == 2  # the folder is not empty now
    assert "not empty" in capsys.readouterr().err


def _assert_shipped_evaluation(bundle) -> None:
    """A shipped bundle's manifest records its evaluation, measured on its very ONNX files: against
    Newton both learned tiers below skinning on every row, and on five or more held-out real clips
    no frame of either tier replaced by the guard."""
    evaluation = json.loads((bundle.path / "manifest.json").read_text())["metrics"]["evaluation"]
    assert evaluation["same_models"] is True and evaluation["rows"]  # measured on these very ONNX files
    for row in evaluation["rows"]:  # against Newton on real motion: both learned tiers below skinning
        mean = row["mean_mm"]
        assert max(mean["coarse"], mean["detail"]) < mean["skinning"], row["title"]
    clips = [r for r in evaluation["held_out_clips"] if r["bundle"] == bundle.name]
    assert len({r["clip"] for r in clips}) >= 5 and {r["tier"] for r in clips} == {"coarse", "detail"}
    for row in clips:
        assert row["fallback_coarse"] == row["fallback_skinning"] == 0, (row["clip"], row["tier"])


def test_the_shipped_tshirt_bundle_verifies_and_records_its_evaluation():
    """The default T-shirt bundle (models/bundles/defaults.json) travels with the evaluation the
    README and docs/models.md quote, measured on its own ONNX files, and lost no frame to the guard on the
    held-out real clips it records (issue #12)."""
    from cloth_usd.runtime.bundle import default_bundle_dir, find_bundle

    bundle = find_bundle("tshirt")
    assert bundle is not None and bundle.path.parent == default_bundle_dir() and bundle.name == "tshirt-v6"
    assert bundle.form.heading.value == "canonical"
    _assert_shipped_evaluation(bundle)


def test_the_sample_shirt_bakes_with_its_own_shipped_bundle():
    """The sample's T-shirt has a bundle of its own (train-garment's garment form) that comes before
    the category's default; the Z-up sample's other shirt gets the default. The bundle records the
    rest garment it was trained on (the sample's, as authored) and travels with its evaluation
    against Newton and on the held-out real clips, measured on its own files."""
    from cloth_usd.core.body import load_body_model, shape_body
    from cloth_usd.core.frames import worn_rest_points
    from cloth_usd.usd.read import open_stage, read_scene

    root = Path(__file__).resolve().parents[2] / "samples"
    scene = read_scene(open_stage(root / "walk_tshirt" / "scene.usda"))
    shirt, char = scene.garments[0], scene.characters[0]
    bundle = find_bundle("tshirt", worn=(len(shirt.rest_points), shirt.triangles))
    assert bundle.name == "sample-tshirt-own" and bundle.garment.serves(len(shirt.rest_points), shirt.triangles)
    assert bundle.detail_adds_coarse and bundle.tiers == (Tier.COARSE, Tier.DETAIL)
    rest = worn_rest_points(char, shirt.rest_points, shape_body(load_body_model(), char.betas)[1])
    np.testing.assert_allclose(bundle.garment_rest[0], rest, atol=1e-6)
    other = read_scene(open_stage(root / "walk_tshirt_zup_cm" / "scene.usda")).garments[0]
    assert find_bundle("tshirt", worn=(len(other.rest_points), other.triangles)).name == "tshirt-v6"
    _assert_shipped_evaluation(bundle)
    assert bundle.manifest["metrics"]["evaluation"]["bundle"]["reads"] == "authored"


def test_the_sample_dress_bakes_with_its_own_shipped_bundle():
    """Like the sample shirt, the sample dress has a bundle of its own (train-garment's garment form,
    the hybrid objective) that comes before dress-v1, and it travels with its evaluation against
    Newton and on the held-out real clips (no frame replaced by the guard), measured on its own files."""
    from cloth_usd.core.body import load_body_model, shape_body
    from cloth_usd.core.frames import worn_rest_points
    from cloth_usd.usd.read import open_stage, read_scene

    root = Path(__file__).resolve().parents[2] / "samples"
    scene = read_scene(open_stage(root / "walk_dress" / "scene.usda"))
    dress, char = scene.garments[0], scene.characters[0]
    bundle = find_bundle("dress", worn=(len(dress.rest_points), dress.triangles))
    assert bundle.name == "sample-dress-own" and bundle.category.value == "dress"
    assert bundle.detail_adds_coarse and bundle.tiers == (Tier.COARSE, Tier.DETAIL)
    rest = worn_rest_points(char, dress.rest_points, shape_body(load_body_model(), char.betas)[1])
    np.testing.assert_allclose(bundle.garment_rest[0], rest, atol=1e-6)
    assert find_bundle("dress").name == "dress-v1"  # any other dress
    _assert_shipped_evaluation(bundle)
    assert bundle.manifest["metrics"]["evaluation"]["bundle"]["reads"] == "authored"
    assert "Newton's frames of 10" in bundle.manifest["training_data"]["description"]


def test_the_sample_trousers_bake_with_their_own_shipped_bundle():
    """The sample trousers have a bundle of their own too, made as the dress's (three of the ten
    simulated sequences went unstable and were left out), that comes before trousers-v2; on the
    held-out clips, martial arts 04's kicks included, the guard replaced none of its frames."""
    from cloth_usd.usd.read import open_stage, read_scene

    root = Path(__file__).resolve().parents[2] / "samples"
    trousers = read_scene(open_stage(root / "walk_trousers" / "scene.usda")).garments[0]
    bundle = find_bundle("trousers", worn=(len(trousers.rest_points), trousers.triangles))
    assert bundle.name == "sample-trousers-own" and bundle.category.value == "trousers"
    assert bundle.detail_adds_coarse and bundle.tiers == (Tier.COARSE, Tier.DETAIL)
    assert find_bundle("trousers").name == "trousers-v2"  # any other trousers
    _assert_shipped_evaluation(bundle)
    evaluation = bundle.manifest["metrics"]["evaluation"]
    assert {r["clip"] for r in evaluation["held_out_clips"]} >= {"04", "10", "25"}
    assert "Newton's frames of 7" in bundle.manifest["training_data"]["description"]


def test_tshirt_v3_keeps_its_ordered_evaluation():
    """The supervised bundle before it: detail < coarse < skinning on every row of its own test
    sets (issue #4), measured on its own ONNX files."""
    bundle = load_bundle(Path(__file__).resolve().parents[2] / "models" / "bundles" / "tshirt-v3")
    evaluation = json.loads((bundle.path / "manifest.json").read_text())["metrics"]["evaluation"]
    assert evaluation["same_models"] is True
    for row in evaluation["rows"]:
        mean = row["mean_mm"]
        assert mean["detail"] < mean["coarse"] < mean["skinning"], row["title"]


def _replace_file(folder, rel: str, data: bytes) -> None:
    """Swap a bundle file and re-pin its sha256: content that is wrong but passes the hash check."""
    import hashlib

    (folder / rel).write_bytes(data)
    m = json.loads((folder / "manifest.json").read_text())
    m["files"][rel] = hashlib.sha256(data).hexdigest()
    (folder / "manifest.json").write_text(json.dumps(m))


@pytest.mark.parametrize("data", [bytes(range(256)) * 8, b"", b"\x08\x07\x12"])
def test_an_onnx_file_that_is_not_a_model_is_a_bundle_error(tmp_path, fake_exported, data):
    pytest.importorskip("onnxruntime", reason="sessions need onnxruntime")
    folder = write_tiny_bundle(tmp_path / "b", fake_exported)
    _replace_file(folder, "coarse.onnx", data)
    bundle = load_bundle(folder)
    with pytest.raises(BundleError, match=r"b: bundle file coarse.onnx is not a loadable ONNX model"):
        bundle.session("coarse", prefer_gpu=False)


def _fit_bytes(tmp_path, **arrays) -> bytes:
    base = dict(anchors=np.arange(4), mean=np.zeros(4), loadings=np.ones((4, 3)), noise_variance=np.ones(4))
    base.update(arrays)
    np.savez(tmp_path / "x.npz", **{k: v for k, v in base.items() if v is not None})
    return (tmp_path / "x.npz").read_bytes()


@pytest.mark.parametrize("make, expect", [
    (lambda p: _fit_bytes(p, loadings=np.ones((5, 3))), r"'loadings' has shape \(5, 3\), expected \(4, F\)"),
    (lambda p: _fit_bytes(p, loadings=np.ones((4, 3, 1))), r"'loadings' has shape"),
    (lambda p: _fit_bytes(p, mean=np.zeros(3)), r"'mean' has shape \(3,\), expected \(4,\)"),
    (lambda p: _fit_bytes(p, anchors=np.zeros(4)), r"'anchors' must be a non-empty \(G,\) integer array"),
    (lambda p: _fit_bytes(p, noise_variance=np.zeros(4)), r"'noise_variance' must be positive"),
    (lambda p: _fit_bytes(p, mean=np.full(4, np.nan)), r"'mean' holds NaN"),
    (lambda p: _fit_bytes(p, loadings=None), r"missing key 'loadings'"),
    (lambda p: bytes(range(256)) * 4, r"not a fit model"),
    (lambda p: _fit_bytes(p)[:200], r"not a fit model"),
])
def test_a_fit_file_of_the_wrong_content_is_a_bundle_error(tmp_path, fake_exported, make, expect):
    folder = write_tiny_bundle(tmp_path / "b", fake_exported)
    _replace_file(folder, "fit.npz", make(tmp_path))
    with pytest.raises(BundleError, match=r"b: bundle file fit.npz is not a fit model") as info:
        load_bundle(folder)
    assert info.match(expect)


def test_find_bundle_names_an_unreadable_manifest(tmp_path, fake_exported):
    folder = write_tiny_bundle(tmp_path / "models" / "b", fake_exported)
    text = (folder / "manifest.json").read_text()
    (folder / "manifest.json").write_text(text[: len(text) // 2])
    with pytest.raises(BundleError, match=r"no readable model bundle for category 'tshirt': .*manifest.json: "
                                          r"unreadable manifest"):
        find_bundle("tshirt", [tmp_path / "models"])
    write_tiny_bundle(tmp_path / "models" / "c", fake_exported)  # a sound one beside it is found
    assert find_bundle("tshirt", [tmp_path / "models"]).path.name == "c"

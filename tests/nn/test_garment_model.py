"""A garment's own model (nn.garment_model): pose and shape to a displacement of its unposed
vertices, trained on its physics, exported as a bundle bound to its triangles."""

from __future__ import annotations

import json

import numpy as np
import pytest

from cloth_usd.core.body import load_body_model
from cloth_usd.core.garment_inputs import faces_sha256, skin_displaced, skin_parts
from cloth_usd.core.features import vertex_normals
from cloth_usd.core.pipeline import OWN_SMOOTHING, smooth_along_normals
from cloth_usd.core.skinning import bind_garment, skin_garment
from cloth_usd.datagen import TShirtParams, make_tshirt
from cloth_usd.datagen.factory import OWN_BODY, save_own_garment
from cloth_usd.errors import ArgumentError, BundleError

torch = pytest.importorskip("torch", reason="training needs torch (pip install 'cloth-usd[train]')")

from train_data import tiny_dataset  # noqa: E402 (the session's tiny data set, built on first use)


@pytest.fixture(scope="module")
def own(tmp_path_factory):
    """A small shirt of a broad body, its config, and coarse and detail runs of a few steps."""
    from cloth_usd.nn.garment_model import GarmentModelConfig, train_garment_model
    from cloth_usd.nn.physics_train import physics_set

    body = load_body_model()
    betas = np.r_[1.0, 1.0, np.zeros(8)]
    verts, faces = make_tshirt(body, betas, TShirtParams(target_vertices=300))
    root = tmp_path_factory.mktemp("garment_model")
    save_own_garment(root / "g.npz", verts, faces, betas)
    (root / "data.json").write_text(json.dumps({
        "garment": "g.npz", "bodies": [OWN_BODY, "slim", "short_fat", "tall_thin", "medium_thin"],
        "test_bodies": ["medium_thin"], "max_frames": 12,
        "train_motions": [{"kind": "arm_raise", "seconds": 1.0, "seed": 0}],
        "test_motions": [{"kind": "arm_raise", "seconds": 1.0, "seed": 5}]}))
    data = physics_set(root / "data.json", body)
    rows = {"coarse": [], "detail": []}
    infos = {}
    for tier in ("coarse", "detail"):
        cfg = GarmentModelConfig(steps=40 if tier == "coarse" else 20, val_every=10, hidden=32, layers=2,
                                 bending_scale=10.0 if tier == "coarse" else 1.0)
        infos[tier] = train_garment_model(root / "data.json", root / tier, cfg, tier=tier, body=body, physics=data,
                                          coarse_run=root / "coarse" if tier == "detail" else None,
                                          progress=rows[tier].append)
    return root, body, data, verts, faces, betas, rows, infos


def test_skinning_a_displacement_is_skinning_the_displaced_rest_garment():
    body = load_body_model()
    betas = np.r_[0.5, -1.0, np.zeros(8)]
    verts, faces = make_tshirt(body, betas, TShirtParams(target_vertices=300))
    binding = bind_garment(body, betas, verts)
    rng = np.random.default_rng(0)
    poses, transl = rng.normal(0.0, 0.3, (3, 72)), rng.normal(0.0, 0.5, (3, 3))
    zero = np.zeros((3, len(verts), 3))
    np.testing.assert_allclose(skin_displaced(binding, poses, transl, body.parents, zero),
                               skin_garment(binding, poses, transl, body.parents), atol=1e-12)
    d = rng.normal(0.0, 0.01, zero.shape)
    parts = skin_parts(binding, poses, transl, body.parents)
    moved = skin_displaced(binding, poses, transl, body.parents, d)
    np.testing.assert_allclose(parts.base + np.einsum("tnab,tnb->tna", parts.linear, d), moved, atol=1e-12)
    # a rigid displacement of every vertex is turned with the bones, not added in the world
    assert np.abs(moved - parts.base - d).max() > 1e-4


def test_an_untrained_model_is_the_skinned_garment_and_training_lowers_its_energy(own):
    root, *_, rows, infos = own
    coarse = rows["coarse"]
    assert coarse[0]["step"] == 0 and coarse[0]["val_mm"] == 0.0
    assert coarse[0]["val_energy"] == pytest.approx(coarse[0]["val_start_energy"])
    assert infos["coarse"]["best_val_energy"] < 0.8 * infos["coarse"]["val_start_energy"]
    assert infos["coarse"]["best_val_mm"] > 0.1  # it moved the garment
    # the detail model starts from the coarse garment, under the material's own bending
    detail = rows["detail"]
    assert detail[0]["val_mm"] == 0.0 and infos["detail"]["best_val_energy"] <= detail[0]["val_start_energy"]
    run = json.loads((root / "coarse" / "run.json").read_text())
    assert run["kind"] == "garment-model" and run["tier"] == "coarse" and run["faces_sha256"] == faces_sha256(own[4])
    assert run["dtype"] == "float32"  # trained in float32, loaded in float64 for the export's checks


def test_training_in_float32_measures_the_energy_of_float64(own):
    """The models train in float32 (TRAIN_DTYPE): each energy term of a trained model's garment is
    the float64 one to within 1e-4 of it, the garment to a micrometre."""
    from cloth_usd.nn.garment_model import TRAIN_DTYPE, _energy, _garment, _prepared, load_garment_run

    root, body, data, *_ = own
    clip = _prepared(data.split("val"))[0]
    frames = np.arange(clip.source.num_frames)
    net = load_garment_run(root / "coarse")[0]
    with torch.no_grad():
        x64 = _garment(net, clip, frames, body)
        x32 = _garment(net.to(TRAIN_DTYPE), clip, frames, body)
        e64 = _energy(clip.source, x64, frames, body, data.material)
        e32 = _energy(clip.source, x32, frames, body, data.material)
    assert x64.dtype == torch.float64 and x32.dtype == TRAIN_DTYPE == torch.float32
    assert float((x32.double() - x64).abs().max()) < 1e-6
    for term in ("membrane", "bending", "gravity", "contact", "total"):  # on the sample shirt 2e-7 to 6e-6
        np.testing.assert_allclose(e32[term].double().numpy(), e64[term].numpy(), rtol=1e-4, atol=1e-9,
                                   err_msg=term)


def test_newton_frames_of_a_training_sequence_pull_the_model_toward_them(own, tmp_path):
    """The hybrid objective: batches of a sequence with simulated frames add the spring toward
    them. A stand-in simulation 2 cm below the skinned garment: a few steps bring the model
    most of the way there, the run keeps its last weights and records the hybrid term."""
    import dataclasses

    from cloth_usd.nn.garment_model import GarmentModelConfig, _garment, _prepared, train_garment_model

    root, body, data, *_ = own
    first = data.split("train")[0]
    frames = np.arange(first.num_frames)
    skinned = _garment(None, _prepared([first])[0], frames, body).numpy()
    target = (skinned - [0.0, 0.02, 0.0]).astype(np.float32)  # below it: away from the shoulders
    clips = tuple(dataclasses.replace(c, target=target) if c is first else c for c in data.clips)
    hybrid = dataclasses.replace(data, clips=clips)
    cfg = GarmentModelConfig(steps=40, val_every=20, hidden=32, layers=2, bending_scale=10.0, lr=2e-2,
                             supervised_share=1.0, supervised_weight=1e8)  # well above the skinned membrane's pull
    rows = []
    info = train_garment_model(root / "data.json", tmp_path / "hybrid", cfg, body=body, physics=hybrid,
                               progress=rows.append)
    assert info["hybrid"]["simulated_sequences"] == 1 and info["hybrid"]["supervised_weight"] == 1e8
    assert info["best_step"] == 40  # the last weights, whatever the validation energy did
    assert np.isnan(rows[0]["train_sim_mm"]) and rows[1]["train_sim_mm"] > rows[-1]["train_sim_mm"]
    from cloth_usd.nn.garment_model import load_garment_run

    net, _ = load_garment_run(tmp_path / "hybrid")
    with torch.no_grad():
        moved = _garment(net, _prepared([first])[0], frames, body).numpy()
    assert np.linalg.norm(moved - target, axis=-1).mean() < 0.5 * 0.02
    physics_only = json.loads((root / "coarse" / "run.json").read_text())
    assert physics_only["hybrid"] is None


def test_a_target_of_the_first_frames_only_is_trained_on_those(own, tmp_path):
    """A kept part of a sequence that went unstable in Newton (``SimConfig.keep_partial``) is a
    target of its first frames: the supervised batches draw from those alone, and the model
    comes toward the target there."""
    import dataclasses

    from cloth_usd.nn.garment_model import (GarmentModelConfig, _first, _garment, _prepared, load_garment_run,
                                            train_garment_model)

    root, body, data, *_ = own
    first = data.split("train")[0]
    kept = _first(first) + 4
    assert kept < first.num_frames
    skinned = _garment(None, _prepared([first])[0], np.arange(kept), body).numpy()
    target = (skinned - [0.0, 0.02, 0.0]).astype(np.float32)
    clips = tuple(dataclasses.replace(c, target=target) if c is first else c for c in data.clips)
    cfg = GarmentModelConfig(steps=40, val_every=20, hidden=32, layers=2, bending_scale=10.0, lr=2e-2,
                             supervised_share=1.0, supervised_weight=1e8)
    info = train_garment_model(root / "data.json", tmp_path / "part", cfg, body=body,
                               physics=dataclasses.replace(data, clips=clips))
    assert info["hybrid"]["simulated_sequences"] == 1 and info["hybrid"]["simulated_frames"] == 4
    net, _ = load_garment_run(tmp_path / "part")
    with torch.no_grad():
        moved = _garment(net, _prepared([first])[0], np.arange(_first(first), kept), body).numpy()
    assert np.linalg.norm(moved - target[_first(first):], axis=-1).mean() < 0.5 * 0.02


def test_the_coarse_model_can_learn_newtons_frames_smoothed_as_the_papers_coarse_tier(own, tmp_path):
    """sim_target taubin: the spring pulls toward Newton's frames with their wrinkles smoothed out
    (the paper's coarse ground truth); the detail tier refuses it, an unknown target is one line."""
    import dataclasses

    from cloth_usd.core.mesh import laplacian_smooth
    from cloth_usd.nn.data import TAUBIN_LAMBDA, TAUBIN_MU, TAUBIN_PASSES
    from cloth_usd.nn.garment_model import (GarmentModelConfig, _garment, _prepared, _sim_targets,
                                            train_garment_model)

    root, body, data, *_ = own
    first = data.split("train")[0]
    frames = np.arange(first.num_frames)
    skinned = _garment(None, _prepared([first])[0], frames, body).numpy()
    wrinkles = np.random.default_rng(0).normal(0.0, 0.004, skinned.shape)  # 4 mm of vertex-sized detail
    target = (skinned - [0.0, 0.02, 0.0] + wrinkles).astype(np.float32)
    clips = tuple(dataclasses.replace(c, target=target) if c is first else c for c in data.clips)
    hybrid = dataclasses.replace(data, clips=clips)
    prepared = _prepared(hybrid.split("train"))
    assert _sim_targets(prepared, "simulation")[0] is target and len(_sim_targets(prepared, "taubin")) == 1
    smooth = _sim_targets(prepared, "taubin")[0]
    np.testing.assert_allclose(smooth, laplacian_smooth(target, first.pair.faces, iterations=TAUBIN_PASSES,
                                                        lam=TAUBIN_LAMBDA, mu=TAUBIN_MU), atol=1e-6)
    # the detail is gone, the garment's place is kept
    clean = skinned - [0.0, 0.02, 0.0]
    off = lambda x: np.linalg.norm(x - clean, axis=-1).mean()
    assert off(smooth) < 0.6 * off(target), (off(smooth), off(target))
    assert np.abs(smooth.mean(axis=1) - target.mean(axis=1)).max() < 1e-3
    cfg = GarmentModelConfig(steps=20, val_every=10, hidden=32, layers=2, bending_scale=10.0, lr=2e-2,
                             supervised_share=1.0, supervised_weight=1e8, sim_target="taubin")
    info = train_garment_model(root / "data.json", tmp_path / "taubin", cfg, body=body, physics=hybrid)
    assert info["hybrid"]["sim_target"] == "taubin" and info["config"]["sim_target"] == "taubin"
    with pytest.raises(ArgumentError, match="detail tier trains toward Newton's frames themselves"):
        train_garment_model(root / "data.json", tmp_path / "detail", cfg, tier="detail", coarse_run=root / "coarse",
                            body=body, physics=hybrid)
    with pytest.raises(ArgumentError, match="sim_target must be one of simulation, taubin"):
        GarmentModelConfig(sim_target="smooth")


def test_mirror_trains_on_each_sequence_and_its_mirror_image(own, tmp_path):
    """config.mirror: the training sequences and their mirror images (left for right), the hybrid
    target mirrored with them; a garment that is not symmetric is refused, naming the config."""
    import dataclasses

    from cloth_usd.nn.garment_model import GarmentModelConfig, _mirrored, train_garment_model

    root, body, data, *_ = own
    first = data.split("train")[0]
    target = np.broadcast_to(first.rest_points, (first.num_frames, *first.rest_points.shape)).astype(np.float32)
    hybrid = dataclasses.replace(data, clips=tuple(dataclasses.replace(c, target=target) if c is first else c
                                                   for c in data.clips))
    cfg = GarmentModelConfig(steps=4, val_every=2, hidden=16, layers=1, mirror=True)
    info = train_garment_model(root / "data.json", tmp_path / "m", cfg, body=body, physics=hybrid)
    train = hybrid.split("train")
    assert info["data"]["mirrored"] is True and info["data"]["train_sequences"] == 2 * len(train)
    assert info["hybrid"]["simulated_sequences"] == 2  # the simulated sequence and its mirror image
    image = _mirrored([train[0]], "c")[0]
    assert image.name.endswith("-mirrored") and image.target.shape == target.shape
    np.testing.assert_allclose(image.transl, first.transl * [-1.0, 1.0, 1.0])
    lopsided = dataclasses.replace(first, rest_points=first.rest_points + np.where(
        first.rest_points[:, :1] > 0.1, [0.0, -0.05, 0.0], 0.0))
    with pytest.raises(ArgumentError, match=r"^c: the garment of .* is not symmetric left for right"):
        _mirrored([lopsided], "c")


def test_export_writes_a_bundle_bound_to_the_garment_that_animates_it(own, tmp_path):
    from cloth_usd.core.garment_inputs import garment_displacement_inputs
    from cloth_usd.core.heading import heading_frame
    from cloth_usd.nn.garment_model import export_garment_bundle, load_garment_run, rounded_to_half
    from cloth_usd.runtime.bundle import load_bundle
    from cloth_usd.runtime.garment import LearnedGarment
    from cloth_usd.datagen import walk_cycle

    root, body, data, verts, faces, betas, _, _ = own
    with pytest.raises(ArgumentError, match=r"^--category dress: the runs were trained on a tshirt \("):
        export_garment_bundle(root / "coarse", root / "detail", root / "data.json", tmp_path / "b", name="mine",
                              category="dress", body=body, physics=data)
    assert not (tmp_path / "b").exists()
    out = export_garment_bundle(root / "coarse", root / "detail", root / "data.json", tmp_path / "b", name="mine",
                                body=body, physics=data)  # the category: the garment's own
    bundle = load_bundle(out)
    assert bundle.category.value == "tshirt"
    assert bundle.garment.vertices == len(verts) and bundle.garment.faces_sha256 == faces_sha256(faces)
    assert bundle.manifest["models"]["detail"]["inputs"] == ["pose", "betas"]
    parity = bundle.manifest["metrics"]["export_parity"]
    assert max(parity.values()) <= 1e-5
    poses, transl = walk_cycle(4)
    garment = LearnedGarment(bundle, body, betas, verts, faces, smoothing=0)  # the models' displacement as they give it
    skinned = skin_garment(garment.binding, poses, transl, body.parents)
    garment.evaluate("coarse", poses, transl)
    assert "limiter" not in vars(garment)  # the coarse tier never factors the detail tier's strain limiter
    coarse = garment.evaluate("coarse", poses, transl, postprocess=False).points
    detail = garment.evaluate("detail", poses, transl, postprocess=False).points
    assert 1e-4 < np.abs(coarse - skinned).max() < 0.15 and np.abs(detail - coarse).max() > 1e-6
    # each file holds one model, its weights stored as float16; the detail tier adds the coarse file's displacement
    assert bundle.manifest["models"]["detail"]["adds"] == "coarse" and bundle.detail_adds_coarse
    assert max(bundle.manifest["metrics"]["float16_weights"].values()) < 1e-4
    import onnx

    for tier in ("coarse", "detail"):
        weights = onnx.load(str(bundle.path / bundle.manifest["models"][tier]["file"])).graph.initializer
        biggest = max(weights, key=lambda w: int(np.prod(w.dims)))
        assert biggest.data_type == onnx.TensorProto.FLOAT16 and list(biggest.dims) == [3 * len(verts), 32]
    canonical = heading_frame(poses, transl, garment.pair.joints[0]).canonical_poses(poses)
    inputs = garment_displacement_inputs(canonical, garment.betas)
    nets = [rounded_to_half(load_garment_run(root / tier)[0]) for tier in ("coarse", "detail")]
    with torch.no_grad():
        args = torch.from_numpy(inputs["pose"]).double(), torch.from_numpy(inputs["betas"]).double()
        d = (nets[0](*args) + nets[1](*args)).numpy()
    np.testing.assert_allclose(detail, skin_displaced(garment.binding, poses, transl, body.parents, d), atol=1e-5)
    # a bake smooths its part along the rest garment's normals first (OWN_SMOOTHING Taubin passes)
    baked = LearnedGarment(bundle, body, betas, verts, faces).evaluate("detail", poses, transl,
                                                                     postprocess=False).points
    smooth = smooth_along_normals(d, vertex_normals(garment.binding.rest_points, faces), faces, OWN_SMOOTHING)
    np.testing.assert_allclose(baked, skin_displaced(garment.binding, poses, transl, body.parents, smooth), atol=1e-5)
    with pytest.raises(ArgumentError, match="smoothing must be a whole number of passes >= 0, got -1"):
        LearnedGarment(bundle, body, betas, verts, faces, smoothing=-1)
    # another garment's triangles are refused in one line naming the bundle
    with pytest.raises(BundleError, match="mine") as err:  # the same points, one triangle fewer
        LearnedGarment(bundle, body, betas, verts, faces[1:])
    assert "\n" not in str(err.value) and "train-garment" in str(err.value)


def test_a_garment_reads_the_joints_that_move_it_their_chain_their_children_and_mirrors():
    """read_joints: a garment bound to the left thigh (and a trace of the left hand, under the
    weight that counts) reads the pelvis above it and the right side, not the knees below it,
    unless it lies on a body vertex the knee moves (a skirt on the shins)."""
    from cloth_usd.core.garment_inputs import READ_WEIGHT, read_joints
    from cloth_usd.core.smpl import JOINT_NAMES

    w = np.zeros((3, 24))
    w[:, JOINT_NAMES.index("left_hip")] = 1.0
    w[0, JOINT_NAMES.index("left_hand")] = 0.5 * READ_WEIGHT
    read = {JOINT_NAMES[j] for j in np.flatnonzero(read_joints(w))}
    assert read == {"pelvis", "left_hip", "right_hip"}
    shin = np.zeros((1, 24))
    shin[0, JOINT_NAMES.index("right_knee")] = 1.0
    read = {JOINT_NAMES[j] for j in np.flatnonzero(read_joints(w, shin))}
    assert read == {"pelvis", "left_hip", "right_hip", "left_knee", "right_knee"}
    with pytest.raises(ValueError, match=r"\(N, 24\)"):
        read_joints(np.zeros((3, 23)))


def test_the_model_reads_only_the_joints_that_move_its_garment(own, tmp_path):
    """A T-shirt's model ignores its hands and feet: the exported files give the same garment
    whatever they do, the manifest gives them the whole circle (a bake warns of no hand), and a
    run made before the models read the joints (no ``pose_joints``) reads all 24, as it was trained."""
    from cloth_usd.core.garment_inputs import garment_displacement_inputs
    from cloth_usd.core.limits import pose_outliers
    from cloth_usd.core.smpl import JOINT_NAMES
    from cloth_usd.datagen import walk_cycle
    from cloth_usd.nn.garment_model import export_garment_bundle, load_garment_run
    from cloth_usd.runtime.bundle import load_bundle
    from cloth_usd.runtime.session import ModelSession

    root, body, data, *_ = own
    run = json.loads((root / "coarse" / "run.json").read_text())
    assert {"spine3", "left_shoulder", "left_hip"} <= set(run["pose_joints"])
    unread = sorted(set(JOINT_NAMES) - set(run["pose_joints"]))
    assert {"left_hand", "right_hand", "left_foot", "right_foot"} <= set(unread)
    bundle = load_bundle(export_garment_bundle(root / "coarse", root / "detail", root / "data.json", tmp_path / "b",
                                               name="mine", body=body, physics=data))
    poses, _ = walk_cycle(3)
    turned = poses.copy()
    for name in unread:
        turned[:, 3 * JOINT_NAMES.index(name):3 * JOINT_NAMES.index(name) + 3] = [2.9, 0.4, -0.3]
    shoulder = poses.copy()
    shoulder[:, 3 * JOINT_NAMES.index("left_shoulder") + 2] += 0.5
    for tier in ("coarse", "detail"):
        session = ModelSession(bundle.path / bundle.manifest["models"][tier]["file"], prefer_gpu=False)
        out = [session.run(garment_displacement_inputs(p, np.zeros(10)))["delta"]
               for p in (poses, turned, shoulder)]
        np.testing.assert_array_equal(out[0], out[1])
        assert np.abs(out[2] - out[0]).max() > 1e-6
        assert bundle.manifest["models"][tier]["config"]["pose_joints"] == run["pose_joints"]
    assert bundle.manifest["training_data"]["poses"]["euler_deg"]["left_hand"] == [[-180.0, 180.0]] * 3
    assert pose_outliers(turned, limits=bundle.pose_limits) is None
    # a run from before: every joint, the net as it was trained
    (tmp_path / "old").mkdir()
    for name in ("model.pt", "history.csv"):
        (tmp_path / "old" / name).write_bytes((root / "coarse" / name).read_bytes())
    old = {k: v for k, v in run.items() if k != "pose_joints"}
    (tmp_path / "old" / "run.json").write_text(json.dumps(old))
    assert load_garment_run(tmp_path / "old")[0].joints.all()
    assert not load_garment_run(root / "coarse")[0].joints.all()


def test_cloth_usd_export_re_exports_garment_runs_with_their_evaluation(own, tmp_path, capsys):
    """``cloth-usd export`` of a train-garment work folder's runs: byte-identical files, and
    evaluation metrics measured on them are recorded as the same models."""
    from cloth_usd.cli import main

    root = own[0]
    args = ["export", "--coarse-run", str(root / "coarse"), "--detail-run", str(root / "detail"),
            "--data", str(root / "data.json"), "--name", "mine"]
    assert main([*args, "-o", str(tmp_path / "a")]) == 0
    first = json.loads((tmp_path / "a" / "manifest.json").read_text())
    (tmp_path / "m.json").write_text(json.dumps({"bundle": {"files": first["files"]}, "rows": []}))
    assert main([*args, "-o", str(tmp_path / "b"), "--metrics", str(tmp_path / "m.json")]) == 0
    second = json.loads((tmp_path / "b" / "manifest.json").read_text())
    assert second["files"] == first["files"] and second["metrics"]["evaluation"]["same_models"] is True
    assert second["garment"] == first["garment"] and second["models"]["detail"]["adds"] == "coarse"
    capsys.readouterr()
    assert main([*args, "-o", str(tmp_path / "c"), "--parity-data", str(tmp_path)]) == 2
    assert "--parity-data" in capsys.readouterr().err


def test_a_detail_run_needs_its_coarse_run_and_one_garment(own, tmp_path):
    from cloth_usd.nn.garment_model import GarmentModelConfig, train_garment_model

    root, body, data, *_ = own
    with pytest.raises(ArgumentError, match="coarse_run"):
        train_garment_model(root / "data.json", tmp_path / "d", GarmentModelConfig(steps=1), tier="detail",
                            body=body, physics=data)
    with pytest.raises(ArgumentError, match="lr"):
        GarmentModelConfig(lr=0.0)


def test_train_garment_refuses_several_garments_for_the_garment_form(tmp_path, capsys):
    from pathlib import Path

    from cloth_usd.cli import main

    sample = Path(__file__).resolve().parents[2] / "samples" / "walk_tshirt" / "scene.usda"
    assert main(["train-garment", str(sample), str(sample), "-o", str(tmp_path / "b"), "--form", "garment"]) == 2
    err = capsys.readouterr().err
    assert "--form paper" in err and len(err.strip().splitlines()) == 1 and not (tmp_path / "b").exists()


def test_evaluate_measures_the_sequences_that_wear_the_bundles_garment(tmp_path_factory, tmp_path, caplog):
    """A test set of several garments: a garment's own bundle is measured on its garment's
    sequences alone, and a test set without that garment is one line naming it."""
    from cloth_usd.core.pipeline import CoarseBase, CoarseFeatures, CoarseForm
    from cloth_usd.core.heading import Heading
    from cloth_usd.evaluate import evaluate_bundle
    from cloth_usd.nn.data import load_dataset
    from cloth_usd.nn.garment_model import GarmentNet, HalfStored, _export
    from cloth_usd.runtime.bundle import GarmentIdentity, write_bundle

    data = tiny_dataset(tmp_path_factory)
    clips = load_dataset(data, None).clips
    garments = {faces_sha256(c.pair.faces): c for c in clips}
    assert len(garments) > 1  # the tiny set wears several shirts
    clip = clips[0]
    n, sha = len(clip.rest_points), faces_sha256(clip.pair.faces)
    worn = sum(1 for c in clips if faces_sha256(c.pair.faces) == sha and c.split.value.startswith("test"))

    def bundle(identity, name):
        model = tmp_path / f"{name}.onnx"
        _export(HalfStored(GarmentNet(identity.vertices, hidden=8, layers=1)), model)
        (tmp_path / "fit.npz").write_bytes((data / "fit.npz").read_bytes())
        return write_bundle(tmp_path / name, name=name, category="tshirt", coarse_onnx=model, detail_onnx=None,
                            fit_npz=tmp_path / "fit.npz", configs={}, training_data={}, metrics={}, opset=18,
                            form=CoarseForm(CoarseBase.SKINNED, Heading.CANONICAL, CoarseFeatures.BODY),
                            garment=identity)

    report = evaluate_bundle(data, bundle(GarmentIdentity(n, sha), "own"), tmp_path / "report", max_frames=3)
    assert report.rows[-1]["sequences"] == worn
    # an untrained garment model is the skinned garment: its coarse tier is skinning's error (after the post-process)
    row = report.rows[-1]["mean_mm"]
    assert abs(row["coarse"] - row["skinning"]) < 2.0
    with pytest.raises(ArgumentError, match="no sequence wears") as err:
        evaluate_bundle(data, bundle(GarmentIdentity(n + 1, sha), "other"), tmp_path / "report2", max_frames=3)
    assert "\n" not in str(err.value)


def test_a_garments_own_bundle_reads_the_test_sequences_garment_as_authored(tmp_path_factory, tmp_path):
    """A data set keeps each garment as it was handed to the simulator, before the drape (its
    drape cache's ``source``): a garment's own bundle reads that one, as a bake of the authored
    garment does, and a category's bundle the draped garment the simulation starts from."""
    import shutil

    from cloth_usd.evaluate import garment_reads, learned_garment
    from cloth_usd.nn.data import load_dataset
    from cloth_usd.runtime.bundle import GarmentIdentity, load_bundle, write_bundle

    data = tmp_path / "data"
    shutil.copytree(tiny_dataset(tmp_path_factory), data)
    clip = load_dataset(data, None).clips[0]
    assert clip.authored_points is None  # no drape cache: nothing to read
    authored = clip.rest_points + [0.0, 0.01, 0.0]  # the drape let it down by 1 cm
    (data / "drape").mkdir(exist_ok=True)
    np.savez(data / "drape" / "pair.npz", vertices=clip.rest_points, faces=clip.pair.faces, source=authored)
    clips = load_dataset(data, None).clips
    same = [c for c in clips if np.array_equal(c.rest_points, clip.rest_points)]
    assert same and all(np.array_equal(c.authored_points, authored) for c in same)
    assert all(c.authored_points is None for c in clips if c not in same)
    (data / "c.onnx").write_bytes(b"-")
    own = write_bundle(tmp_path / "own", name="own", category="tshirt", coarse_onnx=data / "c.onnx", detail_onnx=None,
                       fit_npz=data / "fit.npz", configs={}, training_data={}, metrics={}, opset=18,
                       garment=GarmentIdentity(len(authored), faces_sha256(clip.pair.faces)))
    body = load_body_model()
    own = load_bundle(own)
    # no record of its rest: the garment as authored, which a bake reads, where every sequence keeps it
    assert garment_reads(own, same) == "authored" and garment_reads(own, clips) == "draped"
    np.testing.assert_allclose(learned_garment(own, body, same[0], "authored").binding.rest_points, authored)
    for trained_on, reads in ((authored, "authored"), (clip.rest_points, "draped")):  # recorded: the one it learned
        recorded = write_bundle(tmp_path / reads, name=reads, category="tshirt", coarse_onnx=data / "c.onnx",
                                detail_onnx=None, fit_npz=data / "fit.npz", configs={}, training_data={}, metrics={},
                                opset=18, garment=own.garment, garment_rest=(trained_on, clip.pair.betas))
        assert garment_reads(load_bundle(recorded), clips) == reads
    graph = write_bundle(tmp_path / "graph", name="graph", category="tshirt", coarse_onnx=data / "c.onnx",
                         detail_onnx=None, fit_npz=data / "fit.npz", configs={}, training_data={}, metrics={}, opset=18)
    assert garment_reads(load_bundle(graph), clips) == "draped"
    assert learned_garment(load_bundle(graph), body, same[0]).binding is same[0].pair.binding
    # evaluate --rest authored hands every tier the garment before the drape: a data set that keeps
    # none of some sequences is one line naming it
    from cloth_usd.evaluate import evaluate_bundle

    with pytest.raises(ArgumentError, match="keeps no drape of") as err:
        evaluate_bundle(data, graph, tmp_path / "report", rest="authored")
    assert "\n" not in str(err.value)
    with pytest.raises(ArgumentError, match="--rest 'folded'"):
        evaluate_bundle(data, graph, tmp_path / "report", rest="folded")


def test_a_broken_run_is_one_line_naming_it(own, tmp_path):
    import shutil

    from cloth_usd.nn.garment_model import load_garment_run

    root = own[0]
    run = tmp_path / "run"
    shutil.copytree(root / "coarse", run)
    (run / "model.pt").write_bytes(b"not a model")
    with pytest.raises(ArgumentError, match="model.pt") as err:
        load_garment_run(run)
    assert "\n" not in str(err.value)
    (run / "run.json").write_text('{"kind": "coarse"}')
    with pytest.raises(ArgumentError, match="not a garment model run"):
        load_garment_run(run)

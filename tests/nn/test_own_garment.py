"""A user's own garment: the data set config that names it, and ``cloth-usd train-garment``."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest

from cloth_usd.core.body import load_body_model, shape_body
from cloth_usd.datagen import TShirtParams, make_tshirt
from cloth_usd.datagen.factory import OWN_BODY, load_config, plan_jobs, save_own_garment
from cloth_usd.errors import ArgumentError
from cloth_usd.nn.own_garment import PROCEDURAL_MOTIONS, stored_motions, stored_test_motions

SAMPLE = Path(__file__).resolve().parents[2] / "samples" / "walk_tshirt" / "scene.usda"


@pytest.fixture(scope="module")
def own_config(tmp_path_factory):
    """A 300-vertex shirt made for a broad body, named by a config as the user's own."""
    body = load_body_model()
    betas = np.r_[1.0, 1.0, np.zeros(8)]
    verts, faces = make_tshirt(body, betas, TShirtParams(target_vertices=300))
    root = tmp_path_factory.mktemp("own")
    save_own_garment(root / "g.npz", verts, faces, betas)
    (root / "data.json").write_text(json.dumps({
        "garment": "g.npz", "bodies": [OWN_BODY, "slim", "short_fat", "tall_thin", "medium_thin"],
        "test_bodies": ["medium_thin"], "max_frames": 3,
        "train_motions": [{"kind": "walk", "seconds": 1.0, "seed": 0}],
        "test_motions": [{"kind": "dance", "seconds": 1.0, "seed": 5}]}))
    return root / "data.json", verts, faces, betas


def test_every_sequence_wears_the_one_garment_carried_onto_its_body(own_config):
    path, verts, faces, betas = own_config
    body = load_body_model()
    jobs = plan_jobs(load_config(path), body)
    assert {j.meta["split"] for j in jobs} == {"train", "val", "test_body", "test_motion"}  # no unseen garment
    for job in jobs:
        np.testing.assert_array_equal(job.garment_faces, faces)
        assert job.meta["shirt_label"] == "own" and job.meta["shirt_params"] == {"file": "g.npz"}
    own = next(j for j in jobs if j.meta["body"] == OWN_BODY)
    np.testing.assert_allclose(own.garment_vertices, verts, atol=1e-12)
    np.testing.assert_allclose(own.betas, betas)
    # on a short, fat body the shirt sits as far from the body as on its own
    from cloth_usd.core.association import associate

    fat = next(j for j in jobs if j.meta["body"] == "short_fat")
    gap_own = associate(verts, shape_body(body, betas)[0], body.faces).distance
    gap_fat = associate(fat.garment_vertices, shape_body(body, fat.betas)[0], body.faces).distance
    assert abs(np.median(gap_fat) - np.median(gap_own)) < 2e-3, (np.median(gap_fat), np.median(gap_own))


def test_a_config_without_a_garment_cannot_name_the_own_body(tmp_path):
    (tmp_path / "c.json").write_text(json.dumps({"bodies": [OWN_BODY, "slim"], "test_bodies": []}))
    with pytest.raises(ArgumentError, match="own garment"):
        plan_jobs(load_config(tmp_path / "c.json"))


def test_a_broken_garment_file_is_one_line_naming_it(tmp_path):
    np.savez(tmp_path / "g.npz", vertices=np.zeros((3, 3)), faces=np.array([[0, 1, 5]]), betas=np.zeros(10))
    (tmp_path / "c.json").write_text(json.dumps({"garment": "g.npz", "bodies": [OWN_BODY, "slim"],
                                                 "test_bodies": []}))
    with pytest.raises(ArgumentError, match="g.npz"):
        plan_jobs(load_config(tmp_path / "c.json"))


def test_train_garment_refuses_an_existing_bundle_and_a_stage_without_that_garment(tmp_path, capsys):
    from cloth_usd.cli import main

    (tmp_path / "b").mkdir()
    (tmp_path / "b" / "manifest.json").write_text("{}")
    assert main(["train-garment", str(SAMPLE), "-o", str(tmp_path / "b")]) == 2
    assert "--force" in capsys.readouterr().err
    assert main(["train-garment", str(SAMPLE), "-o", str(tmp_path / "c"), "--garment", "/Nope"]) == 2
    err = capsys.readouterr().err
    assert "/Nope" in err and "/Character/Tshirt" in err and not (tmp_path / "c").exists()
    (tmp_path / "m.json").write_text('{"bvh": "a.bvh"}')  # an entry, not a list of them
    assert main(["train-garment", str(SAMPLE), "-o", str(tmp_path / "c"),
                 "--test-motions", str(tmp_path / "m.json")]) == 2
    err = capsys.readouterr().err
    assert "--test-motions" in err and "m.json" in err and len(err.strip().splitlines()) == 1
    assert not (tmp_path / "c").exists()
    (tmp_path / "m.json").write_text("[]")  # refused, not read as the default
    assert main(["train-garment", str(SAMPLE), "-o", str(tmp_path / "c"),
                 "--test-motions", str(tmp_path / "m.json")]) == 2
    err = capsys.readouterr().err
    assert "--test-motions" in err and "empty" in err and len(err.strip().splitlines()) == 1
    assert not (tmp_path / "c").exists()
    assert main(["train-garment", str(SAMPLE), "-o", str(tmp_path / "c"), "--form", "paper",
                 "--sim-data", str(tmp_path)]) == 2
    assert "--sim-data" in capsys.readouterr().err and not (tmp_path / "c").exists()
    assert main(["train-garment", str(SAMPLE), "-o", str(tmp_path / "c"), "--sim-sequences", "0"]) == 2
    assert "--sim-sequences" in capsys.readouterr().err and not (tmp_path / "c").exists()
    assert main(["train-garment", str(SAMPLE), "-o", str(tmp_path / "c"), "--form", "paper", "--mirror"]) == 2
    assert "--mirror" in capsys.readouterr().err and not (tmp_path / "c").exists()
    with pytest.raises(SystemExit) as exit_:
        main(["train-garment", str(SAMPLE), "-o", str(tmp_path / "c"), "--coarse-target", "smooth"])
    assert exit_.value.code == 2 and "--coarse-target" in capsys.readouterr().err and not (tmp_path / "c").exists()
    # the parser writes the garment model's targets out (it imports no torch): they stay the same
    from cloth_usd.cli import _parser
    from cloth_usd.nn.garment_model import SIM_TARGETS

    train = _parser()._subparsers._group_actions[0].choices["train-garment"]
    assert tuple(next(a for a in train._actions if a.dest == "coarse_target").choices) == SIM_TARGETS


@pytest.mark.slow
def test_train_garment_makes_a_bundle_that_bakes_the_sample(tmp_path, capsys):
    pytest.importorskip("torch", reason="training needs torch (pip install 'cloth-usd[train]')")
    from cloth_usd.cli import main
    from cloth_usd.runtime.bundle import load_bundle

    out = tmp_path / "mine"
    held_out = [{"kind": "arm_raise", "seconds": 1.0, "fps": 30, "seed": 40}]
    (tmp_path / "test_motions.json").write_text(json.dumps(held_out))
    (tmp_path / "none.json").write_text("[]")
    assert main(["train-garment", str(SAMPLE), "-o", str(out), "--form", "paper", "--coarse-epochs", "1",
                 "--detail-epochs", "1", "--batches", "1", "--threads", "1", "--device", "cpu",
                 "--test-motions", str(tmp_path / "test_motions.json"), "--motions", str(tmp_path / "none.json")]) == 0
    said = capsys.readouterr().out
    assert "wrote bundle" in said and "3516 vertices" in said and "testset.json" in said
    # the work folder's test set config plans the held-out motion, and datagen simulates that alone:
    # the garment on its own body and on the slim one, and on the validation body
    testset = load_config(tmp_path / "mine.work" / "testset.json")
    simulated = [j for j in plan_jobs(testset) if j.meta["split"] in testset.simulate_splits]
    assert sorted((j.meta["split"], j.meta["body"], j.meta["motion"]) for j in simulated) == [
        ("test_body", "medium_thin", "arm_raise-s40"), ("test_motion", OWN_BODY, "arm_raise-s40"),
        ("test_motion", "slim", "arm_raise-s40")]
    training = load_config(tmp_path / "mine.work" / "data.json")  # trains as before, on the dance and walk held out
    assert training.simulate_splits is None and testset.garment == training.garment
    assert testset.sim == {**training.sim, "collider_faces": None, "self_contact": False}  # as the shipped test sets
    assert [m["kind"] for m in training.test_motions] == ["dance", "walk"]
    assert list(training.train_motions) == list(PROCEDURAL_MOTIONS)  # --motions []: the procedural ones alone
    bundle = load_bundle(out)
    assert bundle.manifest["category"] == "tshirt" and bundle.manifest["name"] == "mine"
    assert json.loads((tmp_path / "mine.work" / "timing.json").read_text())["total"] > 0
    assert main(["bake", str(SAMPLE), "-o", str(tmp_path / "c.usdc"), "--tier", "detail", "--models", str(out),
                 "--frames", "1001:1003", "--no-progress"]) == 0
    assert "bundle mine" in capsys.readouterr().err + capsys.readouterr().out or (tmp_path / "c.usdc").is_file()
    # a second call refuses to replace the runs and the bundle, unless forced
    assert main(["train-garment", str(SAMPLE), "-o", str(out)]) == 2


@pytest.mark.slow
def test_train_garment_of_the_garment_form_bakes_the_sample(tmp_path, capsys):
    """The default form: the sample shirt's own models, baked; the bundle serves that shirt alone."""
    pytest.importorskip("torch", reason="training needs torch (pip install 'cloth-usd[train]')")
    from cloth_usd.cli import main
    from cloth_usd.runtime.bundle import load_bundle

    out = tmp_path / "own"
    assert main(["train-garment", str(SAMPLE), "-o", str(out), "--steps", "30", "--detail-steps", "10",
                 "--threads", "1", "--sim-sequences", "12", "--coarse-target", "taubin", "--mirror"]) == 0
    said = capsys.readouterr().out
    assert "coarse step 30" in said and "detail step 10" in said and "3516 vertices" in said
    # the work folder's hybrid config: the training sequences, --sim-sequences of them simulated
    # with the test set's solver settings; the closing lines say how to train on them
    assert "hybrid.json" in said and "--sim-data" in said
    assert "its models read" in said and "left_hand, right_hand, which cannot move it" in said
    hybrid = load_config(tmp_path / "own.work" / "hybrid.json")
    training = load_config(tmp_path / "own.work" / "data.json")
    # no --motions: the procedural motions and the CMU stretches shipped with the package
    assert list(training.train_motions) == [*PROCEDURAL_MOTIONS, *stored_motions()] and len(stored_motions()) == 24
    assert hybrid.simulate_splits == ("train",) and hybrid.simulate_sequences == {"train": 12}
    # no --test-motions: the Newton test set holds out the three CMU test stretches shipped with the package
    testset = load_config(tmp_path / "own.work" / "testset.json")
    assert list(testset.test_motions) == list(stored_test_motions()) and len(stored_test_motions()) == 3
    held = {j.meta["motion"] for j in plan_jobs(testset) if j.meta["split"] in testset.simulate_splits}
    assert held == {m["stored"] for m in stored_test_motions()}
    command = next(line for line in said.splitlines() if "a Newton test set for it" in line)
    assert "testset.json" in command and "--mocap" not in command  # its datagen command needs no mocap folder
    assert hybrid.sim == {**training.sim, "collider_faces": None, "self_contact": False, "keep_partial": 15}
    assert [j.name for j in plan_jobs(hybrid)] == [j.name for j in plan_jobs(training)]
    # --coarse-target: the coarse model's spring pulls toward Newton's frames smoothed; the detail's, the frames
    tiers = {t: json.loads((tmp_path / "own.work" / f"{t}.json").read_text()) for t in ("coarse", "detail")}
    assert tiers["coarse"]["sim_target"] == "taubin" and tiers["detail"]["sim_target"] == "simulation"
    # --mirror: both models train on every training sequence and its mirror image (the sample shirt is symmetric)
    assert tiers["coarse"]["mirror"] is True and tiers["detail"]["mirror"] is True
    run = json.loads((tmp_path / "own.work" / "coarse" / "run.json").read_text())
    assert run["data"]["mirrored"] is True and run["data"]["train_sequences"] == 2 * len(
        [j for j in plan_jobs(training) if j.meta["split"] == "train"])
    bundle = load_bundle(out)
    assert bundle.garment is not None and bundle.garment.vertices == 3516
    # the recorded pose range is the range trained on: the motions and their mirror images
    from cloth_usd.core.limits import pose_range
    from cloth_usd.datagen.factory import train_poses
    from cloth_usd.nn.mirror import mirror_poses

    poses = train_poses(training)
    both = np.concatenate([poses, mirror_poses(poses)])
    assert bundle.manifest["training_data"]["poses"]["frames"] == len(both)
    from cloth_usd.core.smpl import JOINT_NAMES

    read = np.isin(JOINT_NAMES, bundle.manifest["models"]["coarse"]["config"]["pose_joints"])
    assert 0 < read.sum() < 24  # a T-shirt's models do not read its hands
    np.testing.assert_allclose(bundle.pose_limits[read], pose_range(both)[read], atol=np.deg2rad(0.006))
    np.testing.assert_allclose(bundle.pose_limits[~read], np.broadcast_to([-np.pi, np.pi], (24 - read.sum(), 3, 2)))
    assert (pose_range(both)[..., 1] - pose_range(poses)[..., 1])[read].max() > np.deg2rad(1)  # the images widen it
    timing = json.loads((tmp_path / "own.work" / "timing.json").read_text())
    assert set(timing) == {"plan", "coarse", "detail", "export", "total"}
    assert main(["bake", str(SAMPLE), "-o", str(tmp_path / "c.usdc"), "--tier", "detail", "--models", str(out),
                 "--frames", "1001:1004", "--no-progress", "--strict"]) == 0
    assert (tmp_path / "c.usdc").is_file()
    # the Z-up sample wears another shirt (3024 vertices): one line naming it, nothing written
    other = Path(__file__).resolve().parents[2] / "samples" / "walk_tshirt_zup_cm" / "scene.usda"
    assert main(["bake", str(other), "-o", str(tmp_path / "d.usdc"), "--tier", "detail", "--models", str(out),
                 "--frames", "1001:1002", "--no-progress"]) == 2
    err = capsys.readouterr().err.strip()
    assert "walk_tshirt_zup_cm" in err and "3516" in err and len(err.splitlines()) == 1
    assert not (tmp_path / "d.usdc").exists()
    # in a folder of bundles the sample's own bundle comes before the category's default, for the sample's shirt
    # alone: the Z-up sample's shirt bakes with the default from the same folder
    import shutil

    from cloth_usd.runtime.bundle import default_bundle_dir

    folder = tmp_path / "bundles"
    shutil.copytree(out, folder / "own")
    shutil.copytree(default_bundle_dir() / "tshirt-v6", folder / "tshirt-v6")
    (folder / "defaults.json").write_text('{"tshirt": "tshirt-v6"}')
    for scene, name in ((SAMPLE, "own"), (other, "tshirt-v6")):
        assert main(["bake", str(scene), "-o", str(tmp_path / f"{name}.usdc"), "--tier", "coarse", "--models",
                     str(folder), "--frames", "1001:1002", "--no-progress"]) == 0
        assert f"bundle {name}" in capsys.readouterr().out
    # inspect names the bundle the learned tiers would use, and says the other shirt's is not its own
    assert main(["inspect", str(SAMPLE), "--models", str(out)]) == 0
    assert "models own (its own)" in capsys.readouterr().out
    assert main(["inspect", str(other), "--models", str(out)]) == 1
    said = capsys.readouterr().out
    assert "models own (another garment's)" in said and "serves another garment (3516 vertices)" in said


def test_several_garments_each_worn_by_every_body_and_by_their_own(tmp_path):
    body = load_body_model()
    made = []
    for i, betas in enumerate((np.r_[1.0, 1.0, np.zeros(8)], np.r_[-1.0, 0.5, np.zeros(8)])):
        verts, faces = make_tshirt(body, betas, TShirtParams(target_vertices=200 + 100 * i))
        save_own_garment(tmp_path / f"g{i}.npz", verts, faces, betas, category="dress")
        made.append((verts, faces, betas))
    (tmp_path / "data.json").write_text(json.dumps({
        "garment": ["g0.npz", "g1.npz"], "bodies": [OWN_BODY, "slim", "medium_thin"], "test_bodies": ["medium_thin"],
        "max_frames": 2, "train_motions": [{"kind": "walk", "seconds": 1.0, "seed": 0}],
        "test_motions": [{"kind": "dance", "seconds": 1.0, "seed": 5}]}))
    jobs = plan_jobs(load_config(tmp_path / "data.json"), body)
    train = [j for j in jobs if j.meta["split"] == "train"]
    assert {(j.meta["shirt"], j.meta["body"]) for j in train} == {(0, OWN_BODY), (0, "slim"), (1, OWN_BODY), (1, "slim")}
    for job in jobs:
        verts, faces, betas = made[job.meta["shirt"]]
        np.testing.assert_array_equal(job.garment_faces, faces)
        assert job.meta["category"] == "dress" and job.meta["shirt_params"] == {"file": f"g{job.meta['shirt']}.npz"}
        if job.meta["body"] == OWN_BODY:  # each garment on the body it was made for
            np.testing.assert_allclose(job.betas, betas)
            np.testing.assert_allclose(job.garment_vertices, verts, atol=1e-12)


def test_garments_of_two_categories_are_refused_naming_them(tmp_path):
    body = load_body_model()
    verts, faces = make_tshirt(body, np.zeros(10), TShirtParams(target_vertices=200))
    save_own_garment(tmp_path / "a.npz", verts, faces, np.zeros(10), category="dress")
    save_own_garment(tmp_path / "b.npz", verts, faces, np.zeros(10), category="trousers")
    (tmp_path / "c.json").write_text(json.dumps({"garment": ["a.npz", "b.npz"], "bodies": [OWN_BODY, "slim"],
                                                 "test_bodies": []}))
    with pytest.raises(ArgumentError, match="dress, trousers"):
        plan_jobs(load_config(tmp_path / "c.json"), body)
    (tmp_path / "d.json").write_text(json.dumps({"garment": 3}))
    with pytest.raises(ArgumentError, match="garment must be"):
        load_config(tmp_path / "d.json")


def test_train_garment_refuses_stages_whose_garments_differ_in_category(tmp_path, capsys):
    from cloth_usd.cli import main

    dress = Path(__file__).resolve().parents[2] / "samples" / "walk_dress" / "dress.usda"
    assert main(["train-garment", str(dress), str(SAMPLE), "-o", str(tmp_path / "b")]) == 2
    err = capsys.readouterr().err
    assert "tshirt" in err and "dress" in err and "one category" in err and not (tmp_path / "b").exists()

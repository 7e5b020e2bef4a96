"""The configs the README's documented runs use stay loadable as the code changes."""

from __future__ import annotations

import json
from pathlib import Path

import pytest

from cloth_usd.datagen.factory import load_config, plan_jobs

CONFIGS = Path(__file__).resolve().parents[1] / "configs"


def test_the_medium_data_set_plans_its_documented_sequences():
    jobs = plan_jobs(load_config(CONFIGS / "datagen_medium.json"))
    splits = [j.meta["split"] for j in jobs]
    assert len(jobs) == 52 and splits.count("train") == 36  # as in the README's medium run
    assert len({j.garment_vertices.shape[0] for j in jobs}) > 6  # shirts differ in topology


def test_the_large_data_set_adds_bodies_to_the_medium_one():
    medium = {j.name for j in plan_jobs(load_config(CONFIGS / "datagen_medium.json"))}
    jobs = plan_jobs(load_config(CONFIGS / "datagen_large.json"))
    splits = [j.meta["split"] for j in jobs]
    assert splits.count("train") == 72  # 6 shirts x 4 bodies x 3 motions, as in the README
    assert medium - {j.name for j in jobs} <= {"val.shirt2.broad.walk-s101"}  # a resumable superset


@pytest.mark.parametrize("name", ["coarse", "coarse_taubin", "coarse_skinned", "coarse_skinned_laplacian", "detail",
                                  "detail_nodec", "detail_noparser"])
def test_training_configs_load(name):
    pytest.importorskip("torch")
    from cloth_usd.nn.train import load_train_config

    config = load_train_config(CONFIGS / f"train_{name}.json")
    assert config.width == (0.0625 if name.startswith("coarse") else 0.125)  # the shipped bundle's widths
    assert config.decompose == (name != "detail_nodec") and config.use_parser == (name != "detail_noparser")
    # train_coarse.json is METHOD.md's form; the shipped coarse model is train_coarse_skinned.json
    assert config.coarse_base.value == ("skinned" if name.startswith("coarse_skinned") else "body")
    assert config.coarse_target.value == ("taubin" if name in ("coarse_taubin", "coarse_skinned") else "stored")


def test_the_shipped_bundle_configs_train_in_the_world_frame():
    """tshirt-v3 was trained before the heading key; its configs keep reproducing it."""
    pytest.importorskip("torch")
    from cloth_usd.nn.train import load_train_config

    for name in ("coarse", "coarse_taubin", "coarse_skinned", "coarse_skinned_laplacian"):
        assert load_train_config(CONFIGS / f"train_{name}.json").heading.value == "world"


def test_the_physics_configs_plan_and_load():
    pytest.importorskip("torch")
    from cloth_usd.nn.train import load_train_config

    config = load_train_config(CONFIGS / "train_coarse_physics.json")
    assert (config.objective.value, config.heading.value, config.coarse_base.value) == ("physics", "canonical",
                                                                                         "skinned")
    jobs = plan_jobs(load_config(CONFIGS / "physics_tshirt.json"))
    splits = [j.meta["split"] for j in jobs]
    assert splits.count("train") == 140 and len({j.meta["motion"] for j in jobs}) == 9  # 7 kinds + 2 test motions


def test_the_experiment_configs_change_one_thing_from_what_they_measure_against():
    """The shape part of the test set is the test set's own unseen-body and unseen-shirt
    sequences; the corner-bodies and more-clips data configs of the T-shirt differ from
    ``tshirt-v6``'s in what their names say (docs/models.md, "Tried after tshirt-v6")."""
    def read(name):
        return json.loads((CONFIGS / name).read_text())

    full, shape = read("datagen_testset.json"), read("datagen_testset_shape.json")
    assert shape.pop("simulate_splits") == ["test_body", "test_garment"] and "floor" not in shape
    assert {k: v for k, v in full.items() if k not in ("simulate_splits", "floor")} == shape
    base, corners, more = (read(f"physics_tshirt_{n}.json") for n in ("mocap", "corners", "mocap_more"))
    bodies = corners.pop("bodies")
    assert bodies == ["short_thin", "short_fat", "tall_thin", "tall_fat", "slim", "broad", "medium_thin"]
    assert base.pop("bodies") != [] and corners == base
    motions = more.pop("train_motions")
    assert motions[:len(base["train_motions"])] == base["train_motions"] and len(motions) == 55
    held_out = {m["bvh"] for m in base["test_motions"]} | {  # and docs/models.md's other held-out clips
        "cmu-mb2_chrystianosaraujo-motion-viewer/02/02_03.bvh", "cmu-daz_papagina-acLSTM/martial/04.bvh",
        "cmu-daz_papagina-acLSTM/martial/10.bvh", "cmu-daz_papagina-acLSTM/indian/13.bvh"}
    assert not {m.get("bvh") for m in motions} & held_out
    assert more.pop("bodies") == bodies
    assert more == {k: v for k, v in base.items() if k != "train_motions"}


def test_the_fine_tune_configs_start_from_the_gpu_runs():
    """``cloth-usd train --init`` needs the initial run's width and coarse form: the fine-tune
    configs of ``tshirt-sim2`` are those of the GPU runs they start from (``train_*_gpu.json``)."""
    pytest.importorskip("torch")
    from cloth_usd.nn.physics_train import load_physics_config
    from cloth_usd.nn.train import load_train_config

    for tier in ("coarse", "detail"):
        config, options = load_physics_config(CONFIGS / f"train_{tier}_finetune_sim.json")
        gpu = load_train_config(CONFIGS / f"train_{tier}_gpu.json")
        assert config.objective.value == "physics" and options.anchor_weight == 1.0e7
        assert (config.width, config.decompose, config.use_parser) == (gpu.width, gpu.decompose, gpu.use_parser)
        if tier == "coarse":
            assert config.coarse_form == gpu.coarse_form


def test_the_own_garment_motion_lists_hold_out_the_test_clips():
    """train-garment's motion lists: real clips only, none of the test sets' (the three clips and the
    dance and martial-arts pair); the 24-clip list is tshirt-v6's training clips."""
    test = {m["bvh"] for name in ("own_garment_test_motions.json", "own_garment_test_motions_dance.json")
            for m in json.loads((CONFIGS / name).read_text())}
    assert len(test) == 5
    v6 = [m for m in json.loads((CONFIGS / "physics_tshirt_mocap.json").read_text())["train_motions"] if "bvh" in m]
    for name in ("own_garment_motions.json", "own_garment_motions_v6.json"):
        motions = json.loads((CONFIGS / name).read_text())
        assert motions and all("bvh" in m for m in motions), name
        assert not test & {m["bvh"] for m in motions}, name
    assert json.loads((CONFIGS / "own_garment_motions_v6.json").read_text()) == v6

"""The configs the README's documented runs use stay loadable as the code changes."""

from __future__ import annotations

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

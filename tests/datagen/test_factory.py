"""The factory end to end on a tiny config: plan, simulate (Newton, CPU), merge, fit."""

from __future__ import annotations

import dataclasses
import json

import numpy as np
import pytest

from cloth_usd.cli import main
from cloth_usd.datagen.dataset import read_shard
from cloth_usd.datagen.factory import FactoryConfig, load_config, plan_jobs
from cloth_usd.errors import ArgumentError

TINY = {  # two training shirts x two training bodies (the fit needs 4 pairs), one test of each
    "shirts": 3, "test_shirts": [2], "bodies": ["short_thin", "tall_fat", "medium_regular"],
    "test_bodies": ["medium_regular"], "garment_vertices": 400, "max_frames": 2,
    "train_motions": [{"kind": "walk", "seconds": 1.0, "seed": 0}],
    "test_motions": [{"kind": "dance", "seconds": 1.0, "seed": 5}],
    "sim": {"substeps": 2, "iterations": 2, "collider_faces": 2000, "drape_frames": 1},
}


def test_default_plan_has_the_papers_training_pairs():
    config = FactoryConfig()
    train_shirts = config.shirts - len(config.test_shirts)
    train_bodies = len(config.bodies) - len(config.test_bodies)
    assert (train_shirts, train_bodies, len(config.bodies)) == (6, 8, 11)


def test_train_poses_are_each_training_motion_once_and_make_no_garment(monkeypatch):
    from cloth_usd.datagen import factory
    from cloth_usd.datagen.motion import MotionSpec, generate

    def no_garments(*args, **kwargs):
        raise AssertionError("train_poses made a garment")

    monkeypatch.setattr(factory, "make_tshirt", no_garments)
    motions = [{"kind": "walk", "seconds": 1.0, "seed": 0}, {"kind": "arm_raise", "seconds": 0.5, "seed": 3}]
    poses = factory.train_poses(FactoryConfig(**{**TINY, "max_frames": 0, "train_motions": motions}))
    np.testing.assert_array_equal(poses, np.concatenate([generate(MotionSpec(**m))[0] for m in motions]))
    assert factory.train_poses(FactoryConfig(**TINY)).shape == (2, 72)  # cut as the config cuts every motion
    with pytest.raises(ArgumentError, match="train_motions: the config lists no training motion"):
        factory.train_poses(FactoryConfig(**{**TINY, "train_motions": []}))


def test_train_betas_are_the_training_bodies():
    from cloth_usd.datagen.bodies import body_shapes
    from cloth_usd.datagen.factory import train_betas

    betas = train_betas(FactoryConfig(**TINY))  # medium_regular is the test body
    np.testing.assert_array_equal(betas, np.stack([s.betas for s in body_shapes(["short_thin", "tall_fat"])]))


def test_config_errors_name_the_file_and_key(tmp_path):
    bad = tmp_path / "bad.json"
    bad.write_text(json.dumps({"shirtz": 3}))
    with pytest.raises(ArgumentError, match="bad.json.*shirtz"):
        load_config(bad)
    bad.write_text("{not json")
    with pytest.raises(ArgumentError, match="bad.json: not valid"):
        load_config(bad)


def test_tiny_factory_run(tmp_path):
    pytest.importorskip("newton")
    config_path = tmp_path / "tiny.json"
    config_path.write_text(json.dumps(TINY))
    jobs = plan_jobs(load_config(config_path))
    splits = {j.meta["split"] for j in jobs}
    assert {"train", "test_body", "test_garment"} <= splits
    out = tmp_path / "data"
    assert main(["datagen", str(config_path), "-o", str(out), "--workers", "1"]) == 0
    manifest = json.loads((out / "manifest.json").read_text())
    assert not list(out.glob("manifest.worker-*.json"))
    assert set(manifest["sequences"]) == {j.name for j in jobs}
    kept = [k for k, v in manifest["sequences"].items() if v["status"] == "ok"]
    assert kept and all(manifest["sequences"][k]["shard"] for k in kept)
    assert all(len(v["alpha"]) == 3 for v in manifest["sequences"].values())
    shard = read_shard(out / manifest["sequences"][kept[0]]["shard"])
    assert np.all(np.isfinite(shard.positions))
    assert (out / "fit.npz").exists()
    # Resume: a second run simulates nothing new and keeps the same shards.
    stamp = {p.name: p.stat().st_mtime_ns for p in out.glob("*.npz") if p.name != "fit.npz"}
    assert main(["datagen", str(config_path), "-o", str(out)]) == 0
    assert stamp == {p.name: p.stat().st_mtime_ns for p in out.glob("*.npz") if p.name != "fit.npz"}
    # Every pair was draped once, the labels evaluation needs are there, and a shard renders.
    assert len(list((out / "drape").glob("*.npz"))) == len({(j.meta["shirt"], j.meta["body"]) for j in jobs})
    meta = manifest["sequences"][kept[0]]["meta"]
    assert meta["body_label"] in ("thin", "regular", "fat") and meta["shirt_label"] in ("short", "regular", "long")
    png = tmp_path / "shard.png"
    assert main(["render", str(out / manifest["sequences"][kept[0]]["shard"]), "-o", str(png),
                 "--frames", "0,1"]) == 0
    assert png.stat().st_size > 1000
    assert main(["render", str(out / manifest["sequences"][kept[0]]["shard"]), "-o", str(png),
                 "--frames", "0,99"]) == 2  # out of range: one line, exit 2
    # The training code reads what the factory wrote (Newton-simulated shards, fit.npz).
    pytest.importorskip("torch")
    from cloth_usd.core.body import load_body_model
    from cloth_usd.nn.data import coarse_example, load_dataset

    data = load_dataset(out, ["train"])
    (clip, *_) = data.split("train")
    example = coarse_example(load_body_model(), clip, np.arange(2))
    assert example.features.shape[:2] == example.target.shape[:2] == (2, clip.rest_points.shape[0])
    assert np.all(np.isfinite(example.features)) and np.all(np.isfinite(example.target))


def test_an_interrupted_run_leaves_a_merged_manifest_and_resumes(tmp_path, monkeypatch):
    """Ctrl-C (or a worker dying) mid-run: the sequences done so far, the rejections and the
    fit are in manifest.json, no worker manifest is left, and the next run does only the rest."""
    from cloth_usd.datagen import factory
    from cloth_usd.datagen.dataset import DatasetConfig, run_jobs
    from cloth_usd.datagen.simulate import SimConfig
    from tests.datagen.test_dataset import FakeSim

    monkeypatch.setattr(factory, "drape_pairs", lambda jobs, out, sim, **_: (jobs, {}))
    calls = []

    def worker(args, stop_after=None):
        jobs, out_dir, sim, dataset, name, *_ = args  # then batch, penetration frames, deadline
        fake = FakeSim()
        run_jobs(jobs[:stop_after], out_dir, SimConfig(**sim), dataset=DatasetConfig(**dataset),
                 manifest_name=name, simulator=fake)
        calls.extend(fake.calls)
        if stop_after is not None:
            raise KeyboardInterrupt

    config = FactoryConfig(**{**TINY, "simulate_splits": ["test_body", "test_garment"]})
    out = tmp_path / "data"
    monkeypatch.setattr(factory, "_worker", lambda args: worker(args, stop_after=1))
    with pytest.raises(KeyboardInterrupt):
        factory.run_factory(config, out)
    manifest = json.loads((out / "manifest.json").read_text())
    assert not list(out.glob("manifest.worker-*.json")) and (out / "fit.npz").exists()
    assert len(manifest["sequences"]) == 1 == len(calls)
    (done,) = manifest["sequences"].values()
    assert done["status"] == "ok" and len(done["alpha"]) == 3

    calls.clear()
    monkeypatch.setattr(factory, "_worker", worker)
    merged = factory.run_factory(config, out)
    planned = [j for j in plan_jobs(config) if j.meta["split"] in ("test_body", "test_garment")]
    assert set(merged.sequences) == {j.name for j in planned}
    assert len(calls) == len(planned) - 1  # the interrupted run's sequence is not redone


def test_simulate_sequences_draws_part_of_the_plan(tmp_path, monkeypatch):
    """simulate_sequences simulates that many of the selected splits' sequences, drawn by the
    config's seed; the rest stay planned (named by the physics objective) but are neither
    draped nor simulated. A bad count is one line naming the key."""
    from cloth_usd.datagen import factory

    config = FactoryConfig(**{**TINY, "simulate_splits": ["train", "test_body"], "simulate_sequences": {"train": 5},
                              "train_motions": [{"kind": k, "seconds": 1.0, "seed": i}
                                                for i, k in enumerate(("walk", "run", "dance"))]})
    planned = plan_jobs(config)
    train = [j.name for j in planned if j.meta["split"] == "train"]
    test_body = [j.name for j in planned if j.meta["split"] == "test_body"]
    chosen = [j.name for j in factory._to_simulate(config, planned)]
    assert len(train) == 12 and len(set(chosen)) == 5 + len(test_body)  # the split it does not name: whole
    assert chosen == [j.name for j in planned if j.name in chosen] and set(test_body) < set(chosen)
    assert chosen == [j.name for j in factory._to_simulate(config, plan_jobs(config))]  # the same draw
    other = dataclasses.replace(config, seed=1)
    assert chosen != [j.name for j in factory._to_simulate(other, plan_jobs(other))]
    more = dataclasses.replace(config, simulate_sequences={"train": 8})  # a larger draw keeps the smaller one's
    assert set(chosen) < {j.name for j in factory._to_simulate(more, plan_jobs(more))}

    draped, simulated = [], []
    monkeypatch.setattr(factory, "drape_pairs",
                        lambda jobs, out, sim, **_: (draped.extend(jobs), (jobs, {}))[1])
    monkeypatch.setattr(factory, "_worker", lambda args: simulated.extend(args[0]))
    factory.run_factory(config, tmp_path / "data")
    assert [j.name for j in draped] == [j.name for j in simulated] == chosen

    # In batches: the validation sequences first, then the others in an order drawn by the seed.
    config = dataclasses.replace(config, simulate_splits=["train", "val"])
    simulated.clear()
    factory.run_factory(config, tmp_path / "batched", workers=1, batch=2)
    chosen = [j.name for j in factory._to_simulate(config, plan_jobs(config))]
    names = [j.name for j in simulated]
    vals = [n for n in chosen if n.startswith("val.")]
    assert sorted(names) == sorted(chosen) and vals and set(names[:len(vals)]) == set(vals) and names != chosen

    for bad in (5, {"train": 0}, {"train": 2.5}, {"train": True}, {"trian": 5}):
        with pytest.raises(ArgumentError, match="simulate_sequences"):
            plan_jobs(FactoryConfig(**{**TINY, "simulate_sequences": bad}))


def test_datagen_says_how_many_sequences_stopped_where_the_garment_left_the_body(tmp_path, monkeypatch, capsys):
    from cloth_usd.core.shards import Manifest
    from cloth_usd.datagen import factory

    config_path = tmp_path / "tiny.json"
    config_path.write_text(json.dumps(TINY))
    left = "frame 69: the garment left the body: 18.9% of the body it covers at rest is bare (more than 10%)"
    sequences = {"whole": {"status": "ok", "shard": "whole.npz", "quality": {"stable": True, "failure": ""}},
                 "part": {"status": "ok", "shard": "part.npz", "partial": {"frames": 63, "failure": left},
                          "quality": {"stable": False, "failure": left}},
                 "off": {"status": "rejected", "shard": None, "quality": {"stable": False, "failure": left}},
                 "torn": {"status": "rejected", "shard": None,
                          "quality": {"stable": False, "failure": "frame 82: edge stretch 2.03 > 2.0"}}}
    monkeypatch.setattr(factory, "run_factory", lambda config, out_dir, **kwargs: Manifest(
        config={}, dataset={}, engine={}, sequences=sequences))
    assert main(["datagen", str(config_path), "-o", str(tmp_path / "d")]) == 0
    assert ("2 sequences simulated (1 of them unstable, their first frames kept), 2 rejected as unstable; 2 of the "
            "unstable ones stopped where the garment left the body" in capsys.readouterr().out)


@pytest.mark.parametrize("failure, setting, other", [
    ("edge stretch 2.26 > 1.6", "sim.max_stretch", "sim.max_bare"),
    ("the garment left the body: 25.3% of the body it covers at rest is bare (more than 10%)", "sim.max_bare",
     "sim.max_stretch")])
def test_datagen_fails_when_every_sequence_is_rejected(tmp_path, monkeypatch, capsys, failure, setting, other):
    """A run whose every sequence went unstable made no data set: exit 2, one line naming the config,
    the first sequence's failure and the setting that decides it (the manifest stays, as the record)."""
    from cloth_usd.core.shards import Manifest
    from cloth_usd.datagen import factory

    config_path = tmp_path / "tiny.json"
    config_path.write_text(json.dumps(TINY))
    rejected = {f"job{k}": {"status": "rejected", "shard": None, "seed": k,
                            "quality": {"stable": False, "failure": f"frame {59 + k}: {failure}"}}
                for k in range(2)}

    def all_rejected(config, out_dir, **kwargs):
        return Manifest(config={}, dataset={}, engine={}, sequences=rejected)

    monkeypatch.setattr(factory, "run_factory", all_rejected)
    assert main(["datagen", str(config_path), "-o", str(tmp_path / "d")]) == 2
    captured = capsys.readouterr()
    assert "0 sequences simulated, 2 rejected" in captured.out
    line = captured.err.strip()
    assert "\n" not in line and "tiny.json: every sequence was rejected" in line
    assert f"job0: frame 59: {failure}" in line and setting in line and other not in line

"""The hybrid objective: the garment's energy plus a supervised term where simulated frames exist.

Every job of the tiny config is turned by :data:`YAW` about the up axis (its root rotation),
so the canonical frame the models see is not the world frame the shards are stored in: a
target left in the world frame would be tens of mm from the garment, not the stand-in
simulation's few mm of ripples.
"""

from __future__ import annotations

import dataclasses
import json

import numpy as np
import pytest

torch = pytest.importorskip("torch", reason="training needs torch (pip install 'cloth-usd[train]')")

from train_data import TINY, fake_simulate, one_thread  # noqa: E402,F401 (one_thread: an autouse fixture)

from cloth_usd.core.pipeline import CoarseBase  # noqa: E402
from cloth_usd.core.scene import Tier  # noqa: E402
from cloth_usd.errors import ArgumentError  # noqa: E402
from cloth_usd.nn.data import Split  # noqa: E402
from cloth_usd.nn.physics_train import _Tier, physics_set, train_physics  # noqa: E402
from cloth_usd.nn.train import Objective, TrainConfig, _Tensors, load_run  # noqa: E402

pytestmark = pytest.mark.slow
#: The turn given to every planned job [deg].
YAW = 30.0
PHYSICS = TrainConfig(objective="physics", coarse_base="skinned", width=0.0625, epochs=2, batch=3, max_batches=2,
                      stat_frames=3, val_frames=3, max_frames=3, bending_scale=10.0, lr=2e-3)
#: The sequences simulated into the sim-data folder (and the one marked rejected there).
SIMULATED = ("train.shirt0.short_thin.walk-s0", "train.shirt0.tall_fat.walk-s0", "train.shirt1.short_thin.walk-s0",
             "val.shirt0.tall_fat.dance-s5")
REJECTED = "train.shirt1.tall_fat.walk-s0"


def _turned(plan_jobs):
    """``plan_jobs`` with every job's root turned by :data:`YAW` about +Y."""
    from scipy.spatial.transform import Rotation

    def plan(config, body=None):
        turn = Rotation.from_euler("y", YAW, degrees=True)
        jobs = []
        for job in plan_jobs(config, body):
            poses = np.array(job.poses, dtype=np.float64)
            poses[:, :3] = (turn * Rotation.from_rotvec(poses[:, :3])).as_rotvec()
            jobs.append(dataclasses.replace(job, poses=poses))
        return jobs

    return plan


@pytest.fixture(scope="module", autouse=True)
def turned():
    from cloth_usd.datagen import factory

    with pytest.MonkeyPatch.context() as mp:
        mp.setattr(factory, "plan_jobs", _turned(factory.plan_jobs))
        yield


@pytest.fixture(scope="module")
def config_path(tmp_path_factory):
    path = tmp_path_factory.mktemp("hybrid") / "tiny.json"
    path.write_text(json.dumps(TINY))
    return path


@pytest.fixture(scope="module")
def sim_data(config_path):
    """A datagen folder of the config (the stand-in simulator): some training and validation
    sequences simulated, one of them rejected in the manifest, the rest never simulated."""
    from cloth_usd.core.shards import Manifest
    from cloth_usd.datagen import dataset, factory
    from cloth_usd.datagen.simulate import SimConfig

    out = config_path.parent / "sim"
    config = factory.load_config(config_path)
    jobs = [j for j in factory.plan_jobs(config) if j.name in (*SIMULATED, REJECTED)]
    assert len(jobs) == len(SIMULATED) + 1
    with pytest.MonkeyPatch.context() as mp:
        mp.setattr(dataset, "engine_versions", lambda: {"simulator": "tests/nn/train_data.py:fake_simulate"})
        dataset.run_jobs(jobs, out, SimConfig(**config.sim), simulator=fake_simulate)
    manifest = Manifest.read(out)
    manifest.sequences[REJECTED]["status"] = "rejected"
    manifest.write(out)
    return out


@pytest.fixture(scope="module")
def runs(config_path, sim_data, tmp_path_factory):
    """A physics run and hybrid runs of weight 0 and of a weight that dwarfs the energy."""
    base = tmp_path_factory.mktemp("hybrid-runs")
    out = {"physics": train_physics(config_path, base / "physics", PHYSICS, device="cpu")}
    for name, weight in (("zero", 0.0), ("large", 1.0e6)):
        config = dataclasses.replace(PHYSICS, objective=Objective.HYBRID, supervised_weight=weight)
        out[name] = train_physics(config_path, base / name, config, device="cpu", sim_data=sim_data)
    return out


def test_the_target_is_the_simulation_in_the_frame_the_models_see(config_path, sim_data):
    """The stand-in simulation is the skinned garment plus ripples of at most 5 mm: turned into
    the canonical frame with the poses, the target lies within them of the model's base."""
    from cloth_usd.core.body import load_body_model

    data = physics_set(config_path, splits=(Split.TRAIN, Split.VAL), max_frames=3, sim_data=sim_data)
    with_target = sorted(c.name for c in data.clips if c.target is not None)
    assert with_target == sorted(SIMULATED)  # the rejected and the unsimulated ones train on the energy alone
    step = _Tier(Tier.COARSE, load_body_model(), CoarseBase.SKINNED, _Tensors(torch.device("cpu")))
    for clip in data.clips:
        if clip.target is None:
            continue
        assert clip.target.shape == (3, clip.pair.num_vertices, 3)
        base = step.inputs(clip, np.arange(3)).base
        gap = np.linalg.norm(clip.target - base, axis=-1)
        assert gap.max() < 6e-3, (clip.name, gap.max())


def test_weight_zero_is_the_physics_objective(runs):
    physics, zero = runs["physics"].history, runs["zero"].history
    np.testing.assert_allclose([r.train_loss for r in zero], [r.train_loss for r in physics], rtol=1e-12)
    np.testing.assert_allclose([r.val_loss for r in zero], [r.val_loss for r in physics], rtol=1e-12)


def test_a_large_weight_brings_the_garment_to_the_simulation(runs):
    """val_mm of a hybrid run is the distance to the simulated target; weight 0 measures it for
    the physics objective's model."""
    zero, large = runs["zero"].history, runs["large"].history
    assert all(np.isfinite(r.val_mm) for r in zero + large)
    assert large[-1].val_mm < zero[-1].val_mm, (large[-1].val_mm, zero[-1].val_mm)
    assert large[-1].val_mm < large[0].val_mm, [r.val_mm for r in large]


def test_run_json_records_the_objective_the_weight_and_the_simulated_clips(runs, sim_data):
    run = load_run(runs["large"].run_dir)
    assert run.config.objective is Objective.HYBRID and run.config.supervised_weight == 1.0e6
    assert run.info["data"]["kind"] == "hybrid"
    hybrid = run.info["hybrid"]
    assert hybrid["sim_data"] == str(sim_data.resolve()) and hybrid["supervised_weight"] == 1.0e6
    assert hybrid["train_sequences_simulated"] == 3 and hybrid["val_sequences_simulated"] == 1
    assert hybrid["target"] == "coarse target (stored)"
    header = (runs["large"].run_dir / "val_terms.csv").read_text().splitlines()[0].split(",")
    assert header[-2:] == ["supervised", "sim_mm"]
    assert "hybrid" not in load_run(runs["physics"].run_dir).info


def test_a_hybrid_run_exports_a_bundle(runs, config_path, tmp_path):
    from cloth_usd.nn.export import export_bundle
    from cloth_usd.runtime.bundle import load_bundle

    out = export_bundle(runs["large"].run_dir, None, config_path, tmp_path / "bundle", name="hybrid-test")
    bundle = load_bundle(out)
    assert bundle.manifest["metrics"]["export_parity"]["coarse_max_m"] < 1e-4
    assert bundle.manifest["training_data"]["sim_manifest_sha256"] == {
        "coarse": load_run(runs["large"].run_dir).info["hybrid"]["sim_manifest_sha256"]}


def test_sim_data_of_another_config_is_refused_in_one_line(config_path, sim_data, tmp_path, capsys):
    from cloth_usd.cli import main

    other = tmp_path / "other.json"  # the same sequence names, one frame shorter
    other.write_text(json.dumps({**TINY, "max_frames": TINY["max_frames"] - 1}))
    train = tmp_path / "train.json"
    train.write_text(json.dumps({**PHYSICS.to_json(), "objective": "hybrid", "supervised_weight": 10.0}))
    args = ["train", "coarse", "--config", str(train), "--device", "cpu", "-o", str(tmp_path / "run")]
    assert main([*args, "--data", str(other), "--sim-data", str(sim_data)]) == 2
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1 and f"--sim-data {sim_data}" in err and "another config" in err, err
    assert main([*args, "--data", str(config_path)]) == 2  # hybrid without --sim-data
    assert "--sim-data" in capsys.readouterr().err
    assert not (tmp_path / "run" / "run.json").exists()
    with pytest.raises(ArgumentError, match="--sim-data"):
        train_physics(config_path, tmp_path / "run", PHYSICS, device="cpu", sim_data=sim_data)


def test_a_kept_part_of_an_unstable_sequence_is_the_target_of_its_first_frames(config_path, sim_data, tmp_path):
    """A shard of a sequence's first frames (``SimConfig.keep_partial``) is that sequence's target
    there, in the frame the models see as the whole one is; the supervised term is 0 past it."""
    import shutil

    from cloth_usd.core.shards import Manifest, read_shard, write_shard
    from cloth_usd.nn.physics_train import _spring, _supervised

    part = tmp_path / "part"
    shutil.copytree(sim_data, part)
    name = SIMULATED[0]
    shard = read_shard(part / f"{name}.npz")
    write_shard(part / f"{name}.npz", dataclasses.replace(
        shard, **{k: getattr(shard, k)[:2] for k in ("positions", "coarse", "poses", "transl", "penetration",
                                                     "max_stretch")}))
    manifest = Manifest.read(part)
    manifest.sequences[name]["partial"] = {"frames": 2, "frames_requested": shard.poses.shape[0], "failure": "test"}
    manifest.write(part)
    whole = {c.name: c for c in physics_set(config_path, splits=(Split.TRAIN,), max_frames=3,
                                            sim_data=sim_data).clips}
    cut = {c.name: c for c in physics_set(config_path, splits=(Split.TRAIN,), max_frames=3, sim_data=part).clips}
    assert cut[name].target.shape[0] == 2 and whole[name].target.shape[0] == 3
    np.testing.assert_allclose(cut[name].target, whole[name].target[:2], atol=1e-6)
    x = torch.from_numpy(whole[name].target[[0, 1, 2]]).double() + 0.01
    term = _supervised(cut[name], x, np.array([0, 1, 2]), 10.0)
    full = _spring(cut[name], x, torch.from_numpy(whole[name].target), 10.0)
    assert float(term[2]) == 0.0 and float(full[2]) > 0.0
    torch.testing.assert_close(term[:2], full[:2], rtol=1e-5, atol=0.0)
    assert _supervised(cut[name], x[2:], np.array([2]), 10.0) is None

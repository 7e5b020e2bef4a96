"""Real motion capture as data set motions: retargeted, facing +Z, eased in, warm-up recorded."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from cloth_usd.core.heading import root_yaw
from cloth_usd.datagen.factory import MOCAP_ENV, load_config, plan_jobs
from cloth_usd.datagen.mocap import MocapSpec, mocap_motion
from cloth_usd.errors import ArgumentError, MotionFileError

MOCAP = Path(__file__).resolve().parents[1] / "data" / "mocap"
WALK = "cmu_mb_02_01_walk.bvh"  # 29 captured frames at 30 fps after the converter's T-pose


def _angles(poses: np.ndarray) -> np.ndarray:
    """(T-1, 24) the rotation between consecutive frames per joint [rad]."""
    r = Rotation.from_rotvec(poses.reshape(-1, 3)).as_matrix().reshape(len(poses), 24, 3, 3)
    rel = np.einsum("tjba,tjbc->tjac", r[:-1], r[1:])
    return np.arccos(np.clip((np.trace(rel, axis1=-2, axis2=-1) - 1) / 2, -1, 1))


def test_clip_eases_in_from_rest_and_faces_forward():
    spec = MocapSpec(bvh=WALK, seconds=0.8, fps=30, ease_seconds=0.5, ramp_seconds=0.2)
    m = mocap_motion(spec, MOCAP)
    ease, ramp, clip = 15, 6, 24
    assert m.poses.shape == (ease + clip, 72) and m.transl.shape == (ease + clip, 3)
    assert m.warmup_frames == ease + ramp
    np.testing.assert_array_equal(m.poses[0], 0.0)  # the rest pose: the drape's
    np.testing.assert_array_equal(m.transl[:ease + 1], 0.0)
    assert abs(root_yaw(m.poses[ease:ease + 1])[0]) < 1e-9  # the clip starts facing +Z
    # No jump: the ease and its step into the clip turn no joint faster than the clip itself does.
    angles = _angles(m.poses)
    assert angles[:ease + 1].max() < min(np.deg2rad(12), angles[ease + 1:].max())
    # The root accelerates over the ramp: its first step is a fraction of its steps after it.
    steps = np.linalg.norm(np.diff(m.transl[ease:], axis=0), axis=1)
    assert steps[0] < 0.25 * steps[ramp:].mean()
    assert m.source["bvh"] == WALK and len(m.source["sha256"]) == 64 and m.source["rig"] == "cmu-mb"


def test_clip_is_the_files_motion_after_the_warm_up():
    """After the ease, the poses are the retargeted file's own (up to the heading turn)."""
    from cloth_usd.datagen.bvh import read_bvh, retarget_bvh, rig_mapping, trim_bvh

    spec = MocapSpec(bvh=WALK, start_seconds=0.1, seconds=0.5, fps=30, ease_seconds=0.2, ramp_seconds=0.0)
    m = mocap_motion(spec, MOCAP)
    bvh = read_bvh(MOCAP / WALK)
    _, mapping = rig_mapping(bvh, None)
    poses, root = retarget_bvh(trim_bvh(bvh, 1 + 3, 1 + 3 + 15), mapping=mapping, fps=30, up_axis=None,
                               blend_seconds=0.0)
    np.testing.assert_allclose(m.poses[6:, 3:], poses[:15, 3:], atol=1e-9)  # joints below the root
    turn = Rotation.from_rotvec([0, -root_yaw(poses[:1])[0], 0])
    np.testing.assert_allclose(m.transl[6:], turn.apply(root[:15] - root[:1]), atol=1e-9)


def test_spec_errors_name_the_field_and_file(tmp_path):
    with pytest.raises(ArgumentError, match="ease_seconds"):
        MocapSpec(bvh=WALK, ease_seconds=0)
    with pytest.raises(ArgumentError, match="ramp_seconds"):
        MocapSpec(bvh=WALK, seconds=0.5, ramp_seconds=1.0)
    with pytest.raises(MotionFileError, match="no_such.bvh"):
        mocap_motion(MocapSpec(bvh="no_such.bvh"), MOCAP)
    with pytest.raises(MotionFileError, match=f"{WALK}.*past the end"):
        mocap_motion(MocapSpec(bvh=WALK, seconds=4.0), MOCAP)


def _config(tmp_path, **extra) -> Path:
    raw = {"shirts": 3, "test_shirts": [2], "bodies": ["short_thin", "tall_fat", "medium_regular"],
           "test_bodies": ["medium_regular"], "garment_vertices": 400,
           "train_motions": [{"kind": "walk", "seconds": 0.5, "fps": 30, "seed": 0}],
           "test_motions": [{"bvh": WALK, "seconds": 0.6, "ease_seconds": 0.3, "ramp_seconds": 0.1}],
           "sim": {"fps": 30}, **extra}
    path = tmp_path / "mocap.json"
    path.write_text(json.dumps(raw))
    return path


def test_factory_plans_mocap_motions_with_their_warm_up(tmp_path, monkeypatch):
    monkeypatch.delenv(MOCAP_ENV, raising=False)
    path = _config(tmp_path)
    with pytest.raises(ArgumentError, match=r"test_motions\[0\].*--mocap"):
        plan_jobs(load_config(path))
    jobs = plan_jobs(load_config(path, mocap_dir=MOCAP))
    real = [j for j in jobs if "mocap" in j.meta["motion"]]
    assert real and {j.meta["split"] for j in real} >= {"test_motion", "test_body", "test_garment"}
    assert all(j.meta["warmup_frames"] == 9 + 3 and j.poses.shape == (27, 72) for j in real)
    assert all(j.meta["motion_source"]["bvh"] == WALK for j in real)
    assert not any("warmup_frames" in j.meta for j in jobs if j not in real)
    monkeypatch.setenv(MOCAP_ENV, str(MOCAP))  # the environment names the folder too
    assert [j.name for j in plan_jobs(load_config(path))] == [j.name for j in jobs]


def test_factory_refuses_a_motion_at_another_rate_than_the_simulation(tmp_path):
    path = _config(tmp_path, sim={"fps": 24})
    with pytest.raises(ArgumentError, match=r"train_motions\[0\].*30 fps.*simulation at 24"):
        plan_jobs(load_config(path, mocap_dir=MOCAP))


def test_a_stretch_whose_body_jumps_is_refused_when_planned(tmp_path):
    """A capture glitch (a limb moving farther in a frame than a body can) is named, not simulated."""
    walk = {"bvh": WALK, "seconds": 0.6, "ease_seconds": 0.3, "ramp_seconds": 0.1}
    plan_jobs(load_config(_config(tmp_path), mocap_dir=MOCAP))  # a walk moves about 3 m/s at most
    path = _config(tmp_path, test_motions=[{**walk, "max_body_speed": 0.5}])
    with pytest.raises(ArgumentError, match=rf"test_motions\[0\] \({WALK} from 0 s\): the body moves [0-9.]+ m/s "
                                            r"between frames \d+ and \d+, past max_body_speed 0.5"):
        plan_jobs(load_config(path, mocap_dir=MOCAP))


def test_simulate_splits_are_checked(tmp_path):
    with pytest.raises(ArgumentError, match="simulate_splits.*test_motions"):
        plan_jobs(load_config(_config(tmp_path, simulate_splits=["test_motions"]), mocap_dir=MOCAP))


def test_a_test_set_of_real_clips_leaves_the_warm_up_out(tmp_path, monkeypatch):
    """simulate_splits simulates and drapes only the test sequences (the fit is fitted on the
    planned training pairs), and loading the data set drops each sequence's warm-up frames."""
    import sys
    from functools import partial

    sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "nn"))
    from train_data import fake_simulate

    from cloth_usd.core.shards import read_shard
    from cloth_usd.datagen import dataset, factory
    from cloth_usd.nn.data import load_dataset

    path = _config(tmp_path, simulate_splits=["test_motion"])
    monkeypatch.setattr(factory, "run_jobs", partial(dataset.run_jobs, simulator=fake_simulate))
    monkeypatch.setattr(dataset, "engine_versions", lambda: {"simulator": "fake_simulate"})
    asked: list[str] = []
    monkeypatch.setattr(factory, "drape_pairs", lambda jobs, *args, **kwargs: (
        asked.extend(j.meta["split"] for j in jobs) or list(jobs), {}))
    out = tmp_path / "data"
    manifest = factory.run_factory(load_config(path, mocap_dir=MOCAP), out)
    assert manifest.accepted and {e["split"] for e in manifest.sequences.values()} == {"test_motion"}
    assert set(asked) == {"test_motion"}  # nothing else is draped
    assert (out / "fit.npz").is_file()  # fitted on the training pairs, which were never simulated
    data = load_dataset(out)
    for clip in data.clips:
        shard = read_shard(out / manifest.sequences[clip.name]["shard"])
        w = clip.meta["warmup_frames"]
        assert clip.positions.shape[0] == shard.positions.shape[0] - w
        np.testing.assert_array_equal(clip.positions, shard.positions[w:])
        np.testing.assert_array_equal(clip.poses, shard.poses[w:])
    short = load_dataset(out, max_frames=2)  # max_frames counts after the warm-up
    assert all(c.positions.shape[0] == 2 for c in short.clips)


def test_floor_jobs_hold_a_pose_and_are_measured(tmp_path, monkeypatch):
    """A held-pose job repeats frame k's pose; floor_report measures moving against settled."""
    import sys
    from functools import partial

    sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "nn"))
    from train_data import fake_simulate

    from cloth_usd.datagen import dataset, factory
    from cloth_usd.datagen.floor import FloorSpec, floor_report
    from cloth_usd.nn.data import load_dataset

    with pytest.raises(ArgumentError, match="floor: unknown keys.*hold"):
        FloorSpec.from_mapping({"hold": 1})
    path = _config(tmp_path, simulate_splits=["test_motion"], floor={"sequences": 1, "frames": 2, "hold_seconds": 0.2})
    jobs = plan_jobs(load_config(path, mocap_dir=MOCAP))
    held = [j for j in jobs if j.meta["split"] == "floor"]
    assert len(held) == 2
    source = next(j for j in jobs if j.name == held[0].meta["floor_of"])
    k, hold = held[0].meta["frame"], held[0].meta["hold_frames"]
    assert source.meta["split"] == "test_motion" and k >= source.meta["warmup_frames"] and hold == 6
    np.testing.assert_array_equal(held[0].poses[:k + 1], source.poses[:k + 1])
    np.testing.assert_array_equal(held[0].poses[k:], np.repeat(source.poses[k:k + 1], hold + 1, axis=0))
    monkeypatch.setattr(factory, "run_jobs", partial(dataset.run_jobs, simulator=fake_simulate))
    monkeypatch.setattr(dataset, "engine_versions", lambda: {"simulator": "fake_simulate"})
    monkeypatch.setattr(factory, "drape_pairs", lambda jobs, *args, **kwargs: (list(jobs), {}))
    out = tmp_path / "data"
    factory.run_factory(load_config(path, mocap_dir=MOCAP), out)
    report = floor_report(out)
    # The stand-in simulator is per-frame (skinning plus pose ripples): it has no dynamics, so
    # the moving garment is the settled one and the floor is zero.
    assert len(report["frames"]) == 2 and report["mean_mm"] < 1e-3
    assert all(r["settle_mm"] < 1e-3 for r in report["frames"])
    assert all(c.split.value == "test_motion" for c in load_dataset(out).clips)  # held poses are not loaded


def test_stored_stretches_are_the_clips_as_a_config_reads_them(tmp_path):
    """store_motions keeps each stretch as mocap_motion makes it (float32), with its name, warm-up and source."""
    from cloth_usd.datagen.mocap import store_motions, stored_motion, stored_motion_names

    specs = [{"bvh": WALK, "seconds": 0.6, "ease_seconds": 0.3, "ramp_seconds": 0.1},
             {"bvh": "cmu_daz_12_01_walk.bvh", "start_seconds": 0.1, "seconds": 0.5, "name": "daz"}]
    out = tmp_path / "stored.npz"
    names = store_motions(specs, MOCAP, out)
    assert names == [MocapSpec(**specs[0]).label, "daz"] and stored_motion_names(out) == tuple(names)
    for name, fields in zip(names, specs):
        made = mocap_motion(MocapSpec(**fields), MOCAP)
        stored, fps = stored_motion(name, out)
        assert fps == 30.0 and stored.warmup_frames == made.warmup_frames
        np.testing.assert_allclose(stored.poses, made.poses, atol=1e-6)
        np.testing.assert_allclose(stored.transl, made.transl, atol=1e-6)
        assert stored.poses.dtype == np.float64
        assert stored.source["stored"] == name and stored.source["sha256"] == made.source["sha256"]
    with pytest.raises(ArgumentError, match=rf"no stored motion 'walk'; {out} holds 2: "):
        stored_motion("walk", out)
    with pytest.raises(ArgumentError, match="motion 1: the name 'daz' is taken"):
        store_motions([specs[1], specs[1]], MOCAP, tmp_path / "twice.npz")


def test_the_shipped_stretches_are_real_motion_held_apart_from_the_test_clips():
    """The package's stretches: the list the sample garments' own bundles train on, eased in from
    rest at 30 fps, and none of the clips the bundles' reports hold out."""
    from cloth_usd.datagen.mocap import stored_motion, stored_motion_names

    root = Path(__file__).resolve().parents[2]
    listed = json.loads((root / "configs" / "own_garment_motions_v6.json").read_text())
    names = stored_motion_names()
    assert names == tuple(MocapSpec(**m).label for m in listed)
    tests = json.loads((root / "configs" / "own_garment_test_motions.json").read_text())
    held_out = {Path(m["bvh"]).stem for m in tests}
    held_out |= {"05_02", "01_01", "02_03", "09_12"}  # and the dances: salsa 10 and 25, martial arts 04
    for name in names:
        m, fps = stored_motion(name)
        clip = m.source["bvh"]
        assert Path(clip).stem not in held_out and not any(clip.endswith(d) for d in
                                                          ("salsa/10.bvh", "salsa/25.bvh", "martial/04.bvh"))
        assert fps == 30.0 and m.poses.shape == (len(m.transl), 72) and 0 < m.warmup_frames < len(m.poses) - 20
        np.testing.assert_array_equal(m.poses[0], 0.0)
        assert np.abs(m.poses).max() > 0.5  # it moves


def test_the_shipped_test_stretches_are_the_test_list_and_apart_from_training():
    """The three stretches train-garment's test set holds out: configs/own_garment_test_motions.json,
    found by name without a file named, and no clip of theirs among the training stretches'."""
    from cloth_usd.core.files import models_dir
    from cloth_usd.datagen.mocap import STORED_TEST_MOTIONS, stored_motion, stored_motion_names

    root = Path(__file__).resolve().parents[2]
    listed = json.loads((root / "configs" / "own_garment_test_motions.json").read_text())
    names = stored_motion_names(models_dir() / STORED_TEST_MOTIONS)
    assert names == tuple(MocapSpec(**m).label for m in listed)
    trained = {stored_motion(n)[0].source["bvh"] for n in stored_motion_names()}
    for name in names:
        m, fps = stored_motion(name)
        assert m.source["bvh"] not in trained and fps == 30.0 and np.abs(m.poses).max() > 0.5
    with pytest.raises(ArgumentError, match=r"no stored motion 'nope'; .*cmu_stretches.npz holds 24: .*; "
                                            r".*cmu_test_stretches.npz holds 3: mocap-0502-t1"):
        stored_motion("nope")


def test_factory_plans_stored_motions_without_a_mocap_folder(tmp_path, monkeypatch):
    from cloth_usd.datagen.mocap import stored_motion, stored_motion_names

    monkeypatch.delenv(MOCAP_ENV, raising=False)
    name = stored_motion_names()[0]
    path = _config(tmp_path, test_motions=[{"stored": name}], max_frames=60)
    real = [j for j in plan_jobs(load_config(path)) if j.meta["motion"] == name]
    m, _ = stored_motion(name)
    assert real and {j.meta["split"] for j in real} >= {"test_motion", "test_body"}
    assert all(j.meta["warmup_frames"] == m.warmup_frames and j.poses.shape == (60, 72) for j in real)
    np.testing.assert_array_equal(real[0].poses, m.poses[:60])
    assert real[0].meta["motion_source"]["stored"] == name
    with pytest.raises(ArgumentError, match=r"test_motions\[0\]: a stored motion takes no other field.*seconds"):
        plan_jobs(load_config(_config(tmp_path, test_motions=[{"stored": name, "seconds": 2}])))

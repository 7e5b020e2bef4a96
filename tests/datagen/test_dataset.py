"""Dataset shards: round trip, resume, rejection, Laplacian coarse target (no simulator needed)."""

from __future__ import annotations

import json

import numpy as np
import pytest

from cloth_usd.core.body import load_body_model
from cloth_usd.datagen.dataset import (DatasetConfig, DatasetError, Job, Manifest, fit_inputs, laplacian_smooth,
                                       read_shard, run_jobs, write_shard)
from cloth_usd.datagen.simulate import SimConfig, SimResult


def _grid(n: int = 8):
    """(n*n, 3) bumpy grid and its triangles."""
    xs, ys = np.meshgrid(np.linspace(0, 1, n), np.linspace(0, 1, n), indexing="ij")
    z = 0.05 * np.sin(9 * xs) * np.cos(7 * ys)
    v = np.stack([xs, ys, z], axis=-1).reshape(-1, 3)
    idx = np.arange(n * n).reshape(n, n)
    a, b, c, d = idx[:-1, :-1].ravel(), idx[1:, :-1].ravel(), idx[:-1, 1:].ravel(), idx[1:, 1:].ravel()
    return v, np.concatenate([np.stack([a, b, d], 1), np.stack([a, d, c], 1)])


def _lap_norm(pos, faces):
    n = pos.shape[-2]
    nb = [[] for _ in range(n)]
    for f in faces:
        for i in range(3):
            nb[f[i]] += [f[(i + 1) % 3], f[(i + 2) % 3]]
    mean = np.stack([pos[..., sorted(set(nb[i])), :].mean(axis=-2) for i in range(n)], axis=-2)
    return np.linalg.norm(mean - pos, axis=-1).mean()


def test_laplacian_coarse_target_is_smoother_and_same_shape():
    v, f = _grid()
    pos = np.stack([v, v + 0.01]).astype(np.float32)
    out = laplacian_smooth(pos, f, iterations=5)
    assert out.shape == pos.shape and out.dtype == np.float32
    assert _lap_norm(out, f) < 0.5 * _lap_norm(pos, f)
    np.testing.assert_allclose(laplacian_smooth(pos, f, iterations=0), pos)
    np.testing.assert_allclose(laplacian_smooth(pos[1], f, iterations=5), out[1], atol=1e-6)  # per frame


def test_taubin_coarse_target_keeps_the_size_laplacian_shrinks():
    """mu < 0: the same smoothing without the shrinkage (a sphere keeps its radius)."""
    import trimesh

    sphere = trimesh.creation.icosphere(subdivisions=3, radius=0.2)
    rng = np.random.default_rng(0)
    pos = (sphere.vertices + rng.normal(0, 0.002, sphere.vertices.shape))[None]
    f = np.asarray(sphere.faces)
    radius = lambda x: np.linalg.norm(x[0], axis=1).mean()  # noqa: E731
    plain = laplacian_smooth(pos, f, iterations=10)
    taubin = laplacian_smooth(pos, f, iterations=10, mu=-0.53)
    assert radius(plain) < 0.99 * radius(pos)
    assert abs(radius(taubin) - radius(pos)) < 0.1 * abs(radius(plain) - radius(pos))
    noise = lambda x: np.linalg.norm(x[0] - sphere.vertices, axis=1).mean()  # noqa: E731
    assert noise(taubin) < 0.7 * noise(pos) < noise(plain)  # the bumps smoothed, the sphere kept
    np.testing.assert_array_equal(laplacian_smooth(pos, f, iterations=10, mu=0.0), plain)


class FakeSim:
    """Stands in for the simulator: the rest garment, dropping 1 mm a frame; counts calls."""

    def __init__(self, unstable=()):
        self.calls, self.unstable = [], set(unstable)

    def __call__(self, body, betas, verts, faces, poses, transl, config):
        self.calls.append(verts.shape[0])
        t = poses.shape[0]
        pos = (verts[None] + transl[:, None] - np.arange(t)[:, None, None] * [0, 1e-3, 0]).astype(np.float32)
        bad = verts.shape[0] in self.unstable
        done = 2 if bad else t
        stable = np.ones(done, bool)
        if bad:
            stable[-1] = False
        return SimResult(positions=pos[:done], nan=np.zeros(done, bool), penetration=np.zeros(done),
                         max_stretch=np.ones(done), max_speed=np.zeros(done), bare=np.zeros(done), stable=stable,
                         frames_requested=t, failure="frame 1: NaN/Inf positions" if bad else "",
                         device="cpu", seconds_per_frame=0.0)


@pytest.fixture(scope="module")
def body():
    return load_body_model()


def _jobs(body):
    from cloth_usd.core.body import shape_body

    v_shaped, _ = shape_body(body, np.zeros(10))
    out = []
    for k, n in enumerate((40, 50, 60)):
        verts = v_shaped[: n] * 1.01
        faces = np.stack([np.arange(n - 2), np.arange(1, n - 1), np.arange(2, n)], axis=1)
        out.append(Job(name=f"job{k}", garment_vertices=verts, garment_faces=faces, betas=np.zeros(10),
                       poses=np.zeros((4, 72)), transl=np.zeros((4, 3)), seed=k, meta={"n": n}))
    return out


def test_run_jobs_round_trip_reject_and_resume(tmp_path, body):
    jobs, sim = _jobs(body), FakeSim(unstable={50})
    cfg = SimConfig(substeps=2)
    manifest = run_jobs(jobs, tmp_path, cfg, body=body, simulator=sim)
    assert sim.calls == [40, 50, 60]
    assert manifest.accepted == ["job0", "job2"] and manifest.rejected == ["job1"]
    assert not (tmp_path / "job1.npz").exists()  # rejected: listed, never written
    raw = json.loads((tmp_path / "manifest.json").read_text())
    assert raw["rejected"] == ["job1"] and raw["config"]["substeps"] == 2
    assert set(raw["engine"]) == {"newton", "warp"}
    assert raw["sequences"]["job0"]["seed"] == 0
    assert raw["sequences"]["job1"]["quality"]["failure"].startswith("frame 1")

    shard = read_shard(tmp_path / "job0.npz")
    assert shard.positions.shape == (4, 40, 3) and shard.positions.dtype == np.float32
    assert shard.coarse.shape == shard.positions.shape
    np.testing.assert_allclose(shard.garment_vertices, jobs[0].garment_vertices, atol=1e-6)
    assoc, fit, surf = fit_inputs(body, np.zeros(10), jobs[0].garment_vertices)
    np.testing.assert_array_equal(shard.assoc_vertex, assoc)
    np.testing.assert_allclose(shard.fit_distance, fit, atol=1e-6)
    assert np.all(surf <= fit + 1e-9)  # the surface is never farther than a vertex on it
    assert shard.meta["seed"] == 0 and shard.meta["quality"]["stable"] is True

    again = FakeSim(unstable={50})
    run_jobs(jobs, tmp_path, cfg, body=body, simulator=again)
    assert again.calls == []  # everything valid or known-rejected: nothing re-simulated

    (tmp_path / "job2.npz").write_bytes(b"truncated")  # a corrupt shard is redone
    third = FakeSim()
    run_jobs(jobs, tmp_path, cfg, body=body, simulator=third)
    assert third.calls == [60]
    changed = FakeSim()
    run_jobs(jobs[:1], tmp_path, SimConfig(substeps=3), body=body, simulator=changed)
    assert changed.calls == [40]  # a new config invalidates the shard


def test_write_shard_is_atomic_and_read_rejects_junk(tmp_path, body):
    sim = FakeSim()
    run_jobs(_jobs(body)[:1], tmp_path, SimConfig(), body=body, simulator=sim)
    shard = read_shard(tmp_path / "job0.npz")
    write_shard(tmp_path / "copy.npz", shard)
    assert sorted(p.name for p in tmp_path.iterdir()) == ["copy.npz", "job0.npz", "manifest.json"]
    assert read_shard(tmp_path / "copy.npz").digest == shard.digest
    np.savez(tmp_path / "junk.npz", a=np.zeros(3))
    with pytest.raises(DatasetError, match="missing"):
        read_shard(tmp_path / "junk.npz")
    with pytest.raises(DatasetError, match="unreadable"):
        read_shard(tmp_path / "nope.npz")
    with pytest.raises(DatasetError, match="coarse_lambda"):
        DatasetConfig(coarse_lambda=0.0)
    assert Manifest.read(tmp_path).accepted == ["job0"]


def test_a_worker_skips_what_an_interrupted_run_merged(tmp_path, body):
    """Parallel workers keep their own manifests; after an interruption they are merged into
    the data set's, and a worker of the next run must still know a rejected sequence."""
    jobs, cfg = _jobs(body), SimConfig(substeps=2)
    run_jobs(jobs, tmp_path, cfg, body=body, simulator=FakeSim(unstable={50}))  # the merged manifest
    again = FakeSim(unstable={50})
    run_jobs(jobs, tmp_path, cfg, body=body, simulator=again, manifest_name="manifest.worker-0.json")
    assert again.calls == []


class FakeBatchSim:
    """Stands in for simulate_batch: each member through FakeSim; records the batches' sizes and lengths."""

    def __init__(self, unstable=()):
        self.single, self.batches, self.penetration_frames = FakeSim(unstable), [], []

    def __call__(self, body, items, config, *, penetration_frames=None):
        self.batches.append([(it.garment_verts.shape[0], it.poses.shape[0]) for it in items])
        self.penetration_frames.append(penetration_frames)
        return [self.single(body, it.betas, it.garment_verts, it.garment_faces, it.poses, it.transl, config)
                for it in items]


def test_run_jobs_in_batches_groups_equal_lengths_and_rejects_each_member(tmp_path, body):
    import dataclasses

    jobs = _jobs(body)
    longer = [dataclasses.replace(j, name=j.name + "-long", poses=np.zeros((6, 72)), transl=np.zeros((6, 3)))
              for j in jobs[:2]]
    sim = FakeBatchSim(unstable={50})
    manifest = run_jobs(jobs + longer, tmp_path, SimConfig(substeps=2), body=body, batch=2,
                        penetration_frames=3, batch_simulator=sim,
                        simulator=lambda *a: pytest.fail("batch > 1 never simulates one at a time"))
    # Two lengths, each in order, at most two a batch: no batch mixes 4- and 6-frame jobs.
    assert sim.batches == [[(40, 4), (50, 4)], [(60, 4)], [(40, 6), (50, 6)]]
    assert sim.penetration_frames == [3, 3, 3]
    assert manifest.accepted == ["job0", "job0-long", "job2"]
    assert manifest.rejected == ["job1", "job1-long"]  # an unstable member is rejected alone
    assert read_shard(tmp_path / "job0-long.npz").positions.shape == (6, 40, 3)
    again = FakeBatchSim()
    run_jobs(jobs + longer, tmp_path, SimConfig(substeps=2), body=body, batch=2, batch_simulator=again)
    assert again.batches == []  # resumable as one at a time is


def test_run_jobs_starts_nothing_after_its_deadline(tmp_path, body):
    import time

    sim = FakeBatchSim()
    manifest = run_jobs(_jobs(body), tmp_path, SimConfig(substeps=2), body=body, batch=2, batch_simulator=sim,
                        deadline=time.time() - 1.0)
    assert sim.batches == [] and manifest.accepted == [] and manifest.rejected == []
    one = FakeSim()
    run_jobs(_jobs(body), tmp_path, SimConfig(substeps=2), body=body, simulator=one, deadline=time.time() + 60.0)
    assert one.calls == [40, 50, 60]  # a deadline not yet passed changes nothing
    with pytest.raises(DatasetError, match="batch must be at least 1"):
        run_jobs(_jobs(body), tmp_path, SimConfig(), body=body, batch=0)


class LateFailSim:
    """Stands in for the simulator: the rest garment, every frame stable until ``fail_at``, where
    an edge stretches past the limit and the simulation stops (as Newton's does); counts calls."""

    def __init__(self, fail_at: int):
        self.fail_at, self.calls = fail_at, 0

    def __call__(self, body, betas, verts, faces, poses, transl, config):
        self.calls += 1
        done = min(self.fail_at + 1, poses.shape[0])
        pos = (verts[None] + np.arange(done)[:, None, None] * [0, 1e-3, 0]).astype(np.float32)
        stable = np.arange(done) < self.fail_at
        stretch = np.where(stable, 1.2, 1.7)
        return SimResult(positions=pos, nan=np.zeros(done, bool), penetration=np.zeros(done),
                         max_stretch=stretch, max_speed=np.zeros(done), bare=np.zeros(done), stable=stable,
                         frames_requested=poses.shape[0],
                         failure=f"frame {self.fail_at}: edge stretch 1.7 > 1.6", device="cpu", seconds_per_frame=0.0)


def _long_job(body, frames: int = 30):
    job = _jobs(body)[0]
    rng = np.random.default_rng(3)
    return Job(name="long", garment_vertices=job.garment_vertices, garment_faces=job.garment_faces,
               betas=np.zeros(10), poses=rng.normal(0, 0.1, (frames, 72)), transl=rng.normal(0, 0.1, (frames, 3)),
               seed=0, meta={})


def test_keep_partial_keeps_the_frames_before_an_unstable_one_and_only_those(tmp_path, body, caplog):
    """``SimConfig.keep_partial``: a sequence that goes unstable at frame 20 of 30 (24 fps) keeps
    its first 15 frames (0.2 s, 5 frames, before the failure) as a shard of those frames, where
    at least ``keep_partial`` of them follow its warm-up; the setting is left out of the digest,
    so turning it on simulates again only the sequence rejected before."""
    from cloth_usd.datagen.simulate import PARTIAL_MARGIN_SECONDS, SimulationError

    assert PARTIAL_MARGIN_SECONDS == 0.2
    job = _long_job(body)
    assert SimConfig(keep_partial=10).to_json() == SimConfig().to_json()
    assert job.digest(SimConfig(keep_partial=10), DatasetConfig()) == job.digest(SimConfig(), DatasetConfig())
    with pytest.raises(SimulationError, match="keep_partial"):
        SimConfig(keep_partial=-1)

    sim = LateFailSim(20)
    manifest = run_jobs([job], tmp_path, SimConfig(), body=body, simulator=sim)
    assert manifest.rejected == ["long"] and not (tmp_path / "long.npz").exists()
    again = LateFailSim(20)
    manifest = run_jobs([job], tmp_path, SimConfig(keep_partial=10), body=body, simulator=again)
    assert again.calls == 1  # rejected whole before: simulated again for its frames
    assert manifest.accepted == ["long"] and manifest.partial == ["long"] and manifest.rejected == []
    entry = manifest.sequences["long"]
    assert entry["partial"] == {"frames": 15, "frames_requested": 30, "failure": "frame 20: edge stretch 1.7 > 1.6"}
    assert entry["quality"]["frames_done"] == 15 and entry["quality"]["max_stretch"] == pytest.approx(1.2)
    shard = read_shard(tmp_path / "long.npz")
    assert shard.positions.shape == (15, 40, 3) and shard.coarse.shape == (15, 40, 3)
    np.testing.assert_array_equal(shard.poses, job.poses[:15])
    np.testing.assert_array_equal(shard.transl, job.transl[:15])
    assert shard.digest == job.digest(SimConfig(), DatasetConfig())
    third = LateFailSim(20)
    run_jobs([job], tmp_path, SimConfig(keep_partial=10), body=body, simulator=third)
    assert third.calls == 0  # its shard is there

    # too few frames left before the failure: rejected, and not simulated again for the same setting
    short = tmp_path / "short"
    first = LateFailSim(14)  # 9 frames before the margin
    assert run_jobs([job], short, SimConfig(keep_partial=10), body=body, simulator=first).rejected == ["long"]
    assert Manifest.read(short).sequences["long"]["keep_partial"] == 10
    same = LateFailSim(14)
    run_jobs([job], short, SimConfig(keep_partial=10), body=body, simulator=same)
    assert same.calls == 0
    fewer = LateFailSim(14)
    assert run_jobs([job], short, SimConfig(keep_partial=9), body=body, simulator=fewer).partial == ["long"]
    assert fewer.calls == 1 and read_shard(short / "long.npz").positions.shape[0] == 9

    # the frames counted are those past the motion's warm-up, which training and evaluation leave out
    import dataclasses

    warm = dataclasses.replace(job, meta={"warmup_frames": 6})
    with caplog.at_level("WARNING"):
        assert run_jobs([warm], tmp_path / "warm", SimConfig(keep_partial=10), body=body,
                        simulator=LateFailSim(20)).rejected == ["long"]  # 15 kept, 9 past the warm-up
    assert "fewer than 10 frames before it follow the 6-frame warm-up, nothing kept" in caplog.text
    assert run_jobs([warm], tmp_path / "warm5", SimConfig(keep_partial=9), body=body,
                    simulator=LateFailSim(20)).partial == ["long"]

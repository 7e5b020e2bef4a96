"""A tiny factory data set for the training and evaluation tests, built once per session.

The factory runs for real (plan, shards, manifest merge, fit attribute) on the tiny config
of ``tests/datagen/test_factory.py``, except that the Newton simulation is replaced by a
fast stand-in: the skinning tier plus pose-dependent ripples along the garment normal
(a few mm), so the learned tiers have something to learn beyond skinning. Seconds on CPU.
"""

from __future__ import annotations

import json
from functools import partial
from pathlib import Path

import numpy as np
import pytest

#: The tiny factory config of tests/datagen/test_factory.py, with a few more frames.
TINY = {
    "shirts": 3, "test_shirts": [2], "bodies": ["short_thin", "tall_fat", "medium_regular"],
    "test_bodies": ["medium_regular"], "garment_vertices": 400, "max_frames": 6,
    "train_motions": [{"kind": "walk", "seconds": 1.0, "seed": 0}],
    "test_motions": [{"kind": "dance", "seconds": 1.0, "seed": 5}],
    "sim": {"substeps": 2, "iterations": 2, "collider_faces": 2000},
}


def fake_simulate(body, betas, garment_verts, garment_faces, poses, transl=None, config=None):
    """Skinning plus ripples whose phase follows the pose: a stand-in for the simulation."""
    from cloth_usd.core.features import vertex_normals
    from cloth_usd.core.skinning import bind_garment, skin_garment
    from cloth_usd.datagen.simulate import SimResult

    transl = np.zeros((poses.shape[0], 3)) if transl is None else transl
    binding = bind_garment(body, betas, garment_verts)
    pts = skin_garment(binding, poses, transl, body.parents)
    normals = vertex_normals(pts, garment_faces)
    rest = np.asarray(garment_verts, dtype=np.float64)
    phase = 4.0 * poses[:, 3:].sum(axis=1, keepdims=True)  # (T, 1)
    ripple = 0.003 * np.sin(70.0 * rest[None, :, 1] + phase) + 0.002 * np.cos(50.0 * rest[None, :, 0] - phase)
    positions = (pts + ripple[..., None] * normals).astype(np.float32)
    t = positions.shape[0]
    zeros = np.zeros(t)
    return SimResult(positions=positions, nan=np.zeros(t, bool), penetration=zeros, max_stretch=np.ones(t),
                     max_speed=zeros, bare=zeros, stable=np.ones(t, bool), frames_requested=t, failure="", device="cpu",
                     seconds_per_frame=0.0)


def build_tiny_dataset(out: Path) -> Path:
    """Run the factory on :data:`TINY` with :func:`fake_simulate` into ``out``."""
    from cloth_usd.datagen import dataset, factory

    config_path = out.parent / f"{out.name}.json"
    config_path.write_text(json.dumps(TINY))
    with pytest.MonkeyPatch.context() as mp:
        mp.setattr(factory, "run_jobs", partial(dataset.run_jobs, simulator=fake_simulate))
        # the shards record the stand-in, not Newton (and importing Newton alone costs seconds)
        mp.setattr(dataset, "engine_versions", lambda: {"simulator": "tests/nn/train_data.py:fake_simulate"})
        if hasattr(factory, "drape_pairs"):  # the rest garment as planned: no drape simulation either
            mp.setattr(factory, "drape_pairs", lambda jobs, *args, **kwargs: (list(jobs), {}))
        factory.run_factory(factory.load_config(config_path), out, workers=1)
    return out


@pytest.fixture(scope="module", autouse=True)
def one_thread():
    """One torch thread for a module's tests: two on a loaded 2-core machine spin-wait (10-50x
    slower steps). Imported by the training test modules, where it applies to every test."""
    import torch

    threads = torch.get_num_threads()
    torch.set_num_threads(1)
    yield
    torch.set_num_threads(threads)


def tiny_dataset(tmp_path_factory) -> Path:
    """The session's tiny data set folder (built on first use)."""
    out = tmp_path_factory.getbasetemp() / "tiny-train-data"
    if not (out / "manifest.json").exists():
        build_tiny_dataset(out)
    return out


#: A tiny, fast training config for the tests.
TINY_TRAIN = {"epochs": 2, "width": 0.125, "batch": 3, "lr": 3e-3, "stat_frames": 3, "val_frames": 3,
              "max_frames": 3, "max_batches": 2}


def tiny_runs(tmp_path_factory) -> tuple[Path, Path, Path]:
    """``(data, coarse run, detail run)``: both tiers trained for 2 epochs through the CLI."""
    from cloth_usd.cli import main

    data = tiny_dataset(tmp_path_factory)
    base = tmp_path_factory.getbasetemp()
    coarse, detail = base / "tiny-run-coarse", base / "tiny-run-detail"
    config = base / "tiny-train.json"
    config.write_text(json.dumps(TINY_TRAIN))
    if not (coarse / "best.pt").exists():
        assert main(["train", "coarse", "--data", str(data), "-o", str(coarse), "--config", str(config),
                     "--device", "cpu"]) == 0
    if not (detail / "best.pt").exists():
        assert main(["train", "detail", "--data", str(data), "-o", str(detail), "--config", str(config),
                     "--coarse-run", str(coarse), "--device", "cpu"]) == 0
    return data, coarse, detail


def tiny_trained_bundle(tmp_path_factory) -> Path:
    """The tiny runs exported to a bundle through the CLI (ONNX parity checked on export)."""
    from cloth_usd.cli import main

    data, coarse, detail = tiny_runs(tmp_path_factory)
    out = tmp_path_factory.getbasetemp() / "tiny-trained-bundle"
    if not (out / "manifest.json").exists():
        assert main(["export", "--coarse-run", str(coarse), "--detail-run", str(detail), "--data", str(data),
                     "-o", str(out), "--name", "tiny-trained"]) == 0
    return out

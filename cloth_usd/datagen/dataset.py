"""Sharded, resumable ground-truth data: one ``.npz`` shard per garment-body-motion.

A shard holds the garment (rest vertices, faces), the body (betas) and motion (poses,
transl), the simulated positions, docs/method.md's coarse target (Laplacian smoothing of
the simulated garment), the fit-attribute inputs (each garment vertex's associated
unposed body vertex and its distance to it) and the quality figures. A JSON
:class:`Manifest` beside the shards records seeds, engine versions, the
:class:`~cloth_usd.datagen.simulate.SimConfig`, per-sequence quality and the rejected
(unstable) sequences, which are listed but never written. Files are written to a temp
name and renamed, so a crash never leaves a half shard. Never pickle: every array is
plain and :func:`read_shard` loads with ``allow_pickle=False``. Shape letters: T frames,
N garment vertices, M garment triangles, V body vertices.
"""

from __future__ import annotations

import hashlib
import json
import logging
import time
from dataclasses import dataclass, field
from pathlib import Path
from typing import Callable, Iterable

import numpy as np

from ..core.association import associate
from ..core.body import BodyModel, load_body_model, shape_body
from ..core.mesh import laplacian_smooth
from ..core.shards import (MANIFEST_NAME, SHARD_FORMAT, DatasetError, Manifest, Shard, read_shard,  # noqa: F401
                           write_shard)
from .simulate import SimConfig, SimItem, SimResult, engine_versions, simulate, simulate_batch

__all__ = [
    "DatasetError",
    "DatasetConfig",
    "Job",
    "Shard",
    "Manifest",
    "SHARD_FORMAT",
    "laplacian_smooth",
    "fit_inputs",
    "write_shard",
    "read_shard",
    "shard_is_valid",
    "run_jobs",
]

log = logging.getLogger(__name__)


@dataclass(frozen=True)
class DatasetConfig:
    """How shards are derived from a simulation."""

    coarse_iterations: int = 10
    """Laplacian smoothing passes that make the coarse target from the simulated garment."""
    coarse_lambda: float = 0.5
    """Step of each smoothing pass (0 < lambda <= 1)."""

    def __post_init__(self) -> None:
        if self.coarse_iterations < 0:
            raise DatasetError(f"DatasetConfig.coarse_iterations must be >= 0, got {self.coarse_iterations}")
        if not 0.0 < self.coarse_lambda <= 1.0:
            raise DatasetError(f"DatasetConfig.coarse_lambda must be in (0, 1], got {self.coarse_lambda}")


@dataclass(frozen=True)
class Job:
    """One garment-body-motion sequence to simulate."""

    name: str
    """Shard stem: letters, digits, '-', '_' and '.' only."""
    garment_vertices: np.ndarray
    """(N, 3) float rest garment [m], canonical body frame."""
    garment_faces: np.ndarray
    """(M, 3) int triangles."""
    betas: np.ndarray
    """(B',) shape coefficients."""
    poses: np.ndarray
    """(T, 72) axis-angle [rad]; frame 0 is the rest pose."""
    transl: np.ndarray
    """(T, 3) root translation [m]."""
    seed: int = 0
    """The seed that drew this job's garment, body and motion (recorded in the manifest)."""
    meta: dict = field(default_factory=dict)
    """JSON-able provenance (garment parameters, motion name, ...)."""

    def digest(self, config: SimConfig, dataset: DatasetConfig) -> str:
        """sha256 over every input and setting: a shard is reused only when it matches."""
        h = hashlib.sha256()
        for arr in (self.garment_vertices, self.garment_faces, self.betas, self.poses, self.transl):
            a = np.ascontiguousarray(arr)
            h.update(str((a.dtype.str, a.shape)).encode())
            h.update(a.tobytes())
        h.update(json.dumps([config.to_json(), dataset.__dict__, SHARD_FORMAT], sort_keys=True).encode())
        return h.hexdigest()


def fit_inputs(body: BodyModel, betas: np.ndarray, garment_vertices: np.ndarray
               ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The fit-attribute inputs of one garment-body pair (docs/method.md, rest pose).

    Returns:
        ``(assoc_vertex (N,) int64, fit_distance (N,) [m] to that body vertex,
        surface_distance (N,) [m] to the body surface)``.
    """
    v_shaped, _ = shape_body(body, betas)
    a = associate(garment_vertices, v_shaped, body.faces)
    fit = np.linalg.norm(np.asarray(garment_vertices, dtype=np.float64) - v_shaped[a.vertex], axis=1)
    return a.vertex, fit, a.distance


# --------------------------------------------------------------------------- files


def shard_is_valid(path: str | Path, digest: str | None = None) -> bool:
    """Whether ``path`` is a readable shard (made from ``digest`` when given)."""
    try:
        shard = read_shard(path)
    except DatasetError as exc:
        log.info("%s", exc)
        return False
    return digest is None or shard.digest == digest


# --------------------------------------------------------------------------- jobs


def _check_name(name: str) -> None:
    if not name or not all(c.isalnum() or c in "-_." for c in name) or name.startswith("."):
        raise DatasetError(f"job name '{name}' must use letters, digits, '-', '_' and '.' only")


def make_shard(job: Job, result: SimResult, body: BodyModel, config: SimConfig,
               dataset: DatasetConfig, digest: str) -> Shard:
    """Assemble a shard from a job and its simulation: stable, or the part of an unstable one a
    data set keeps (:meth:`~cloth_usd.datagen.simulate.SimResult.partial`), whose frames are the
    job's first ones."""
    frames = result.frames_done
    assoc, fit, surf = fit_inputs(body, job.betas, job.garment_vertices)
    coarse = laplacian_smooth(result.positions, job.garment_faces, iterations=dataset.coarse_iterations,
                              lam=dataset.coarse_lambda)
    meta = {"name": job.name, "seed": int(job.seed), "config": config.to_json(), "engine": engine_versions(),
            "quality": result.quality(), "job": job.meta, "fps": config.fps}
    return Shard(
        garment_vertices=np.asarray(job.garment_vertices, dtype=np.float32),
        garment_faces=np.asarray(job.garment_faces, dtype=np.int64),
        positions=result.positions.astype(np.float32), coarse=coarse.astype(np.float32),
        betas=np.asarray(job.betas, dtype=np.float64), poses=np.asarray(job.poses[:frames], dtype=np.float64),
        transl=np.asarray(job.transl[:frames], dtype=np.float64), assoc_vertex=assoc.astype(np.int64),
        fit_distance=fit.astype(np.float32), surface_distance=surf.astype(np.float32),
        penetration=result.penetration.astype(np.float32), max_stretch=result.max_stretch.astype(np.float32),
        digest=digest, meta=meta)


def run_jobs(jobs: Iterable[Job], out_dir: str | Path, config: SimConfig = SimConfig(), *,
             body: BodyModel | None = None, dataset: DatasetConfig = DatasetConfig(),
             simulator: Callable[..., SimResult] = simulate,
             manifest_name: str = MANIFEST_NAME, batch: int = 1, penetration_frames: int | None = None,
             batch_simulator: Callable[..., list[SimResult]] = simulate_batch,
             deadline: float | None = None) -> Manifest:
    """Simulate every job into ``out_dir/<name>.npz``, resumably.

    A job whose shard exists, reads back and carries the job's digest is skipped; so is
    a job the manifest already lists as rejected with the same digest. Unstable
    sequences are rejected: listed in the manifest with their quality, never written.
    The manifest is rewritten atomically after every job.

    Args:
        simulator: the simulation function (tests substitute a fake).
        manifest_name: the manifest file; parallel workers each keep their own and the
            caller merges them (shards are shared: their digests make resume safe).
        batch: simulate up to this many jobs of the same length at once, as one model
            (:func:`~cloth_usd.datagen.simulate.simulate_batch`: on a GPU about the cost of
            one); 1 simulates each job alone with ``simulator``.
        penetration_frames: with ``batch`` > 1, measure the penetration at this many frames
            of each sequence (None: every frame; see ``simulate_batch``).
        batch_simulator: the batch simulation function (tests substitute a fake).
        deadline: ``time.time()`` after which no further simulation starts (the one under way
            finishes); the jobs left are simulated by a later run (None: no limit).
    """
    if batch < 1:
        raise DatasetError(f"batch must be at least 1, got {batch}")
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    body = body if body is not None else load_body_model()
    try:
        manifest = Manifest.read(out, manifest_name)
    except DatasetError:
        manifest = Manifest(config={}, dataset={}, engine={})
    earlier = {}  # what an interrupted run merged into the data set's manifest (workers' runs)
    if manifest_name != MANIFEST_NAME:
        try:
            earlier = Manifest.read(out).sequences
        except DatasetError:
            pass
    manifest.config, manifest.dataset, manifest.engine = config.to_json(), dict(dataset.__dict__), engine_versions()
    pending = []  # (job, digest, shard path) still to simulate
    for job in jobs:
        _check_name(job.name)
        digest = job.digest(config, dataset)
        path = out / f"{job.name}.npz"
        prior = manifest.sequences.get(job.name) or earlier.get(job.name)
        if prior and prior.get("digest") == digest and prior["status"] == "rejected" \
                and (not config.keep_partial or prior.get("keep_partial", 0) == config.keep_partial):
            log.info("%s: rejected before with the same inputs, skipped", job.name)
            continue
        if path.exists() and shard_is_valid(path, digest):
            log.info("%s: shard exists, skipped", job.name)
            if not prior or prior.get("digest") != digest:  # e.g. a manifest lost in a crash
                shard = read_shard(path)
                manifest.sequences[job.name] = {"status": "ok", "seed": int(job.seed), "digest": digest,
                                                "shard": path.name, "quality": shard.meta.get("quality", {}),
                                                "meta": job.meta}
                manifest.write(out, manifest_name)
            continue
        pending.append((job, digest, path))

    def record(job: Job, digest: str, path: Path, result: SimResult) -> None:
        entry = {"seed": int(job.seed), "digest": digest, "quality": result.quality(), "meta": job.meta}
        warmup = int((job.meta or {}).get("warmup_frames", 0))
        part = result.partial(config.keep_partial, config.fps, warmup=warmup)
        if result.is_stable:
            write_shard(path, make_shard(job, result, body, config, dataset, digest))
            entry.update(status="ok", shard=path.name)
        elif part is not None:
            write_shard(path, make_shard(job, part, body, config, dataset, digest))
            log.warning("%s: unstable (%s); its first %d of %d frames kept", job.name, result.failure or "unstable",
                        part.frames_done, result.frames_requested)
            entry.update(status="ok", shard=path.name, quality=part.quality(), keep_partial=config.keep_partial,
                         partial={"frames": part.frames_done, "frames_requested": result.frames_requested,
                                  "failure": result.failure})
        else:
            kept = (f"; fewer than {config.keep_partial} frames before it follow the {warmup}-frame warm-up, "
                    "nothing kept") if config.keep_partial else ""
            log.warning("%s: rejected (%s%s)", job.name, result.failure or "unstable", kept)
            path.unlink(missing_ok=True)  # a stale shard of older inputs must not survive
            entry.update(status="rejected", shard=None)
            if config.keep_partial:
                entry.update(keep_partial=config.keep_partial)
        manifest.sequences[job.name] = entry
        manifest.write(out, manifest_name)

    def out_of_time(left: int) -> bool:
        if deadline is not None and time.time() > deadline:
            log.warning("deadline passed: %d sequences left unsimulated (run again to continue)", left)
            return True
        return False

    if batch == 1:
        for i, (job, digest, path) in enumerate(pending):
            if out_of_time(len(pending) - i):
                break
            record(job, digest, path, simulator(body, job.betas, job.garment_vertices, job.garment_faces,
                                                job.poses, job.transl, config))
    else:
        by_length: dict[int, list] = {}
        for p in pending:  # a batch shares its frame count; the jobs' order is kept within a length
            by_length.setdefault(int(p[0].poses.shape[0]), []).append(p)
        left = len(pending)
        for group in by_length.values():
            for i in range(0, len(group), batch):
                if out_of_time(left):
                    break
                chunk = group[i:i + batch]
                left -= len(chunk)
                items = [SimItem(j.betas, j.garment_vertices, j.garment_faces, j.poses, j.transl) for j, _, _ in chunk]
                log.info("simulating %d sequences of %d frames as one model", len(chunk), chunk[0][0].poses.shape[0])
                for (job, digest, path), result in zip(chunk, batch_simulator(body, items, config,
                                                                              penetration_frames=penetration_frames)):
                    record(job, digest, path, result)
    manifest.write(out, manifest_name)
    return manifest

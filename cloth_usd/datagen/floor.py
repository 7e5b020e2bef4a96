"""The error floor of a per-frame model: a moving garment against the same pose held still.

A per-frame model sees one pose and gives one garment. The simulated garment in a moving
shot also depends on how the body got there (it swings, lags, overshoots), so no per-frame
model can match it exactly. How far it can get is measured here: for a few frames k of a
simulated sequence, the same motion up to frame k and then the pose of frame k held for
``hold_seconds``, until the cloth settles. The distance between the moving garment at
frame k and the settled one is that frame's floor: the part of the error that belongs to
the dynamics.

Each held sequence is a job of its own (split :data:`FLOOR_SPLIT`, named
``floor.<sequence>.f<k>``), simulated and stored by the factory like any other;
:func:`floor_report` reads them back beside their sequences. Shape letters: T frames.
"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from ..core.files import check_keys
from ..core.shards import DatasetError, Manifest, read_shard
from ..errors import ArgumentError
from .dataset import Job

__all__ = ["FLOOR_SPLIT", "FloorSpec", "held_frames", "held_motion", "floor_jobs", "floor_report"]

#: The split of the held-pose sequences (never trained or evaluated on).
FLOOR_SPLIT = "floor"


@dataclass(frozen=True)
class FloorSpec:
    """Which frames are held, and for how long."""

    sequences: int = 4
    """How many of the simulated sequences get held frames (spread evenly over the plan), >= 1."""
    frames: int = 2
    """Held frames per sequence, spread evenly over the frames after the warm-up, >= 1."""
    hold_seconds: float = 1.0
    """How long each pose is held [s], > 0."""

    def __post_init__(self) -> None:
        for key in ("sequences", "frames"):
            value = getattr(self, key)
            if not isinstance(value, int) or value < 1:
                raise ArgumentError(f"floor.{key} must be an integer >= 1, got {value!r}")
        if not (isinstance(self.hold_seconds, (int, float)) and self.hold_seconds > 0):
            raise ArgumentError(f"floor.hold_seconds must be > 0, got {self.hold_seconds!r}")

    @classmethod
    def from_mapping(cls, raw) -> FloorSpec:
        """From the config's ``floor`` table; unknown keys are an error naming them."""
        raw = check_keys(raw, cls, "floor")
        return cls(**raw)


def held_frames(num_frames: int, warmup: int, count: int) -> list[int]:
    """``count`` frame indices spread evenly over ``warmup .. num_frames - 1``, the ends left out."""
    if num_frames - warmup < 1:
        return []
    picks = np.linspace(warmup, num_frames - 1, count + 2)[1:-1]
    return sorted({int(round(k)) for k in picks})


def held_motion(poses: np.ndarray, transl: np.ndarray, frame: int, hold: int) -> tuple[np.ndarray, np.ndarray]:
    """The motion up to ``frame``, then that frame's pose and root repeated ``hold`` times.

    Returns:
        ``(poses (frame + 1 + hold, 72), transl (frame + 1 + hold, 3))``.
    """
    k = int(frame)
    return (np.concatenate([poses[:k + 1], np.repeat(poses[k:k + 1], hold, axis=0)]),
            np.concatenate([transl[:k + 1], np.repeat(transl[k:k + 1], hold, axis=0)]))


def floor_jobs(jobs: list[Job], spec: FloorSpec) -> list[Job]:
    """The held-pose jobs of ``spec.sequences`` of ``jobs``, spread evenly over the list.

    Each is the job's motion up to frame k, then frame k's pose (and root) repeated for
    ``hold_seconds``; its ``meta`` is the job's with ``split`` :data:`FLOOR_SPLIT`,
    ``floor_of`` (the job's name), ``frame`` (k) and ``hold_frames``.
    """
    out = []
    picks = sorted({int(round(i)) for i in np.linspace(0, len(jobs) - 1, min(spec.sequences, len(jobs)))}) \
        if jobs else []
    for job in (jobs[i] for i in picks):
        fps = float(job.meta.get("fps") or 24.0)
        hold = max(1, int(round(spec.hold_seconds * fps)))
        t = job.poses.shape[0]
        for k in held_frames(t, int(job.meta.get("warmup_frames", 0)), spec.frames):
            poses, transl = held_motion(job.poses, job.transl, k, hold)
            meta = {**job.meta, "split": FLOOR_SPLIT, "floor_of": job.name, "frame": k, "hold_frames": hold}
            meta.pop("warmup_frames", None)
            out.append(dataclasses.replace(job, name=f"floor.{job.name}.f{k}", poses=poses, transl=transl,
                                           meta=meta))
    return out


def floor_report(data_dir: str | Path) -> dict:
    """The floor measured on a data set folder, or ``{}`` when it holds no held-pose sequences.

    Returns:
        ``{"frames": [{"sequence", "frame", "mean_mm", "p95_mm", "max_mm", "settle_mm"}, ...],
        "mean_mm": ..., "p95_mm": ...}``: per held frame, the distance between the moving
        garment and the settled one (mean, 95th percentile and maximum over vertices
        [mm]) and the largest vertex step over the last held frame (how settled it is
        [mm]); then the mean and 95th percentile over all held frames' vertices.
    Raises:
        ArgumentError: an unreadable manifest or shard (naming it).
    """
    root = Path(data_dir)
    try:
        manifest = Manifest.read(root)
    except DatasetError as exc:
        raise ArgumentError(str(exc)) from exc
    rows, all_d = [], []
    for name, entry in sorted(manifest.sequences.items()):
        meta = entry.get("meta", {})
        if meta.get("split") != FLOOR_SPLIT or entry.get("status") != "ok":
            continue
        moving_entry = manifest.sequences.get(meta.get("floor_of", ""), {})
        if moving_entry.get("status") != "ok":
            continue
        try:
            held = read_shard(root / entry["shard"]).positions
            moving = read_shard(root / moving_entry["shard"]).positions
        except DatasetError as exc:
            raise ArgumentError(str(exc)) from exc
        k = int(meta["frame"])
        if k >= moving.shape[0]:
            continue
        d = np.linalg.norm(moving[k].astype(np.float64) - held[-1], axis=-1) * 1e3
        settle = np.linalg.norm(held[-1].astype(np.float64) - held[-2], axis=-1).max() * 1e3
        rows.append({"sequence": meta["floor_of"], "frame": k, "mean_mm": float(d.mean()),
                     "p95_mm": float(np.percentile(d, 95)), "max_mm": float(d.max()), "settle_mm": float(settle)})
        all_d.append(d)
    if not rows:
        return {}
    d = np.concatenate(all_d)
    return {"frames": rows, "mean_mm": float(d.mean()), "p95_mm": float(np.percentile(d, 95))}

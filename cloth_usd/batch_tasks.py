"""What a batch worker runs: the :class:`Job` record, the task a worker is sent, and
:func:`run_task`, which runs one in a worker process (local or Ray).

Shared by :mod:`cloth_usd.batch` (the scheduler and local executor) and
:mod:`cloth_usd.batch_ray` (the Ray executor), which both import it; it imports neither.
"""

from __future__ import annotations

import logging
import os
import signal
import threading
import time
from dataclasses import dataclass
from enum import Enum
from pathlib import Path
from typing import Any, Callable

from .errors import ArgumentError, ClothUsdError, OutputWriteError

__all__ = ["KILL_HOOK_ENV", "Job", "Kind", "Task", "Event", "worker_init", "run_task", "remove_chunk_dir",
           "one_line"]

#: Test hook, read when a task starts: a folder of marker files ``<job name>.<task kind>.kill``
#: (kinds: bake, plan, chunk, stitch). The first task that finds its marker removes it and
#: SIGKILLs its own worker: at once when the marker says ``start``, or once it has
#: written its first frames into the temporary layer when it says ``write``.
KILL_HOOK_ENV = "CLOTH_USD_BATCH_TEST_KILL"


# ------------------------------------------------------------------------------ jobs


@dataclass(frozen=True)
class Job:
    """One bake of a batch."""

    name: str
    """Unique within the batch; names the job in the summary and report."""
    stage: Path
    """The USD stage to read."""
    output: Path
    """The cache layer to write."""
    frames: str | None = None
    """``START:END[:STEP]``, None for the stage's range."""
    garments: tuple[str, ...] | None = None
    """Garment prim paths, None for every enabled garment."""
    tier: str | None = None
    """Default tier for garments without ``cloth:tier`` (None: skinning)."""
    models: tuple[str, ...] | None = None
    """Model bundle search folders, None for the shipped ones."""
    body_model: str | None = None
    """SMPL-format file or folder, None for the embedded model."""
    joint_map: str | None = None
    """Joint map file for skeletons named in no known convention (``bake --joint-map``)."""
    strict: bool = False
    """A learned frame that is not a garment fails the job (``bake --strict``) instead of
    being replaced by a safer tier."""

    def bake_command(self) -> list[str]:
        """The ``cloth-usd bake`` command line that bakes this job by itself."""
        cmd = ["cloth-usd", "bake", str(self.stage), "-o", str(self.output), "--force"]
        if self.frames:
            cmd += ["--frames", self.frames]
        for g in self.garments or ():
            cmd += ["--garment", g]
        if self.tier:
            cmd += ["--tier", self.tier]
        if self.models:
            if len(self.models) > 1:  # `bake --models` takes one folder
                raise ArgumentError(f"job {self.name}: several model folders; `cloth-usd bake` takes one")
            cmd += ["--models", self.models[0]]
        if self.body_model:
            cmd += ["--body-model", self.body_model]
        if self.joint_map:
            cmd += ["--joint-map", self.joint_map]
        if self.strict:
            cmd += ["--strict"]
        return cmd



# ----------------------------------------------------------------------------- tasks


class Kind(str, Enum):
    BAKE = "bake"
    PLAN = "plan"
    CHUNK = "chunk"
    STITCH = "stitch"


@dataclass(frozen=True)
class Task:
    """One unit a worker runs; plain data, so it pickles for processes and Ray."""

    kind: Kind
    job: Job
    output: Path
    """What the task writes (the job's output, or a chunk layer)."""
    frames: str | None = None
    force: bool = False
    chunks: tuple[Path, ...] = ()
    """Stitch: the chunk layers, in time order."""
    inputs_sha256: str = ""


_CACHE = None  # the worker process's ModelCache


def worker_init() -> None:
    """Once per worker process: a model cache, and warnings kept for the report, not stderr."""
    global _CACHE
    if _CACHE is None:
        from .baker import ModelCache

        _CACHE = ModelCache()
        logging.getLogger("cloth_usd").addHandler(logging.NullHandler())
        # tqdm's default lock is a multiprocessing semaphore, which a killed worker leaks.
        from tqdm import tqdm

        tqdm.set_lock(threading.RLock())


def _kill_hook(task: Task) -> Callable[..., None] | None:
    """The test hook of :data:`KILL_HOOK_ENV`."""
    folder = os.environ.get(KILL_HOOK_ENV)
    if not folder:
        return None
    marker = Path(folder) / f"{task.job.name}.{task.kind.value}.kill"
    try:
        mode = marker.read_text().strip()
        marker.unlink()  # only one attempt (of one task) takes it
    except FileNotFoundError:
        return None

    def die(*_: Any) -> None:
        os.kill(os.getpid(), signal.SIGKILL)

    if mode == "start":
        die()
    return die


def run_task(task: Task) -> dict:
    """Run one task in a worker; never raises for a job's own errors.

    Returns:
        ``status`` (done, skipped, planned or error), ``seconds`` and, by kind,
        ``frames``, ``garments``, ``warnings``, ``inputs_sha256`` or ``error`` and
        ``retry`` (whether another attempt could succeed).
    """
    worker_init()
    began = time.perf_counter()
    try:
        from .baker import bake, bake_plan, stitch_chunks
        from .usd.write import remove_stale_temps

        hook = _kill_hook(task)
        job = task.job
        if task.kind is Kind.CHUNK:
            task.output.parent.mkdir(exist_ok=True)
        remove_stale_temps(task.output)  # left by an attempt killed mid-write
        common = dict(frames=task.frames, garments=job.garments, tier=job.tier, body_model=job.body_model,
                      models=list(job.models) if job.models else None, cache=_CACHE, joint_map=job.joint_map)
        if task.kind is Kind.PLAN:
            plan = bake_plan(job.stage, None if task.force else job.output, **common)
            out = {"status": "skipped" if plan.current else "planned", "frames": str(plan.frames),
                   "count": int(plan.frames.times().shape[0]), "inputs_sha256": plan.inputs_sha256}
        elif task.kind is Kind.STITCH:
            stitch_chunks(task.chunks, task.output, inputs_sha256=task.inputs_sha256, force=True)
            for chunk in task.chunks:
                chunk.unlink(missing_ok=True)
            remove_chunk_dir(task.chunks[0].parent)
            out = {"status": "done"}
        else:
            result = bake(job.stage, task.output, force=True, skip_current=not task.force,
                          on_progress=hook, strict=job.strict, **common)
            out = {"status": "skipped" if result.skipped else "done", "frames": int(result.times.shape[0]),
                   "inputs_sha256": result.inputs_sha256,
                   "garments": [_garment_summary(g) for g in result.garments],
                   "warnings": [w for g in result.garments for w in g.warnings]}
    except OutputWriteError as exc:  # USD could not save: a full disk, a share gone; worth another attempt
        out = {"status": "error", "error": one_line(str(exc)), "retry": True}
    except ClothUsdError as exc:
        out = {"status": "error", "error": one_line(str(exc)), "retry": False}
    except OSError as exc:  # a full disk, a network share gone: worth another attempt
        out = {"status": "error", "error": one_line(f"{type(exc).__name__}: {exc}"), "retry": True}
    except Exception as exc:  # a bug: report it with the job, keep the batch going
        out = {"status": "error", "error": one_line(f"{type(exc).__name__}: {exc}"), "retry": False}
    out["seconds"] = time.perf_counter() - began
    return out


def remove_chunk_dir(folder: Path) -> None:
    """Remove a chunk folder and what earlier runs left in it (other chunk sizes, temps)."""
    if folder.is_dir() and folder.name.endswith(".chunks"):
        for entry in folder.iterdir():
            if entry.is_file():
                entry.unlink(missing_ok=True)
        try:
            folder.rmdir()
        except OSError:
            pass


def _garment_summary(g) -> dict:
    return {"prim": g.prim_path, "tier": g.tier.value, "vertices": g.vertices, "frames": g.frames,
            "mean_body_distance_mm": round(g.mean_body_distance_mm, 3),
            "max_displacement_mm": round(g.max_displacement_mm, 3), "max_offset_mm": round(g.max_offset_mm, 3)}


def one_line(text: str) -> str:
    lines = [line.strip() for line in text.strip().splitlines() if line.strip()]
    return lines[0] if lines else "unknown error"

# --------------------------------------------------------------------------- executor


@dataclass(frozen=True)
class Event:
    """A task that ended: with a result, or with its worker dead (``died`` says how)."""

    tid: int
    result: dict | None
    died: str | None = None
    final: bool = False
    """The executor already retried it (Ray): do not run it again."""


"""What a batch worker runs: the :class:`Task` it is sent, :func:`run_task`, which runs
one in a worker process (local or Ray) and returns a :class:`TaskResult`, and the
:class:`Event` an executor hands back to the driver."""

from __future__ import annotations

import dataclasses
import logging
import os
import signal
import threading
import time
from dataclasses import dataclass
from enum import Enum
from pathlib import Path
from typing import Any, Callable

from tqdm import tqdm

from ..baking import ModelCache, bake, bake_plan, stitch_chunks
from ..core.frame_range import FrameRange
from ..core.provenance import GarmentReport
from ..errors import ClothUsdError, OutputWriteError
from ..usd.write import remove_stale_temps
from .jobs import Job

__all__ = ["KILL_HOOK_ENV", "Kind", "Task", "Outcome", "TaskResult", "Event", "chunk_tasks", "worker_init",
           "run_task", "remove_chunk_dir", "one_line"]

#: Test hook, read when a task starts: a folder of marker files ``<job name>.<task kind>.kill``
#: (kinds: bake, plan, chunk, stitch). The first task that finds its marker removes it and
#: SIGKILLs its own worker: at once when the marker says ``start``, or once it has
#: written its first frames into the temporary layer when it says ``write``.
KILL_HOOK_ENV = "CLOTH_USD_BATCH_TEST_KILL"


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
    frames: FrameRange | None = None
    """None for the stage's range."""
    force: bool = False
    chunks: tuple[Path, ...] = ()
    """Stitch: the chunk layers, in time order."""
    inputs_sha256: str = ""


def chunk_tasks(job: Job, frames: FrameRange, size: int, force: bool) -> list[Task]:
    """The frame chunks of a job, each a cache layer in ``.<output name>.chunks/``."""
    folder = job.output.parent / f".{job.output.name}.chunks"
    return [Task(Kind.CHUNK, job, folder / f"{part.start:.10g}_{part.end:.10g}{job.output.suffix}", frames=part,
                 force=force)
            for part in frames.chunks(size)]


class Outcome(str, Enum):
    """How a task ended."""

    DONE = "done"
    SKIPPED = "skipped"
    """Its output was already up to date."""
    PLANNED = "planned"
    """A plan task whose job is to be baked."""
    ERROR = "error"


@dataclass(frozen=True)
class TaskResult:
    """What :func:`run_task` returns; plain data, so it pickles back from processes and Ray."""

    status: Outcome
    seconds: float = 0.0
    """Worker time [s]."""
    frames: FrameRange | None = None
    """Plan: the job's resolved frame range."""
    count: int = 0
    """Plan, bake, chunk: the number of frames planned or baked."""
    inputs_sha256: str = ""
    garments: tuple[GarmentReport, ...] = ()
    """Bake, chunk: what was baked per garment (warnings included)."""
    error: str | None = None
    """The one-line error of a failed task."""
    retry: bool = False
    """A failed task that another attempt could bring through (a full disk, a share gone)."""


@dataclass(frozen=True)
class Event:
    """A task that ended: with a result, or with its worker dead (``died`` says how)."""

    tid: int
    result: TaskResult | None
    died: str | None = None
    final: bool = False
    """The executor already retried it (Ray): do not run it again."""


_CACHE: ModelCache | None = None  # the worker process's ModelCache


def worker_init() -> None:
    """Once per worker process: a model cache, and warnings kept for the report, not stderr."""
    global _CACHE
    if _CACHE is None:
        _CACHE = ModelCache()
        logging.getLogger("cloth_usd").addHandler(logging.NullHandler())
        # tqdm's default lock is a multiprocessing semaphore, which a killed worker leaks.
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


def _run(task: Task) -> TaskResult:
    hook = _kill_hook(task)
    job = task.job
    if task.kind in (Kind.BAKE, Kind.CHUNK):  # a batch makes its out_dir (and a job's chunk folder)
        task.output.parent.mkdir(parents=True, exist_ok=True)
    remove_stale_temps(task.output)  # left by an attempt killed mid-write
    common = dict(frames=task.frames, garments=job.garments, tier=job.tier, body_model=job.body_model,
                  models=list(job.models) if job.models else None, cache=_CACHE, joint_map=job.joint_map)
    if task.kind is Kind.PLAN:
        plan = bake_plan(job.stage, None if task.force else job.output, **common)
        return TaskResult(Outcome.SKIPPED if plan.current else Outcome.PLANNED, frames=plan.frames,
                          count=plan.frames.count(), inputs_sha256=plan.inputs_sha256)
    if task.kind is Kind.STITCH:
        stitch_chunks(task.chunks, task.output, inputs_sha256=task.inputs_sha256, force=True)
        for chunk in task.chunks:
            chunk.unlink(missing_ok=True)
        remove_chunk_dir(task.chunks[0].parent)
        return TaskResult(Outcome.DONE)
    result = bake(job.stage, task.output, force=True, skip_current=not task.force,
                  on_progress=hook, strict=job.strict, **common)
    return TaskResult(Outcome.SKIPPED if result.skipped else Outcome.DONE, count=int(result.times.shape[0]),
                      inputs_sha256=result.inputs_sha256, garments=result.garments)


def run_task(task: Task) -> TaskResult:
    """Run one task in a worker; never raises for a job's own errors (they come back as
    :attr:`Outcome.ERROR` with :attr:`TaskResult.retry` saying whether another attempt could succeed)."""
    worker_init()
    began = time.perf_counter()
    try:
        out = _run(task)
    except OutputWriteError as exc:  # USD could not save: a full disk, a share gone; worth another attempt
        out = TaskResult(Outcome.ERROR, error=one_line(str(exc)), retry=True)
    except ClothUsdError as exc:
        out = TaskResult(Outcome.ERROR, error=one_line(str(exc)), retry=False)
    except OSError as exc:  # a full disk, a network share gone: worth another attempt
        out = TaskResult(Outcome.ERROR, error=one_line(f"{type(exc).__name__}: {exc}"), retry=True)
    except Exception as exc:  # a bug: report it with the job, keep the batch going
        out = TaskResult(Outcome.ERROR, error=one_line(f"{type(exc).__name__}: {exc}"), retry=False)
    return dataclasses.replace(out, seconds=time.perf_counter() - began)


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


def one_line(text: str) -> str:
    lines = [line.strip() for line in text.strip().splitlines() if line.strip()]
    return lines[0] if lines else "unknown error"

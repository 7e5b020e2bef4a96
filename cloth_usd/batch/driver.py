"""The batch driver: :func:`run_batch` queues each job's tasks on an executor (local
processes or Ray), retries those whose worker died, and turns their results into reports."""

from __future__ import annotations

import logging
import os
import time
from collections import deque
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Callable, Sequence

from ..core.provenance import GarmentReport
from ..errors import ArgumentError
from ..usd.write import remove_stale_temps
from .jobs import Job
from .pool import LocalPool
from .report import BatchReport, JobReport, JobStatus
from .tasks import Kind, Outcome, Task, TaskResult, chunk_tasks

__all__ = ["EXECUTORS", "run_batch"]

log = logging.getLogger(__name__)

#: Where jobs run: ``local`` worker processes, or ``ray`` (``pip install 'cloth-usd[ray]'``).
EXECUTORS = ("local", "ray")


@dataclass
class _JobState:
    job: Job
    status: JobStatus | None = None
    error: str | None = None
    seconds: float = 0.0
    frames: int = 0
    attempts: int = 0
    inputs_sha256: str = ""
    chunks: list[Task] = field(default_factory=list)
    chunks_left: int = 0
    garments: dict[str, GarmentReport] = field(default_factory=dict)
    warnings: list[str] = field(default_factory=list)

    def report(self) -> JobReport:
        return JobReport(name=self.job.name, stage=str(self.job.stage), output=str(self.job.output),
                         status=self.status or JobStatus.FAILED, error=self.error, seconds=self.seconds,
                         frames=self.frames, attempts=self.attempts, chunks=len(self.chunks),
                         garments=tuple(self.garments.values()), warnings=tuple(self.warnings))

    def add(self, result: TaskResult) -> None:
        """A bake's or chunk's garments: another chunk of a garment is merged into it."""
        for g in result.garments:
            old = self.garments.get(g.prim_path)
            self.garments[g.prim_path] = g if old is None else old.merged(g)
            self.warnings += [w for w in g.warnings if w not in self.warnings]


def run_batch(jobs: Sequence[Job], *, executor: str = "local", workers: int | None = None, retries: int = 2,
              chunk_frames: int | None = None, force: bool = False, address: str | None = None,
              job_timeout: float | None = None, on_job: Callable[[JobReport], None] | None = None
              ) -> BatchReport:
    """Run jobs; a job's failure fails it alone.

    Args:
        jobs: from :func:`~cloth_usd.batch.load_jobs`.
        executor: ``local`` (worker processes on this machine) or ``ray``.
        workers: parallel tasks (default: the CPU count; on Ray, the CPUs of a
            local Ray it starts).
        retries: extra attempts of a task whose worker died or timed out.
        chunk_frames: bake jobs longer than this in chunks of this many frames, in
            parallel, then stitch them into the output.
        force: bake every job, even the up-to-date ones.
        address: the Ray cluster to join (``ray`` executor), default a local one.
        job_timeout: seconds one task may run before its worker is killed (a retry).
        on_job: called with each job's report as it ends.
    """
    if executor not in EXECUTORS:
        raise ArgumentError(f"--executor '{executor}': valid executors are {', '.join(EXECUTORS)}")
    if retries < 0:
        raise ArgumentError(f"--retries {retries}: must be 0 or more")
    if chunk_frames is not None and chunk_frames < 1:
        raise ArgumentError(f"--chunk-frames {chunk_frames}: must be at least 1")
    if job_timeout is not None and job_timeout <= 0:
        raise ArgumentError(f"--job-timeout {job_timeout}: must be positive")
    if workers is not None and workers < 1:
        raise ArgumentError(f"--workers {workers}: must be at least 1")
    if not jobs:
        raise ArgumentError("no jobs to run")
    began = time.perf_counter()
    workers = workers or os.cpu_count() or 1
    if executor == "ray":
        from .ray import RayPool  # Ray is imported only when a batch asks for it

        pool: Any = RayPool(workers=workers, retries=retries, address=address, job_timeout=job_timeout)
        workers = pool.size
    else:
        pool = LocalPool(workers, job_timeout)
    states = [_JobState(job) for job in jobs]
    queue: deque[tuple[int, Task]] = deque()
    tasks: dict[int, tuple[int, Task]] = {}  # tid -> (job index, task)
    attempts: dict[int, int] = {}
    running: set[int] = set()

    def push(index: int, task: Task) -> None:
        tid = len(tasks)
        tasks[tid] = (index, task)
        queue.append((tid, task))

    def finish(index: int, status: JobStatus, error: str | None = None) -> None:
        state = states[index]
        if state.status is not None:
            return
        state.status, state.error = status, error
        if on_job is not None:
            on_job(state.report())

    for i, job in enumerate(jobs):
        push(i, Task(Kind.PLAN if chunk_frames else Kind.BAKE, job, job.output, frames=job.frames, force=force))
    try:
        while queue or running:
            while queue and pool.free() > 0:
                tid, task = queue.popleft()
                if states[tasks[tid][0]].status is None:  # drop tasks of failed jobs
                    pool.submit(tid, task)
                    running.add(tid)
                    states[tasks[tid][0]].attempts += 1
            for event in pool.wait(timeout=1.0):
                running.discard(event.tid)
                index, task = tasks[event.tid]
                state = states[index]
                if state.status is not None:
                    continue
                result = event.result
                if result is not None:
                    state.seconds += result.seconds
                if result is None or (result.status is Outcome.ERROR and result.retry):
                    why = event.died or result.error
                    attempts[event.tid] = attempts.get(event.tid, 0) + 1
                    if not event.final and attempts[event.tid] <= retries:
                        log.warning("job %s: %s task %s; trying again", task.job.name, task.kind.value, why)
                        queue.appendleft((event.tid, task))
                    else:
                        runs = retries + 1 if event.final else attempts[event.tid]
                        finish(index, JobStatus.FAILED, f"{task.kind.value} task: {why} ({runs} attempts)")
                        _clean_temps(task.output)
                    continue
                if result.status is Outcome.ERROR:
                    finish(index, JobStatus.FAILED, result.error)
                    continue
                _advance(state, index, task, result, chunk_frames, force, push, finish)
    except BaseException:
        pool.close()
        raise
    pool.close()
    return BatchReport(jobs=tuple(s.report() for s in states), seconds=time.perf_counter() - began,
                       executor=executor, workers=workers)


def _advance(state: _JobState, index: int, task: Task, result: TaskResult, chunk_frames: int | None,
             force: bool, push: Callable[[int, Task], None], finish: Callable[..., None]) -> None:
    """A task of a job succeeded: queue what follows, or finish the job."""
    job = state.job
    if task.kind is Kind.PLAN:
        state.inputs_sha256 = result.inputs_sha256
        state.frames = result.count
        if result.status is Outcome.SKIPPED:
            finish(index, JobStatus.SKIPPED)
        elif result.count <= (chunk_frames or 0):
            push(index, Task(Kind.BAKE, job, job.output, frames=result.frames, force=True))
        else:
            state.chunks = chunk_tasks(job, result.frames, chunk_frames or 1, force)
            state.chunks_left = len(state.chunks)
            for chunk in state.chunks:
                push(index, chunk)
    elif task.kind is Kind.CHUNK:
        state.add(result)
        state.chunks_left -= 1
        if state.chunks_left == 0:
            push(index, Task(Kind.STITCH, job, job.output, chunks=tuple(c.output for c in state.chunks),
                              inputs_sha256=state.inputs_sha256))
    elif task.kind is Kind.STITCH:
        finish(index, JobStatus.DONE)
    else:
        state.add(result)
        state.frames = result.count
        finish(index, JobStatus.SKIPPED if result.status is Outcome.SKIPPED else JobStatus.DONE)


def _clean_temps(path: Path) -> None:
    """Best effort: the temporary file a killed last attempt left (the parent may not see it on Ray)."""
    try:
        remove_stale_temps(path)
    except OSError:
        pass

"""Headless batch bakes: many jobs, in local worker processes or on Ray.

A :class:`Job` is one bake (stage, garments, frame range, tier, output) and an
idempotent unit of work: its output path is fixed before it runs, the cache records a
digest of everything it was baked from (:func:`cloth_usd.baker.bake_plan`), and a job
whose output already holds that digest is skipped. So a batch can be run again after
any failure and only redoes what is missing, and a farm scheduler (Deadline, OpenCue)
can run the same jobs itself, one ``cloth-usd bake`` each (:meth:`Job.bake_command`).

Jobs come from a TOML or JSON job file, a text file of stage paths, or stage paths and
globs (:func:`load_jobs`). :func:`run_batch` runs them:

- each job is a task; with ``chunk_frames`` a long job becomes a plan task, one task
  per frame chunk (each writes its own cache layer into ``.<output>.chunks/`` beside
  the output) and a stitch task that joins them into the output and removes the chunks;
- a worker keeps one :class:`~cloth_usd.baker.ModelCache`, so each body model and model
  bundle is loaded once per worker and each garment bound once;
- a worker that dies (killed, out of memory) or passes ``job_timeout`` costs its task
  one attempt; the task runs again, up to ``retries`` more times. Layers are written
  atomically, so a killed task leaves no partial output, only a temporary file the
  next attempt removes;
- errors in a job (a broken stage, a missing bundle) fail that job alone, with its
  one-line message, and are not retried.

Run one batch per output folder at a time: two batches writing the same outputs would
race.
"""

from __future__ import annotations

import glob
import hashlib
import json
import logging
import multiprocessing
import multiprocessing.connection
import os
import signal
import time
from collections import deque
from dataclasses import dataclass, field
from enum import Enum
from pathlib import Path
from typing import Any, Callable, Iterable, Sequence

from .batch_tasks import KILL_HOOK_ENV, Event, Job, Kind, Task, run_task, worker_init
from .core.files import read_config
from .errors import ArgumentError

__all__ = ["Job", "JobStatus", "JobReport", "BatchReport", "load_jobs", "run_batch", "describe_jobs", "EXECUTORS",
           "KILL_HOOK_ENV"]

log = logging.getLogger(__name__)

#: Where jobs run: ``local`` worker processes, or ``ray`` (``pip install 'cloth-usd[ray]'``).
EXECUTORS = ("local", "ray")

_STAGE_SUFFIXES = {".usd", ".usda", ".usdc", ".usdz"}
_JOB_KEYS = ("name", "stage", "output", "frames", "garments", "tier", "models", "body_model", "joint_map", "strict")
_DEFAULT_KEYS = ("frames", "garments", "tier", "models", "body_model", "joint_map", "strict")
_FILE_KEYS = ("out_dir", "defaults", "jobs")
def _frames_token(frames: str | None) -> str:
    if frames is None:
        return "all"
    from .baker import parse_frames

    r = parse_frames(frames)
    return f"{r.start:.10g}-{r.end:.10g}" + ("" if r.step == 1.0 else f"x{r.step:.10g}")


def _default_outputs(entries: list[dict]) -> None:
    """Give every entry without an output ``<out dir>/<base>.<tier>.<frames>[.g<hash>].usdc``.

    ``base`` is the stage's stem, prefixed with its parent folders' names only where
    two stages of the same stem would share an output folder.
    """
    todo = [e for e in entries if e.get("output") is None]
    depth = {id(e): 0 for e in todo}

    def base(e: dict) -> str:
        stage: Path = e["stage"]
        parents = stage.resolve().parent.parts[len(stage.resolve().parent.parts) - depth[id(e)]:]
        return "_".join([*parents, stage.stem]) if depth[id(e)] else stage.stem

    def name(e: dict) -> Path:
        folder = Path(e["out_dir"]) if e.get("out_dir") else e["stage"].parent
        token = f"{base(e)}.{e.get('tier') or 'skinning'}.{_frames_token(e.get('frames'))}"
        if e.get("garments"):
            token += ".g" + hashlib.sha256("\n".join(sorted(e["garments"])).encode()).hexdigest()[:8]
        return folder / f"{token}.usdc"

    for _ in range(64):
        seen: dict[Path, list[dict]] = {}
        for e in todo:
            seen.setdefault(name(e).resolve(), []).append(e)
        clashes = [group for group in seen.values() if len({g["stage"].resolve() for g in group}) > 1]
        if not clashes:
            break
        for group in clashes:
            for e in group:
                depth[id(e)] += 1
    for e in todo:
        e["output"] = name(e)


def _as_tuple(value: Any, key: str, where: str) -> tuple[str, ...] | None:
    if value is None:
        return None
    if isinstance(value, str):
        return (value,)
    if isinstance(value, (list, tuple)) and all(isinstance(v, str) for v in value):
        return tuple(value)
    raise ArgumentError(f"{where}: '{key}' must be a string or a list of strings, got {value!r}")


def _check_keys(table: dict, valid: Sequence[str], where: str) -> None:
    unknown = sorted(set(table) - set(valid))
    if unknown:
        raise ArgumentError(f"{where}: unknown key(s) {', '.join(unknown)} (valid: {', '.join(valid)})")


def _entries_from_file(path: Path) -> tuple[list[dict], dict, str | None]:
    """Raw job tables, file defaults and out_dir of a .toml/.json/.txt job file."""
    where = str(path)
    try:
        text = path.read_text()
    except OSError as exc:
        raise ArgumentError(f"{path}: cannot read the job file ({exc.strerror})") from None
    if path.suffix == ".txt":
        lines = (line.split("#", 1)[0].strip() for line in text.splitlines())
        return [{"stage": line} for line in lines if line], {}, None
    data = read_config(path, "the job file", text=text)
    if isinstance(data, list):
        data = {"jobs": data}
    if not isinstance(data, dict):
        raise ArgumentError(f"{path}: expected a table with 'jobs' (a list of tables) or a list of jobs")
    _check_keys(data, _FILE_KEYS, where)
    jobs = data.get("jobs")
    if not isinstance(jobs, list) or not all(isinstance(j, dict) for j in jobs):
        raise ArgumentError(f"{path}: 'jobs' must be a list of tables, each with at least a 'stage'")
    defaults = data.get("defaults", {})
    if not isinstance(defaults, dict):
        raise ArgumentError(f"{path}: 'defaults' must be a table")
    _check_keys(defaults, _DEFAULT_KEYS, f"{where} [defaults]")
    for i, job in enumerate(jobs):
        _check_keys(job, _JOB_KEYS, f"{where} job {i + 1}")
    out_dir = data.get("out_dir")
    if out_dir is not None and not isinstance(out_dir, str):
        raise ArgumentError(f"{path}: 'out_dir' must be a string")
    return [dict(j) for j in jobs], dict(defaults), out_dir


def _expand(spec: str) -> list[Path]:
    """A stage path, or the stages a glob matches (sorted)."""
    path = Path(spec)
    if path.exists():
        if path.suffix not in _STAGE_SUFFIXES:
            raise ArgumentError(f"{spec}: not a job file (.toml, .json, .txt) or a USD stage "
                                f"({', '.join(sorted(_STAGE_SUFFIXES))})")
        return [path]
    if glob.has_magic(spec):
        found = sorted(Path(p) for p in glob.glob(spec, recursive=True) if Path(p).suffix in _STAGE_SUFFIXES)
        if not found:
            raise ArgumentError(f"{spec}: the pattern matches no USD stage")
        return found
    raise ArgumentError(f"{spec}: no such file; pass a job file (.toml, .json, .txt), stages or a glob")


def load_jobs(sources: str | Path | Sequence[str | Path], *, out_dir: str | Path | None = None,
              frames: str | None = None, garments: Sequence[str] | None = None, tier: str | None = None,
              models: str | Sequence[str] | None = None, body_model: str | None = None,
              joint_map: str | None = None, strict: bool | None = None) -> list[Job]:
    """Read jobs from job files, stage paths and globs.

    A TOML or JSON job file holds ``jobs`` (a list of tables with ``stage`` and
    optionally ``name``, ``output``, ``frames``, ``garments``, ``tier``, ``models``,
    ``body_model``, ``joint_map``, ``strict``), optional ``defaults`` (the same keys but ``name``, ``stage``,
    ``output``) and ``out_dir``; relative paths are relative to the file. A ``.txt``
    lists stage paths, one a line (``#`` comments). Anything else is a stage or a glob.

    Keyword arguments are the defaults of jobs that give none (a job file's own
    ``defaults`` and ``out_dir`` come first). A job without ``output`` gets
    ``<out_dir>/<stage stem>.<tier>.<frames>.usdc`` (the stage's folder without an
    out_dir; a ``.g<hash>`` part when it names garments).

    Raises:
        ArgumentError: an unreadable or malformed job file, a bad frame range or tier,
            a pattern that matches nothing, two jobs with one output or one name.
    """
    from .baker import parse_frames, parse_tier

    if isinstance(sources, (str, Path)):
        sources = [sources]
    cli = {"frames": frames, "garments": _as_tuple(garments, "garments", "--garment"), "tier": tier,
           "models": _as_tuple(models, "models", "--models"), "body_model": body_model, "joint_map": joint_map,
           "strict": strict}
    entries: list[dict] = []
    for spec in sources:
        path = Path(spec)
        if path.suffix in (".toml", ".json", ".txt") and path.is_file():
            raw, defaults, file_out = _entries_from_file(path)
            base = path.parent
            where = str(path)
        else:
            raw, defaults, file_out, base, where = ([{"stage": str(p)} for p in _expand(str(spec))], {},
                                                    None, Path("."), str(spec))
        for i, job in enumerate(raw):
            label = f"{where} job {i + 1}" if len(raw) > 1 else where
            if not isinstance(job.get("stage"), str):
                raise ArgumentError(f"{label}: needs 'stage', the path of a USD stage")
            e: dict[str, Any] = {"label": label}
            for key in _DEFAULT_KEYS:
                value = job.get(key, defaults.get(key))
                if key in ("garments", "models"):
                    value = _as_tuple(value, key, label)
                    if key == "models" and value is not None:
                        value = tuple(str(base / m) for m in value)
                elif key in ("body_model", "joint_map") and value is not None:
                    value = str(base / value)
                elif key == "strict" and value is not None and not isinstance(value, bool):
                    raise ArgumentError(f"{label}: strict must be true or false, got {value!r}")
                e[key] = value if value is not None else cli[key]
            e["stage"] = base / job["stage"]
            e["output"] = base / job["output"] if job.get("output") else None
            e["name"] = job.get("name")
            e["out_dir"] = str(base / file_out) if file_out else (str(out_dir) if out_dir else None)
            if e["frames"] is not None:
                try:
                    parse_frames(str(e["frames"]))
                except ArgumentError as exc:
                    raise ArgumentError(f"{label}: {exc}") from None
                e["frames"] = str(e["frames"])
            try:
                parse_tier(e["tier"])
            except ArgumentError as exc:
                raise ArgumentError(f"{label}: {exc}") from None
            entries.append(e)
    if not entries:
        raise ArgumentError(f"{', '.join(map(str, sources)) or 'no sources'}: no jobs")
    _default_outputs(entries)
    jobs, outputs, names = [], {}, set()
    for e in entries:
        key = Path(e["output"]).resolve()
        if key in outputs:
            raise ArgumentError(f"{e['label']}: writes {e['output']}, as {outputs[key]} does; give each job "
                                "its own output")
        name = e["name"] or Path(e["output"]).name.removesuffix(Path(e["output"]).suffix)
        if name in names:
            raise ArgumentError(f"{e['label']}: job name '{name}' is used twice; give each job its own name")
        names.add(name)
        outputs[key] = e["label"]
        jobs.append(Job(name=name, stage=Path(e["stage"]), output=Path(e["output"]), frames=e["frames"],
                        garments=e["garments"], tier=e["tier"], models=e["models"], body_model=e["body_model"],
                        joint_map=e["joint_map"], strict=bool(e["strict"])))
    return jobs


def _chunk_tasks(job: Job, frames: str, size: int, force: bool) -> list[Task]:
    """The frame chunks of a job, each a cache layer in ``.<output name>.chunks/``."""
    from .baker import FrameRange, parse_frames

    whole = parse_frames(frames)
    times = whole.times()
    folder = job.output.parent / f".{job.output.name}.chunks"
    tasks = []
    for lo in range(0, times.shape[0], size):
        part = FrameRange(float(times[lo]), float(times[min(lo + size, times.shape[0]) - 1]), whole.step)
        path = folder / f"{part.start:.10g}_{part.end:.10g}{job.output.suffix}"
        tasks.append(Task(Kind.CHUNK, job, path, frames=str(part), force=force))
    return tasks


# ---------------------------------------------------------------------------- report


class JobStatus(str, Enum):
    """How a job ended."""

    DONE = "done"
    SKIPPED = "skipped"
    """Its output was already up to date."""
    FAILED = "failed"


@dataclass(frozen=True)
class JobReport:
    """The outcome of one job."""

    name: str
    stage: str
    output: str
    status: JobStatus
    error: str | None
    """The one-line error of a failed job."""
    seconds: float
    """Worker time spent on it, all attempts and chunks [s]."""
    frames: int
    attempts: int
    """Task runs, including retries of killed workers."""
    chunks: int
    """Frame chunks it was baked in (0: baked whole)."""
    garments: tuple[dict, ...] = ()
    """Per garment: prim, tier, vertices, frames, mean_body_distance_mm, max_displacement_mm, max_offset_mm."""
    warnings: tuple[str, ...] = ()

    def as_dict(self) -> dict:
        return {"name": self.name, "stage": self.stage, "output": self.output, "status": self.status.value,
                "error": self.error, "seconds": round(self.seconds, 3), "frames": self.frames,
                "attempts": self.attempts, "chunks": self.chunks, "garments": list(self.garments),
                "warnings": list(self.warnings)}


@dataclass(frozen=True)
class BatchReport:
    """The outcome of :func:`run_batch`."""

    jobs: tuple[JobReport, ...]
    seconds: float
    """Wall time of the batch [s]."""
    executor: str
    workers: int

    def count(self, status: JobStatus) -> int:
        return sum(j.status is status for j in self.jobs)

    @property
    def failed(self) -> tuple[JobReport, ...]:
        return tuple(j for j in self.jobs if j.status is JobStatus.FAILED)

    def as_dict(self) -> dict:
        """JSON-able: counts, settings and one entry per job."""
        return {"format_version": 1, "executor": self.executor, "workers": self.workers,
                "seconds": round(self.seconds, 3),
                "counts": {s.value: self.count(s) for s in JobStatus}, "jobs": [j.as_dict() for j in self.jobs]}

    def write(self, path: str | Path) -> Path:
        """Write :meth:`as_dict` as JSON (atomically)."""
        path = Path(path)
        tmp = path.with_name(f".{path.name}.tmp")
        tmp.write_text(json.dumps(self.as_dict(), indent=2) + "\n")
        os.replace(tmp, path)
        return path

    def summary(self) -> list[str]:
        """Lines for a terminal: counts, then each failed job with its error, then warnings."""
        lines = [f"{len(self.jobs)} jobs: {self.count(JobStatus.DONE)} done, "
                 f"{self.count(JobStatus.SKIPPED)} skipped (up to date), {self.count(JobStatus.FAILED)} failed "
                 f"({self.seconds:.1f} s, {self.workers} {self.executor} workers)"]
        lines += [f"failed {j.name}: {j.error}" for j in self.failed]
        lines += [f"warning {j.name}: {w}" for j in self.jobs for w in j.warnings]
        return lines


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
    garments: dict = field(default_factory=dict)
    warnings: list[str] = field(default_factory=list)

    def report(self) -> JobReport:
        return JobReport(name=self.job.name, stage=str(self.job.stage), output=str(self.job.output),
                         status=self.status or JobStatus.FAILED, error=self.error, seconds=self.seconds,
                         frames=self.frames, attempts=self.attempts, chunks=len(self.chunks),
                         garments=tuple(self.garments.values()), warnings=tuple(self.warnings))

    def add(self, result: dict) -> None:
        for g in result.get("garments", ()):
            old = self.garments.get(g["prim"])
            if old is None:
                self.garments[g["prim"]] = dict(g)
            else:  # another chunk of the same garment
                old["frames"] += g["frames"]
                for key in ("max_displacement_mm", "max_offset_mm"):
                    old[key] = max(old[key], g[key])
        self.warnings += [w for w in result.get("warnings", ()) if w not in self.warnings]



class _Worker:
    def __init__(self, ctx) -> None:
        self.conn, child = ctx.Pipe()
        # A forkserver child inherits the server's environment, not ours: pass the hook on.
        hook = os.environ.get(KILL_HOOK_ENV)
        self.process = ctx.Process(target=_worker_main, args=(child, hook), daemon=True)
        self.process.start()
        child.close()
        self.tid: int | None = None
        self.since = 0.0


def _worker_main(conn, kill_hook: str | None = None) -> None:
    """A local worker: run tasks from the pipe until it closes."""
    signal.signal(signal.SIGINT, signal.SIG_IGN)  # the parent handles Ctrl-C
    if kill_hook:
        os.environ[KILL_HOOK_ENV] = kill_hook
    else:
        os.environ.pop(KILL_HOOK_ENV, None)
    worker_init()
    while True:
        try:
            message = conn.recv()
        except (EOFError, OSError):
            return
        if message is None:
            return
        tid, task = message
        conn.send((tid, run_task(task)))


def _death(exitcode: int | None) -> str:
    if exitcode is not None and exitcode < 0:
        try:
            return f"killed by {signal.Signals(-exitcode).name}"
        except ValueError:
            return f"killed by signal {-exitcode}"
    return f"exited with code {exitcode}"


class _LocalPool:
    """Worker processes, one task each at a time; a dead worker is replaced.

    Workers fork from a server process that has imported cloth_usd once (the
    ``forkserver`` start method), so starting or replacing one is quick and never
    forks a parent that holds threads.
    """

    def __init__(self, workers: int, job_timeout: float | None) -> None:
        self.ctx = multiprocessing.get_context("forkserver")
        self.ctx.set_forkserver_preload(["cloth_usd.batch", "cloth_usd.baker", "cloth_usd.usd.read",
                                         "cloth_usd.usd.write", "tqdm.auto"])
        self.size = workers
        self.timeout = job_timeout
        self.workers: list[_Worker] = []

    def free(self) -> int:
        return self.size - sum(w.tid is not None for w in self.workers)

    def submit(self, tid: int, task: Task) -> None:
        worker = next((w for w in self.workers if w.tid is None), None)
        if worker is None:
            worker = _Worker(self.ctx)
            self.workers.append(worker)
        worker.tid, worker.since = tid, time.monotonic()
        worker.conn.send((tid, task))

    def wait(self, timeout: float) -> list[Event]:
        busy = [w for w in self.workers if w.tid is not None]
        if not busy:
            return []
        multiprocessing.connection.wait([w.conn for w in busy] + [w.process.sentinel for w in busy], timeout)
        events = []
        for w in busy:
            try:
                if w.conn.poll():
                    tid, result = w.conn.recv()
                    events.append(Event(tid, result))
                    w.tid = None
                    continue
            except (EOFError, OSError):
                pass
            if not w.process.is_alive():
                w.process.join()
                events.append(Event(w.tid, None, died=f"worker {_death(w.process.exitcode)}"))
                self._drop(w)
            elif self.timeout is not None and time.monotonic() - w.since > self.timeout:
                w.process.kill()
                w.process.join()
                events.append(Event(w.tid, None, died=f"timed out after {self.timeout:g} s (worker killed)"))
                self._drop(w)
        return events

    def _drop(self, worker: _Worker) -> None:
        worker.conn.close()
        self.workers.remove(worker)

    def close(self) -> None:
        for w in self.workers:
            try:
                w.conn.send(None)
            except OSError:
                pass
        deadline = time.monotonic() + 5.0
        for w in self.workers:
            w.process.join(max(0.0, deadline - time.monotonic()))
            if w.process.is_alive():
                w.process.kill()
                w.process.join()
            w.conn.close()
        self.workers.clear()


# ---------------------------------------------------------------------------- driver


def run_batch(jobs: Sequence[Job], *, executor: str = "local", workers: int | None = None, retries: int = 2,
              chunk_frames: int | None = None, force: bool = False, address: str | None = None,
              job_timeout: float | None = None, on_job: Callable[[JobReport], None] | None = None
              ) -> BatchReport:
    """Run jobs; a job's failure fails it alone.

    Args:
        jobs: from :func:`load_jobs`.
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
        from .batch_ray import RayPool

        pool: Any = RayPool(workers=workers, retries=retries, address=address, job_timeout=job_timeout)
        workers = pool.size
    else:
        pool = _LocalPool(workers, job_timeout)
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
                    state.seconds += float(result.get("seconds", 0.0))
                if result is None or (result["status"] == "error" and result.get("retry")):
                    why = event.died or result["error"]
                    attempts[event.tid] = attempts.get(event.tid, 0) + 1
                    if not event.final and attempts[event.tid] <= retries:
                        log.warning("job %s: %s task %s; trying again", task.job.name, task.kind.value, why)
                        queue.appendleft((event.tid, task))
                    else:
                        runs = retries + 1 if event.final else attempts[event.tid]
                        finish(index, JobStatus.FAILED, f"{task.kind.value} task: {why} ({runs} attempts)")
                        _clean_temps(task.output)
                    continue
                if result["status"] == "error":
                    finish(index, JobStatus.FAILED, result["error"])
                    continue
                _advance(state, index, task, result, chunk_frames, force, push, finish)
    except BaseException:
        pool.close()
        raise
    pool.close()
    return BatchReport(jobs=tuple(s.report() for s in states), seconds=time.perf_counter() - began,
                       executor=executor, workers=workers)


def _advance(state: _JobState, index: int, task: Task, result: dict, chunk_frames: int | None,
             force: bool, push: Callable[[int, Task], None], finish: Callable[..., None]) -> None:
    """A task of a job succeeded: queue what follows, or finish the job."""
    job = state.job
    if task.kind is Kind.PLAN:
        state.inputs_sha256 = result["inputs_sha256"]
        state.frames = result["count"]
        if result["status"] == "skipped":
            finish(index, JobStatus.SKIPPED)
        elif result["count"] <= (chunk_frames or 0):
            push(index, Task(Kind.BAKE, job, job.output, frames=result["frames"], force=True))
        else:
            state.chunks = _chunk_tasks(job, result["frames"], chunk_frames or 1, force)
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
        state.frames = result["frames"]
        finish(index, JobStatus.SKIPPED if result["status"] == "skipped" else JobStatus.DONE)


def _clean_temps(path: Path) -> None:
    """Best effort: the temporary file a killed last attempt left (the parent may not see it on Ray)."""
    try:
        from .usd.write import remove_stale_temps

        remove_stale_temps(path)
    except OSError:
        pass


def describe_jobs(jobs: Iterable[Job]) -> list[str]:
    """One line per job for ``--dry-run``: its name and the ``cloth-usd bake`` command that runs it."""
    import shlex

    return [f"{job.name}: {shlex.join(job.bake_command())}" for job in jobs]


"""Headless batch bakes: many jobs, in local worker processes or on Ray.

A :class:`Job` is one bake (stage, garments, frame range, tier, output) and an
idempotent unit of work: its output path is fixed before it runs, the cache records a
digest of everything it was baked from (:func:`cloth_usd.baking.bake_plan`), and a job
whose output already holds that digest is skipped. So a batch can be run again after
any failure and only redoes what is missing, and a farm scheduler (Deadline, OpenCue)
can run the same jobs itself, one ``cloth-usd bake`` each (:meth:`Job.bake_command`).

Jobs come from a TOML or JSON job file, a text file of stage paths, or stage paths and
globs (:func:`load_jobs`, :mod:`.jobs`). :func:`run_batch` (:mod:`.driver`) runs them:

- each job is a task (:mod:`.tasks`); with ``chunk_frames`` a long job becomes a plan task,
  one task per frame chunk (each writes its own cache layer into ``.<output>.chunks/``
  beside the output) and a stitch task that joins them into the output and removes the chunks;
- a worker (:mod:`.pool`, :mod:`.ray`) keeps one :class:`~cloth_usd.baking.ModelCache`, so
  each body model and model bundle is loaded once per worker and each garment bound once;
- a worker that dies (killed, out of memory) or passes ``job_timeout`` costs its task
  one attempt; the task runs again, up to ``retries`` more times. Layers are written
  atomically, so a killed task leaves no partial output, only a temporary file the
  next attempt removes;
- errors in a job (a broken stage, a missing bundle) fail that job alone, with its
  one-line message, and are not retried; :mod:`.report` holds what comes back.

Run one batch per output folder at a time: two batches writing the same outputs would
race.
"""

from .driver import EXECUTORS, run_batch
from .jobs import Job, describe_jobs, load_jobs
from .report import BatchReport, JobReport, JobStatus
from .tasks import KILL_HOOK_ENV

__all__ = ["Job", "JobStatus", "JobReport", "BatchReport", "load_jobs", "run_batch", "describe_jobs", "EXECUTORS",
           "KILL_HOOK_ENV"]

"""What a batch reports: a :class:`JobReport` per job, the :class:`BatchReport`, its JSON."""

from __future__ import annotations

import json
import os
from dataclasses import dataclass
from enum import Enum
from pathlib import Path

from ..core.provenance import GarmentReport
from ..errors import OutputWriteError

__all__ = ["JobStatus", "JobReport", "BatchReport"]


class JobStatus(str, Enum):
    """How a job ended."""

    DONE = "done"
    SKIPPED = "skipped"
    """Its output was already up to date."""
    FAILED = "failed"


def _garment_json(g: GarmentReport) -> dict:
    return {"prim": g.prim_path, "tier": g.tier.value, "vertices": g.vertices, "frames": g.frames,
            "mean_body_distance_mm": round(g.mean_body_distance_mm, 3),
            "max_displacement_mm": round(g.max_displacement_mm, 3), "max_offset_mm": round(g.max_offset_mm, 3)}


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
    garments: tuple[GarmentReport, ...] = ()
    """Per garment, its chunks merged (:meth:`~cloth_usd.core.provenance.GarmentReport.merged`)."""
    warnings: tuple[str, ...] = ()

    def as_dict(self) -> dict:
        return {"name": self.name, "stage": self.stage, "output": self.output, "status": self.status.value,
                "error": self.error, "seconds": round(self.seconds, 3), "frames": self.frames,
                "attempts": self.attempts, "chunks": self.chunks, "garments": [_garment_json(g) for g in self.garments],
                "warnings": list(self.warnings)}


@dataclass(frozen=True)
class BatchReport:
    """The outcome of :func:`~cloth_usd.batch.run_batch`."""

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
        """Write :meth:`as_dict` as JSON (atomically).

        Raises:
            OutputWriteError: the file cannot be written (a missing folder, no permission, a full disk).
        """
        path = Path(path)
        tmp = path.with_name(f".{path.name}.tmp")
        try:
            tmp.write_text(json.dumps(self.as_dict(), indent=2) + "\n")
            os.replace(tmp, path)
        except OSError as exc:
            tmp.unlink(missing_ok=True)
            raise OutputWriteError(f"--report {path}: cannot write the report ({exc.strerror or exc})") from None
        return path

    def summary(self) -> list[str]:
        """Lines for a terminal: counts, then each failed job with its error, then warnings."""
        lines = [f"{len(self.jobs)} jobs: {self.count(JobStatus.DONE)} done, "
                 f"{self.count(JobStatus.SKIPPED)} skipped (up to date), {self.count(JobStatus.FAILED)} failed "
                 f"({self.seconds:.1f} s, {self.workers} {self.executor} workers)"]
        lines += [f"failed {j.name}: {j.error}" for j in self.failed]
        lines += [f"warning {j.name}: {w}" for j in self.jobs for w in j.warnings]
        return lines

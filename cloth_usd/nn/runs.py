"""Run folders: what a training run writes and how it is read back.

A run folder holds::

    run.json        tier, TrainConfig, model config, data set (path, manifest sha256), coarse run
    stats.npz       normalisation statistics (also inside the model, as buffers)
    checkpoint.pt   the last finished epoch: model, optimizer, RNG states, history (resume)
    best.pt         the model of the lowest validation loss (export reads this)
    history.csv     per epoch: train loss, val loss, val error [mm], lr, seconds (also .json)
    curve.png       the validation curve

Checkpoints are torch state dicts (our own files, written atomically); data never goes
through pickle.
"""

from __future__ import annotations

import csv
import dataclasses
import errno
import io
import json
import math
import os
import tempfile
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Callable, Mapping, Sequence

import torch

from ..core.files import file_sha256
from ..core.heading import Heading
from ..core.scene import Tier
from ..errors import ArgumentError, OutputWriteError
from .config import TrainConfig, build_model, trainable
from .models import CoarseGenerator, DetailGenerator

__all__ = ["RUN", "STATS", "CHECKPOINT", "BEST", "HISTORY", "CURVE", "RUN_FORMAT", "Run", "EpochRecord",
           "TrainResult", "read_run_json", "resume_settings", "load_run", "torch_load", "atomic_save",
           "atomic_text", "write_history", "record_epoch", "rng_state", "set_rng_state", "coarse_run_record"]

RUN = "run.json"
STATS = "stats.npz"
CHECKPOINT = "checkpoint.pt"
BEST = "best.pt"
HISTORY = "history"
CURVE = "curve.png"
#: Layout of run folders; bump when a file changes meaning.
RUN_FORMAT = 1


@dataclass(frozen=True)
class Run:
    """A trained run folder, loaded."""

    path: Path
    tier: Tier
    config: TrainConfig
    info: Mapping[str, Any]
    """The parsed ``run.json``."""
    model: CoarseGenerator | DetailGenerator
    """The best-validation model, in eval mode."""
    epoch: int
    """The epoch ``model`` comes from."""


def read_run_json(run_dir: Path) -> dict:
    path = run_dir / RUN
    try:
        info = json.loads(path.read_text())
    except OSError:
        raise ArgumentError(f"{run_dir}: not a training run (no {RUN})") from None
    except ValueError as exc:
        raise ArgumentError(f"{path}: unreadable ({exc})") from exc
    if info.get("format") != RUN_FORMAT:
        raise ArgumentError(f"{path}: run format {info.get('format')!r}, this cloth-usd reads {RUN_FORMAT}")
    if isinstance(info.get("config"), dict):  # runs from before the heading key saw the world frame
        info["config"].setdefault("heading", Heading.WORLD.value)
    return info


def resume_settings(run_dir: str | Path, *, epochs: int | None = None) -> tuple[TrainConfig, str | None]:
    """The config (with ``epochs`` if given) and coarse run of an existing run folder, to resume it."""
    info = read_run_json(Path(run_dir))
    raw = dict(info["config"])
    if epochs is not None:
        raw["epochs"] = epochs
    return TrainConfig.from_mapping(raw, str(Path(run_dir) / RUN)), (info.get("coarse_run") or {}).get("path")


def torch_load(path: Path, device: torch.device | str) -> dict:
    try:
        return torch.load(path, map_location=device, weights_only=True)
    except FileNotFoundError:
        raise ArgumentError(f"{path}: missing (has the run finished an epoch?)") from None
    except Exception as exc:  # a truncated or foreign file
        raise ArgumentError(f"{path}: unreadable checkpoint ({exc})") from exc


def load_run(run_dir: str | Path, *, device: torch.device | str = "cpu", best: bool = True) -> Run:
    """Load a run's best (or last) model.

    Raises:
        ArgumentError: naming the folder or file, when it is not a finished run.
    """
    run_dir = Path(run_dir)
    info = read_run_json(run_dir)
    tier = trainable(info["tier"], f"{run_dir / RUN}: tier")
    config = TrainConfig.from_mapping(info["config"], str(run_dir / RUN))
    model = build_model(tier, config).to(device)
    state = torch_load(run_dir / (BEST if best else CHECKPOINT), device)
    model.load_state_dict(state["model"])
    return Run(path=run_dir, tier=tier, config=config, info=info, model=model.eval(), epoch=int(state["epoch"]))


def _write_failed(path: Path, exc: OSError) -> OutputWriteError:
    if exc.errno == errno.ENOSPC:
        return OutputWriteError(f"{path}: no space left on device; free some space in '{path.parent}' and run "
                                "again; the file was left as it was")
    return OutputWriteError(f"{path}: could not be written ({exc.strerror or exc}); the file was left as it was")


def _atomic(write: Callable[[str], None], path: Path) -> None:
    """``write(temporary path)``, then rename it to ``path``; OutputWriteError (and no
    temporary file) when either fails."""
    tmp = None
    try:
        fd, tmp = tempfile.mkstemp(prefix=f".{path.name}.", suffix=".tmp", dir=path.parent)
        os.close(fd)
        write(tmp)
        os.replace(tmp, path)
    except OSError as exc:
        if tmp is not None:
            Path(tmp).unlink(missing_ok=True)
        raise _write_failed(path, exc) from None
    except BaseException:
        if tmp is not None:
            Path(tmp).unlink(missing_ok=True)
        raise


def atomic_save(obj: Any, path: Path) -> None:
    """``torch.save`` to a temporary file beside ``path``, renamed into place.

    Raises:
        OutputWriteError: the file could not be written (a full disk); nothing is left behind.
    """
    buf = io.BytesIO()  # serialised first, so a full disk is Python's OSError, not torch's RuntimeError
    torch.save(obj, buf)

    def write(tmp: str) -> None:
        with open(tmp, "wb") as fh:
            fh.write(buf.getbuffer())

    _atomic(write, path)


def atomic_text(text: str, path: Path) -> None:
    """``text`` to a temporary file beside ``path``, renamed into place.

    Raises:
        OutputWriteError: the file could not be written (a full disk); nothing is left behind.
    """
    def write(tmp: str) -> None:
        with open(tmp, "w") as fh:
            fh.write(text)

    _atomic(write, path)


@dataclass(frozen=True)
class EpochRecord:
    """One line of the training history."""

    epoch: int
    train_loss: float
    """Mean training loss (MSE in output-scale units)."""
    val_loss: float
    """Validation loss, same units (NaN without validation data)."""
    val_mm: float
    """Mean per-vertex validation error [mm] of the tier's output against its target
    (coarse: the coarse target; detail: the simulation), before the post-process."""
    lr: float
    seconds: float


@dataclass(frozen=True)
class TrainResult:
    """What :func:`train` returns."""

    run_dir: Path
    history: tuple[EpochRecord, ...]
    best_epoch: int
    model: CoarseGenerator | DetailGenerator
    """The last epoch's model (the best one is in ``best.pt``)."""

    @property
    def best(self) -> EpochRecord:
        """The best epoch's record (the last one when no epoch is marked best)."""
        return next((r for r in self.history if r.epoch == self.best_epoch), self.history[-1])


def write_history(run_dir: Path, history: Sequence[EpochRecord]) -> None:
    rows = [dataclasses.asdict(r) for r in history]
    atomic_text(json.dumps(rows, indent=1) + "\n", run_dir / f"{HISTORY}.json")
    buf = io.StringIO()
    writer = csv.DictWriter(buf, fieldnames=[f.name for f in dataclasses.fields(EpochRecord)])
    writer.writeheader()
    writer.writerows(rows)
    atomic_text(buf.getvalue(), run_dir / f"{HISTORY}.csv")


def record_epoch(run_dir: Path, model: torch.nn.Module, optimizer: torch.optim.Optimizer,
                  history: list[EpochRecord], record: EpochRecord, best_loss: float, best_epoch: int
                  ) -> tuple[float, int]:
    """Append ``record``; write ``best.pt`` when it is the best so far (validation loss, or the
    training loss without validation), the resumable checkpoint and the history files.
    Returns the new ``(best_loss, best_epoch)``."""
    history.append(record)
    score = record.val_loss if not math.isnan(record.val_loss) else record.train_loss
    if score <= best_loss or best_epoch < 0:
        best_loss, best_epoch = score, record.epoch
        atomic_save({"epoch": record.epoch, "model": model.state_dict(), "val_loss": record.val_loss}, run_dir / BEST)
    atomic_save({"epoch": record.epoch, "model": model.state_dict(), "optimizer": optimizer.state_dict(),
                  "rng": rng_state(), "history": [dataclasses.asdict(r) for r in history],
                  "best_loss": best_loss, "best_epoch": best_epoch}, run_dir / CHECKPOINT)
    write_history(run_dir, history)
    return best_loss, best_epoch


def rng_state() -> dict:
    state = {"torch": torch.get_rng_state()}
    if torch.cuda.is_available():
        state["cuda"] = torch.cuda.get_rng_state_all()
    return state


def set_rng_state(state: Mapping[str, Any]) -> None:
    torch.set_rng_state(state["torch"].cpu())
    if "cuda" in state and torch.cuda.is_available():
        torch.cuda.set_rng_state_all([s.cpu() for s in state["cuda"]])


def coarse_run_record(coarse: Run) -> dict:
    return {"path": str(coarse.path.resolve()), "best_sha256": file_sha256(coarse.path / BEST),
            "epoch": coarse.epoch}

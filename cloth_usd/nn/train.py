"""Training of the coarse and detail generators (docs/method.md): seeded, resumable, logged.

``cloth-usd train coarse|detail --data DATA --out RUN`` calls :func:`train`. Batches are
frames of one sequence (they share one garment graph); inputs are built through
:mod:`cloth_usd.core.pipeline`, the runtime's own feature path (see
:mod:`cloth_usd.nn.data`). Loss: docs/method.md's MSE of the displacement, measured in units
of the model's output scale (the per-axis RMS of the training targets), so both tiers'
losses are O(1).

A run folder holds::

    run.json        tier, TrainConfig, model config, data set (path, manifest sha256), coarse run
    stats.npz       normalisation statistics (also inside the model, as buffers)
    checkpoint.pt   the last finished epoch: model, optimizer, RNG states, history (resume)
    best.pt         the model of the lowest validation loss (export reads this)
    history.csv     per epoch: train loss, val loss, val error [mm], lr, seconds (also .json)
    curve.png       the validation curve

Resuming (``resume=True``) restarts after the last finished epoch and continues
bit-identically: every epoch's data order comes from ``(seed, epoch)`` alone and the
model, optimizer and torch RNG states are restored. Checkpoints are torch state dicts
(our own files, written atomically); data never goes through pickle.

Shape letters: B frames of a batch, N garment vertices.
"""

from __future__ import annotations

import csv
import dataclasses
import enum
import io
import json
import logging
import math
import os
import tempfile
import time
from collections import deque
from concurrent.futures import ThreadPoolExecutor
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Callable, Iterable, Mapping, Sequence

import numpy as np
import torch

from ..core.body import BodyModel
from ..core.files import file_sha256, read_config
from ..core.graph import MeshGraph
from ..core.heading import Heading
from ..core.pipeline import CoarseBase
from ..core.scene import Tier
from ..errors import ArgumentError, ClothUsdError
from ..runtime.io import COARSE_INPUTS, DETAIL_INPUTS, coarse_inputs, detail_inputs
from .data import (
    Clip,
    CoarseTarget,
    DataSet,
    Moments,
    Split,
    Statistics,
    coarse_example,
    detail_example,
    load_dataset,
    plan_batches,
    with_coarse_target,
    with_heading,
)
from .models import CoarseConfig, CoarseGenerator, DetailConfig, DetailGenerator

__all__ = ["TRAINABLE_TIERS", "Objective", "CoarseInput", "TrainConfig", "load_train_config", "resume_settings",
           "EpochRecord", "TrainResult", "train", "load_run", "Run", "torch_coarse_fn", "torch_detail_fn",
           "pick_device", "plot_history"]

log = logging.getLogger(__name__)

RUN = "run.json"
STATS = "stats.npz"
CHECKPOINT = "checkpoint.pt"
BEST = "best.pt"
HISTORY = "history"
CURVE = "curve.png"
#: Layout of run folders; bump when a file changes meaning.
RUN_FORMAT = 1


#: The tiers that have a generator to train (skinning has no model).
TRAINABLE_TIERS = (Tier.COARSE, Tier.DETAIL)


def _trainable(tier: Tier | str, where: str = "tier") -> Tier:
    """``tier`` as a :class:`~cloth_usd.core.scene.Tier` of :data:`TRAINABLE_TIERS`.

    Raises:
        ArgumentError: naming ``where`` and the valid tiers.
    """
    try:
        chosen = Tier(tier)
    except ValueError:
        chosen = None
    if chosen not in TRAINABLE_TIERS:
        value = tier.value if isinstance(tier, Tier) else tier
        raise ArgumentError(f"{where} {value!r}: not a trainable tier "
                            f"(valid: {', '.join(t.value for t in TRAINABLE_TIERS)})")
    return chosen


class Objective(str, enum.Enum):
    """What a generator is trained to minimise."""

    SUPERVISED = "supervised"
    """The distance to simulated ground truth (a ``cloth-usd datagen`` data set)."""
    PHYSICS = "physics"
    """Coarse only: the garment's own energy at the output, no simulation
    (:mod:`cloth_usd.nn.physics_train`)."""


class CoarseInput(str, enum.Enum):
    """What the detail model is trained on as ``M_coarse``."""

    PREDICTED = "predicted"
    """The trained coarse model's prediction: what the detail model sees at inference."""
    TARGET = "target"
    """The coarse ground truth (Laplacian-smoothed simulation)."""


@dataclass(frozen=True)
class TrainConfig:
    """How one generator is trained (``--config`` file keys; defaults in brackets)."""

    epochs: int = 60
    """Passes over the training split."""
    lr: float = 1e-3
    """Adam learning rate of epoch 0."""
    lr_decay: float = 0.96
    """The learning rate is ``lr * lr_decay ** epoch``."""
    batch: int = 8
    """Frames per optimisation step (one sequence per step: a batch shares one garment graph)."""
    width: float = 1.0
    """Multiplier on every hidden width of the model (1: the paper's)."""
    decompose: bool = True
    """Magnitude x direction output (the paper); False is the 'no decomposition' ablation."""
    use_parser: bool = True
    """Detail only: the attribute parser (the paper); False is the 'no parser' ablation."""
    seed: int = 0
    """Seeds the initial weights and every epoch's data order."""
    grad_clip: float = 1.0
    """Clip the gradient norm to this (0: no clipping)."""
    stat_frames: int = 16
    """Frames per training sequence used for the normalisation statistics."""
    val_frames: int = 0
    """Frames per validation sequence, evenly spread (0: all)."""
    max_batches: int = 0
    """Stop every epoch after this many batches (0: the whole split; quick runs)."""
    max_frames: int = 0
    """Use only the first frames of every sequence (0: all; quick runs)."""
    coarse_input: CoarseInput = CoarseInput.PREDICTED
    """Detail only: train on the coarse model's prediction or on the coarse target."""
    prefetch: int = 2
    """Batches whose features are computed ahead in a worker thread (0: none)."""
    coarse_base: CoarseBase = CoarseBase.BODY
    """Coarse only: the displacement is added to ``I M_b`` (docs/method.md) or to the ``skinned``
    garment (a detail run takes its coarse run's)."""
    coarse_target: CoarseTarget = CoarseTarget.STORED
    """The coarse ground truth: the shards' Laplacian smoothing (docs/method.md) or ``taubin``
    (re-derived without shrinkage); the coarse model's target, and the detail model's
    ``M_coarse`` when ``coarse_input`` is ``target``."""
    objective: Objective = Objective.SUPERVISED
    """Supervised on simulated data, or ``physics`` (coarse only; :mod:`cloth_usd.nn.physics_train`)."""
    bending_scale: float = 1.0
    """Physics objective only: multiplies the material's bending stiffness (a stiffer
    bending makes the coarse tier drape without fine folds)."""
    heading: Heading = Heading.CANONICAL
    """Coarse only: the frame the models see the body in (a detail run takes its coarse
    run's): ``canonical`` turns every frame's body to face +Z (the garment turned with it), so
    the models give the same local garment whichever way a character faces; ``world`` is how
    runs before this key were trained (their run.json reads as ``world``)."""

    def __post_init__(self) -> None:
        for key, kind in (("coarse_input", CoarseInput), ("coarse_target", CoarseTarget), ("coarse_base", CoarseBase),
                          ("heading", Heading), ("objective", Objective)):
            value = getattr(self, key)
            if value not in {k.value for k in kind}:  # str enums: a member equals its value
                raise ArgumentError(f"TrainConfig: {key}={value!r} is not one of {', '.join(k.value for k in kind)}")
            object.__setattr__(self, key, kind(value))
        checks = {"epochs": self.epochs >= 1, "lr": self.lr > 0, "lr_decay": 0 < self.lr_decay <= 1,
                  "batch": self.batch >= 1, "width": self.width > 0, "grad_clip": self.grad_clip >= 0,
                  "stat_frames": self.stat_frames >= 1, "val_frames": self.val_frames >= 0,
                  "max_batches": self.max_batches >= 0, "max_frames": self.max_frames >= 0,
                  "prefetch": self.prefetch >= 0, "bending_scale": self.bending_scale > 0}
        bad = [k for k, ok in checks.items() if not ok]
        if bad:
            raise ArgumentError(f"TrainConfig: out of range: {', '.join(f'{k}={getattr(self, k)!r}' for k in bad)}")

    def to_json(self) -> dict:
        return {k: v.value if isinstance(v, enum.Enum) else v for k, v in dataclasses.asdict(self).items()}

    @classmethod
    def from_mapping(cls, raw: Mapping[str, Any], source: str = "config") -> "TrainConfig":
        """Build from a mapping; unknown keys are an error that names them and the valid ones."""
        known = {f.name for f in dataclasses.fields(cls)}
        unknown = sorted(set(raw) - known)
        if unknown:
            raise ArgumentError(f"{source}: unknown keys {unknown} (valid: {', '.join(sorted(known))})")
        try:
            return cls(**raw)
        except (TypeError, ValueError) as exc:
            raise ArgumentError(f"{source}: {exc}") from exc


def load_train_config(path: str | Path | None, **overrides: Any) -> TrainConfig:
    """A TrainConfig from a ``.json`` or ``.toml`` file (defaults when None), then ``overrides``."""
    raw: dict = {}
    if path is not None:
        path = Path(path)
        raw = read_config(path, "the --config training config")
        if not isinstance(raw, dict):
            raise ArgumentError(f"--config {path}: expected a table of TrainConfig keys")
    raw.update({k: v for k, v in overrides.items() if v is not None})
    return TrainConfig.from_mapping(raw, str(path) if path is not None else "config")


def resume_settings(run_dir: str | Path, *, epochs: int | None = None) -> tuple[TrainConfig, str | None]:
    """The config (with ``epochs`` if given) and coarse run of an existing run folder, to resume it."""
    info = _read_run_json(Path(run_dir))
    raw = dict(info["config"])
    if epochs is not None:
        raw["epochs"] = epochs
    return TrainConfig.from_mapping(raw, str(Path(run_dir) / RUN)), (info.get("coarse_run") or {}).get("path")


def model_config(tier: Tier | str, config: TrainConfig) -> CoarseConfig | DetailConfig:
    """The model config a TrainConfig asks for (paper widths times ``width``)."""
    if _trainable(tier) is Tier.COARSE:
        return CoarseConfig(width=config.width, decompose=config.decompose)
    return DetailConfig(width=config.width, decompose=config.decompose, use_parser=config.use_parser)


#: Initial bias of the magnitude head's output. With PyTorch's default init about half the
#: vertices start with a negative pre-activation, and at small widths often all of them:
#: ReLU then passes no gradient to the magnitude nor (m = 0) to the direction, and the
#: model never trains (seen at width 0.125). A bias of 1 starts every magnitude at one
#: output scale (the target's RMS).
MAGNITUDE_BIAS = 1.0


def build_model(tier: Tier | str, config: TrainConfig) -> CoarseGenerator | DetailGenerator:
    """A fresh model; seed torch before calling for reproducible weights."""
    mc = model_config(tier, config)
    model = CoarseGenerator(mc) if isinstance(mc, CoarseConfig) else DetailGenerator(mc)
    if model.head.magnitude is not None:
        with torch.no_grad():
            model.head.magnitude[-1].bias.fill_(MAGNITUDE_BIAS)
    return model


def pick_device(name: str | None) -> torch.device:
    """``cpu``, ``cuda`` (an error when unavailable) or ``auto``/None (cuda when available)."""
    if name in (None, "auto"):
        return torch.device("cuda" if torch.cuda.is_available() else "cpu")
    if name not in ("cpu", "cuda") and not str(name).startswith("cuda:"):
        raise ArgumentError(f"--device {name}: unknown (valid: auto, cpu, cuda)")
    if str(name).startswith("cuda") and not torch.cuda.is_available():
        raise ArgumentError(f"--device {name}: torch sees no CUDA device (torch {torch.__version__}); use cpu")
    return torch.device(name)


# ----------------------------------------------------------------------------- model calls


class _Tensors:
    """Named model inputs as tensors on one device; graph tensors are moved once per graph.

    The cache holds each graph it keys by ``id``, so a freed graph's id can never be
    reused by another garment's graph while its tensors are cached.
    """

    def __init__(self, device: torch.device) -> None:
        self.device = device
        self._graphs: dict[int, tuple[MeshGraph, dict[str, torch.Tensor]]] = {}

    def __call__(self, inputs: Mapping[str, np.ndarray], graph: MeshGraph, names: Sequence[str]) -> list:
        held, cached = self._graphs.setdefault(id(graph), (graph, {}))
        assert held is graph
        out = []
        for name in names:
            if name in ("features", "attributes"):
                out.append(torch.from_numpy(inputs[name]).to(self.device))
                continue
            if name not in cached:
                cached[name] = torch.from_numpy(inputs[name]).to(self.device)
            out.append(cached[name])
        return out


def _coarse_forward(model: CoarseGenerator, features: np.ndarray, graph: MeshGraph, tensors: _Tensors) -> torch.Tensor:
    return model(*tensors(coarse_inputs(features, graph.table), graph, COARSE_INPUTS))


def _detail_forward(model: DetailGenerator, features: np.ndarray, attributes: np.ndarray, graph: MeshGraph,
                    tensors: _Tensors) -> torch.Tensor:
    return model(*tensors(detail_inputs(features, attributes, graph), graph, DETAIL_INPUTS))


def torch_coarse_fn(model: CoarseGenerator, device: torch.device | str = "cpu") -> Callable:
    """A :data:`cloth_usd.core.pipeline.CoarseFn` running a torch coarse model (no grad)."""
    tensors = _Tensors(torch.device(device))

    def run(features: np.ndarray, graph: MeshGraph) -> np.ndarray:
        with torch.no_grad():
            return _coarse_forward(model, features, graph, tensors).cpu().numpy()

    return run


def torch_detail_fn(model: DetailGenerator, device: torch.device | str = "cpu") -> Callable:
    """A :data:`cloth_usd.core.pipeline.DetailFn` running a torch detail model (no grad)."""
    tensors = _Tensors(torch.device(device))

    def run(features: np.ndarray, attributes: np.ndarray, graph: MeshGraph) -> np.ndarray:
        with torch.no_grad():
            return _detail_forward(model, features, attributes, graph, tensors).cpu().numpy()

    return run


# ----------------------------------------------------------------------------- runs


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


def _read_run_json(run_dir: Path) -> dict:
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


def _torch_load(path: Path, device: torch.device | str) -> dict:
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
    info = _read_run_json(run_dir)
    tier = _trainable(info["tier"], f"{run_dir / RUN}: tier")
    config = TrainConfig.from_mapping(info["config"], str(run_dir / RUN))
    model = build_model(tier, config).to(device)
    state = _torch_load(run_dir / (BEST if best else CHECKPOINT), device)
    model.load_state_dict(state["model"])
    return Run(path=run_dir, tier=tier, config=config, info=info, model=model.eval(), epoch=int(state["epoch"]))


def _atomic_save(obj: Any, path: Path) -> None:
    fd, tmp = tempfile.mkstemp(prefix=f".{path.name}.", suffix=".tmp", dir=path.parent)
    os.close(fd)
    try:
        torch.save(obj, tmp)
        os.replace(tmp, path)
    except BaseException:
        Path(tmp).unlink(missing_ok=True)
        raise


def _atomic_text(text: str, path: Path) -> None:
    fd, tmp = tempfile.mkstemp(prefix=f".{path.name}.", suffix=".tmp", dir=path.parent)
    with os.fdopen(fd, "w") as fh:
        fh.write(text)
    os.replace(tmp, path)


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


def _write_history(run_dir: Path, history: Sequence[EpochRecord]) -> None:
    rows = [dataclasses.asdict(r) for r in history]
    _atomic_text(json.dumps(rows, indent=1) + "\n", run_dir / f"{HISTORY}.json")
    buf = io.StringIO()
    writer = csv.DictWriter(buf, fieldnames=[f.name for f in dataclasses.fields(EpochRecord)])
    writer.writeheader()
    writer.writerows(rows)
    _atomic_text(buf.getvalue(), run_dir / f"{HISTORY}.csv")


def plot_history(history: Sequence[EpochRecord], path: str | Path, title: str = "", *,
                 loss_label: str = "loss (MSE / output scale^2)", mm_label: str = "validation error [mm]",
                 log_loss: bool = True) -> Path:
    """Training and validation loss (log scale) and the validation error [mm] per epoch, as a PNG."""
    import matplotlib

    matplotlib.use("Agg")
    from matplotlib.figure import Figure

    epochs = [r.epoch for r in history]
    fig = Figure(figsize=(9, 3.5))
    ax1, ax2 = fig.subplots(1, 2)
    ax1.plot(epochs, [r.train_loss for r in history], "o-", label="train", ms=3)
    ax1.plot(epochs, [r.val_loss for r in history], "s-", label="validation", ms=3)
    if log_loss:
        ax1.set_yscale("log")
    ax1.set_xlabel("epoch")
    ax1.set_ylabel(loss_label)
    ax1.legend()
    ax2.plot(epochs, [r.val_mm for r in history], "s-", color="C1", ms=3)
    ax2.set_xlabel("epoch")
    ax2.set_ylabel(mm_label)
    if title:
        fig.suptitle(title)
    fig.tight_layout()
    fig.savefig(str(path), dpi=100)
    return Path(path)


# ----------------------------------------------------------------------------- training


class _Examples:
    """Builds a batch's inputs and target (numpy), the feature work ahead in a worker thread."""

    def __init__(self, tier: Tier, body: BodyModel, clips: Sequence[Clip], config: TrainConfig,
                 coarse_model: CoarseGenerator | None, device: torch.device,
                 coarse_base: CoarseBase | None = None) -> None:
        self.tier, self.body, self.clips, self.config = tier, body, clips, config
        self.coarse_model = coarse_model
        self.coarse_base = CoarseBase(coarse_base) if coarse_base is not None else config.coarse_base
        """The coarse model's base: the config's (coarse), the coarse run's (detail)."""
        self.tensors = _Tensors(device)

    def _first(self, item: tuple[int, np.ndarray]):
        clip = self.clips[item[0]]
        return clip, item[1], coarse_example(self.body, clip, item[1], self.coarse_base)

    def iterate(self, batches: Sequence[tuple[int, np.ndarray]]) -> Iterable[tuple]:
        """``(clip, features, attributes | None, base, target)`` per batch, in order."""
        depth = self.config.prefetch
        if depth == 0:
            for item in batches:
                yield self._finish(*self._first(item))
            return
        with ThreadPoolExecutor(max_workers=1) as pool:
            queue: deque = deque()
            todo = iter(batches)
            for item in todo:
                queue.append(pool.submit(self._first, item))
                if len(queue) > depth:
                    yield self._finish(*queue.popleft().result())
            while queue:
                yield self._finish(*queue.popleft().result())

    def _finish(self, clip: Clip, frames: np.ndarray, ex) -> tuple:
        if self.tier is Tier.COARSE:
            return clip, ex.features, None, ex.base, ex.target
        if self.config.coarse_input is CoarseInput.PREDICTED:
            with torch.no_grad():
                delta = _coarse_forward(self.coarse_model, ex.features, clip.pair.graph, self.tensors)
            coarse_points = ex.base + delta.cpu().numpy().astype(np.float64)
        else:
            coarse_points = clip.coarse[frames].astype(np.float64)
        dx = detail_example(clip, frames, ex.posed, coarse_points)
        return clip, dx.features, dx.attributes, dx.base, dx.target


def _statistics(examples: _Examples, clips: Sequence[Clip], config: TrainConfig) -> Statistics:
    tier = examples.tier
    feats = Moments(7 if tier is Tier.COARSE else 30)
    target, attrs = Moments(3), Moments(85)
    for _, f, a, _, t in examples.iterate(plan_batches(clips, config.batch, frames=config.stat_frames)):
        feats.add(f)
        target.add(t)
        if a is not None:
            attrs.add(a)
    return Statistics.from_moments(feats, target, attrs)


def _apply_statistics(model: CoarseGenerator | DetailGenerator, stats: Statistics) -> None:
    model.set_statistics(torch.from_numpy(stats.input_mean), torch.from_numpy(stats.input_std),
                         torch.from_numpy(stats.output_scale))
    if isinstance(model, DetailGenerator):
        model.set_attribute_statistics(torch.from_numpy(stats.attribute_mean), torch.from_numpy(stats.attribute_std))


def _forward(model, tensors: _Tensors, clip: Clip, features: np.ndarray, attributes: np.ndarray | None) -> torch.Tensor:
    if attributes is None:
        return _coarse_forward(model, features, clip.pair.graph, tensors)
    return _detail_forward(model, features, attributes, clip.pair.graph, tensors)


def _validate(model, examples: _Examples, clips: Sequence[Clip], config: TrainConfig) -> tuple[float, float]:
    """(loss, mean vertex error [mm]) over the validation clips."""
    if not clips:
        return math.nan, math.nan
    model.eval()
    scale = model.output_scale
    loss_sum = err_sum = 0.0
    count = 0
    with torch.no_grad():
        for clip, f, a, _, t in examples.iterate(plan_batches(clips, config.batch, frames=config.val_frames or None)):
            pred = _forward(model, examples.tensors, clip, f, a)
            target = torch.from_numpy(t).to(pred)
            vertices = target.shape[0] * target.shape[1]
            loss_sum += float((((pred - target) / scale) ** 2).mean(-1).sum())
            err_sum += float(torch.linalg.vector_norm(pred - target, dim=-1).sum())
            count += vertices
    return loss_sum / count, err_sum / count * 1000.0


def _start_epoch(model: torch.nn.Module, optimizer: torch.optim.Optimizer, clips: Sequence, config: TrainConfig,
                 epoch: int) -> tuple[float, list[tuple[int, np.ndarray]]]:
    """Set epoch ``epoch``'s learning rate (``lr * lr_decay ** epoch``) and training mode; its
    batches, shuffled by ``(seed, epoch)`` and cut to ``max_batches``. Returns ``(lr, batches)``."""
    lr = config.lr * config.lr_decay ** epoch
    for group in optimizer.param_groups:
        group["lr"] = lr
    batches = plan_batches(clips, config.batch, np.random.default_rng([config.seed, epoch]))
    if config.max_batches:
        batches = batches[:config.max_batches]
    model.train()
    return lr, batches


def _step(model: torch.nn.Module, optimizer: torch.optim.Optimizer, loss: torch.Tensor, grad_clip: float) -> float:
    """One optimisation step on ``loss`` (gradient norm clipped to ``grad_clip`` unless 0); its value."""
    optimizer.zero_grad(set_to_none=True)
    loss.backward()
    if grad_clip:
        torch.nn.utils.clip_grad_norm_(model.parameters(), grad_clip)
    optimizer.step()
    return float(loss.detach())


def _record_epoch(run_dir: Path, model: torch.nn.Module, optimizer: torch.optim.Optimizer,
                  history: list[EpochRecord], record: EpochRecord, best_loss: float, best_epoch: int
                  ) -> tuple[float, int]:
    """Append ``record``; write ``best.pt`` when it is the best so far (validation loss, or the
    training loss without validation), the resumable checkpoint and the history files.
    Returns the new ``(best_loss, best_epoch)``."""
    history.append(record)
    score = record.val_loss if not math.isnan(record.val_loss) else record.train_loss
    if score <= best_loss or best_epoch < 0:
        best_loss, best_epoch = score, record.epoch
        _atomic_save({"epoch": record.epoch, "model": model.state_dict(), "val_loss": record.val_loss}, run_dir / BEST)
    _atomic_save({"epoch": record.epoch, "model": model.state_dict(), "optimizer": optimizer.state_dict(),
                  "rng": _rng_state(), "history": [dataclasses.asdict(r) for r in history],
                  "best_loss": best_loss, "best_epoch": best_epoch}, run_dir / CHECKPOINT)
    _write_history(run_dir, history)
    return best_loss, best_epoch


def _rng_state() -> dict:
    state = {"torch": torch.get_rng_state()}
    if torch.cuda.is_available():
        state["cuda"] = torch.cuda.get_rng_state_all()
    return state


def _set_rng_state(state: Mapping[str, Any]) -> None:
    torch.set_rng_state(state["torch"].cpu())
    if "cuda" in state and torch.cuda.is_available():
        torch.cuda.set_rng_state_all([s.cpu() for s in state["cuda"]])


def _coarse_run_record(coarse: Run) -> dict:
    return {"path": str(coarse.path.resolve()), "best_sha256": file_sha256(coarse.path / BEST),
            "epoch": coarse.epoch}


def train(tier: Tier | str, data_dir: str | Path, run_dir: str | Path, config: TrainConfig = TrainConfig(), *,
          coarse_run: str | Path | None = None, device: str | None = "auto", resume: bool = False,
          body: BodyModel | None = None, dataset: DataSet | None = None,
          progress: Callable[[EpochRecord], None] | None = None) -> TrainResult:
    """Train one generator on a factory data set.

    Args:
        tier: ``coarse`` or ``detail``.
        data_dir: the ``cloth-usd datagen`` folder (train and val splits are used).
        run_dir: the run folder to create (or to continue with ``resume``).
        config: the training config (``config.epochs`` is the total, also when resuming).
        coarse_run: detail only: the trained coarse run whose predictions are ``M_coarse``.
        device: ``auto``, ``cpu`` or ``cuda``.
        resume: continue the run in ``run_dir`` after its last finished epoch.
        body: the body model (default: the embedded one).
        dataset: an already loaded data set of ``data_dir`` (tests; skips loading).
        progress: called after every epoch.
    Raises:
        ArgumentError: a tier that is not trainable (skinning), bad folders, a run that exists
            without ``resume``, a resumed run whose config or data differ.
    """
    tier = _trainable(tier)
    if config.objective is not Objective.SUPERVISED:
        raise ArgumentError(f"train: objective {config.objective.value!r} trains on a data set config, not on "
                            "simulated data (cloth_usd.nn.physics_train.train_physics; cloth-usd train coarse "
                            "--objective physics --data CONFIG)")
    dev = pick_device(device)
    run_dir = Path(run_dir)
    if not resume and (run_dir / CHECKPOINT).exists():
        raise ArgumentError(f"--out {run_dir}: a run exists there; pass --resume to continue it or pick a new folder")
    if resume and not (run_dir / CHECKPOINT).exists():
        raise ArgumentError(f"--resume: {run_dir} has no {CHECKPOINT} to continue")
    if tier is Tier.DETAIL and coarse_run is None and config.coarse_input is CoarseInput.PREDICTED:
        raise ArgumentError("train detail needs --coarse-run RUN (the trained coarse model gives M_coarse; "
                            "or set coarse_input = 'target' in the config)")
    if tier is Tier.COARSE and coarse_run is not None:
        raise ArgumentError("train coarse takes no --coarse-run")
    coarse = load_run(coarse_run, device=dev) if coarse_run is not None else None
    if coarse is not None and coarse.tier is not Tier.COARSE:
        raise ArgumentError(f"--coarse-run {coarse_run}: is a {coarse.tier.value} run, not a coarse one")
    data = dataset if dataset is not None else load_dataset(
        data_dir, (Split.TRAIN, Split.VAL), body=body, max_frames=config.max_frames or None)
    heading = coarse.config.heading if coarse is not None else config.heading
    data = with_heading(with_coarse_target(data, config.coarse_target), heading)
    train_clips, val_clips = data.split(Split.TRAIN), data.split(Split.VAL)
    if not train_clips:
        raise ArgumentError(f"--data {data_dir}: no accepted training sequences")
    if not val_clips:
        log.warning("%s: no validation sequences; the best model is the last one", data_dir)
    info = {"format": RUN_FORMAT, "tier": tier.value, "config": config.to_json(),
            "model_config": dataclasses.asdict(model_config(tier, config)),
            "data": {"path": str(Path(data_dir).resolve()), "manifest_sha256": data.manifest_sha256,
                     "train_sequences": len(train_clips), "val_sequences": len(val_clips)},
            "coarse_run": _coarse_run_record(coarse) if coarse is not None else None,
            "body_model_sha256": data.body.sha256, "torch": torch.__version__}
    base = coarse.config.coarse_base if coarse is not None else config.coarse_base
    examples = _Examples(tier, data.body, train_clips, config, coarse.model if coarse else None, dev, base)
    val_examples = _Examples(tier, data.body, val_clips, config, coarse.model if coarse else None, dev, base)

    torch.manual_seed(config.seed)
    model = build_model(tier, config).to(dev)
    optimizer = torch.optim.Adam(model.parameters(), lr=config.lr)
    history: list[EpochRecord] = []
    best_loss, best_epoch, start = math.inf, -1, 0
    if resume:
        old = _read_run_json(run_dir)
        old_config = TrainConfig.from_mapping(old["config"], str(run_dir / RUN)).to_json()  # older runs lack newer keys
        same = {k: v for k, v in old_config.items() if k != "epochs"} == \
            {k: v for k, v in info["config"].items() if k != "epochs"}
        if not same or old["tier"] != tier.value:
            raise ArgumentError(f"--resume: {run_dir / RUN} was made with another tier or config "
                                f"({old['tier']}, {old['config']}); only epochs may change")
        if old["data"]["manifest_sha256"] != data.manifest_sha256:
            raise ArgumentError(f"--resume: {run_dir} was trained on another data set "
                                f"(manifest sha256 {old['data']['manifest_sha256'][:12]}...)")
        if (old.get("coarse_run") or {}).get("best_sha256") != (info.get("coarse_run") or {}).get("best_sha256"):
            raise ArgumentError(f"--resume: {run_dir} was trained on another coarse model")
        state = _torch_load(run_dir / CHECKPOINT, dev)
        model.load_state_dict(state["model"])
        optimizer.load_state_dict(state["optimizer"])
        _set_rng_state(state["rng"])
        history = [EpochRecord(**r) for r in state["history"]]
        best_loss, best_epoch, start = state["best_loss"], state["best_epoch"], int(state["epoch"]) + 1
        log.info("%s: resuming after epoch %d", run_dir, start - 1)
    else:
        run_dir.mkdir(parents=True, exist_ok=True)
        stats = _statistics(examples, train_clips, config)
        _apply_statistics(model, stats)
        stats.save(run_dir / STATS)
    info["config"]["epochs"] = config.epochs
    _atomic_text(json.dumps(info, indent=2, sort_keys=True) + "\n", run_dir / RUN)

    for epoch in range(start, config.epochs):
        began = time.perf_counter()
        lr, batches = _start_epoch(model, optimizer, train_clips, config, epoch)
        scale = model.output_scale
        total, steps = 0.0, 0
        for clip, f, a, _, t in examples.iterate(batches):
            pred = _forward(model, examples.tensors, clip, f, a)
            loss = (((pred - torch.from_numpy(t).to(pred)) / scale) ** 2).mean()
            total += _step(model, optimizer, loss, config.grad_clip)
            steps += 1
        val_loss, val_mm = _validate(model, val_examples, val_clips, config)
        record = EpochRecord(epoch=epoch, train_loss=total / max(steps, 1), val_loss=val_loss, val_mm=val_mm,
                             lr=lr, seconds=time.perf_counter() - began)
        best_loss, best_epoch = _record_epoch(run_dir, model, optimizer, history, record, best_loss, best_epoch)
        plot_history(history, run_dir / CURVE, title=f"{tier.value}: {run_dir.name}")
        log.info("%s epoch %d: train %.4g, val %.4g (%.3f mm), %.1f s", tier.value, epoch, record.train_loss,
                 val_loss, val_mm, record.seconds)
        if progress is not None:
            progress(record)
    if start >= config.epochs:
        log.info("%s: already trained for %d epochs", run_dir, config.epochs)
    if not history:
        raise ClothUsdError(f"{run_dir}: no epoch was trained")
    return TrainResult(run_dir=run_dir, history=tuple(history), best_epoch=best_epoch, model=model.eval())

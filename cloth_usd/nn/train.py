"""Training of the coarse and detail generators (docs/method.md): seeded, resumable, logged.

``cloth-usd train coarse|detail --data DATA --out RUN`` calls :func:`train`. Batches are
frames of one sequence (they share one garment graph); inputs are built through
:mod:`cloth_usd.core.pipeline`, the runtime's own feature path (see
:mod:`cloth_usd.nn.data`). Loss: docs/method.md's MSE of the displacement, measured in units
of the model's output scale (the per-axis RMS of the training targets), so both tiers'
losses are O(1).

The config is :mod:`cloth_usd.nn.config`'s, the run folder :mod:`cloth_usd.nn.runs`'s
(curves: :mod:`cloth_usd.nn.plots`), the torch model calls :mod:`cloth_usd.nn.inference`'s.

Resuming (``resume=True``) restarts after the last finished epoch and continues
bit-identically: every epoch's data order comes from ``(seed, epoch)`` alone and the
model, optimizer and torch RNG states are restored.

Shape letters: B frames of a batch, N garment vertices.
"""

from __future__ import annotations

import dataclasses
import json
import logging
import math
import time
from collections import deque
from concurrent.futures import ThreadPoolExecutor
from pathlib import Path
from typing import Callable, Iterable, Sequence

import numpy as np
import torch

from ..core.body import BodyModel
from ..core.features import DETAIL_FEATURES
from ..core.pipeline import CoarseBase, CoarseFeatures, coarse_feature_count
from ..core.scene import Tier
from ..errors import ArgumentError, ClothUsdError, OutputWriteError
from .config import (TRAINABLE_TIERS, CoarseInput, Objective, TrainConfig, build_model, load_train_config, model_config,
                     trainable)
from .data import (
    Clip,
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
from .inference import Tensors, coarse_forward, detail_forward, pick_device, torch_coarse_fn, torch_detail_fn
from .models import CoarseGenerator, DetailGenerator
from .plots import plot_history
from .runs import (CHECKPOINT, CURVE, RUN, RUN_FORMAT, STATS, EpochRecord, Run, TrainResult, atomic_text,
                   coarse_run_record, load_run, read_run_json, record_epoch, resume_settings, set_rng_state,
                   torch_load)

__all__ = ["TRAINABLE_TIERS", "Objective", "CoarseInput", "TrainConfig", "load_train_config", "resume_settings",
           "EpochRecord", "TrainResult", "train", "load_run", "Run", "torch_coarse_fn", "torch_detail_fn",
           "pick_device", "plot_history"]

log = logging.getLogger(__name__)

# The names cloth_usd.nn.physics_train takes from here, under the names it uses.
_atomic_text, _coarse_forward, _detail_forward, _Tensors = atomic_text, coarse_forward, detail_forward, Tensors
_coarse_run_record, _record_epoch, _trainable = coarse_run_record, record_epoch, trainable


class _Examples:
    """Builds a batch's inputs and target (numpy), the feature work ahead in a worker thread."""

    def __init__(self, tier: Tier, body: BodyModel, clips: Sequence[Clip], config: TrainConfig,
                 coarse_model: CoarseGenerator | None, device: torch.device,
                 coarse_base: CoarseBase | None = None, coarse_features: CoarseFeatures | None = None) -> None:
        self.tier, self.body, self.clips, self.config = tier, body, clips, config
        self.coarse_model = coarse_model
        self.coarse_base = CoarseBase(coarse_base) if coarse_base is not None else config.coarse_base
        """The coarse model's base: the config's (coarse), the coarse run's (detail)."""
        self.coarse_features = CoarseFeatures(coarse_features) if coarse_features is not None \
            else config.coarse_features
        """The coarse model's features, taken as the base is."""
        self.tensors = Tensors(device)

    def _first(self, item: tuple[int, np.ndarray]):
        clip = self.clips[item[0]]
        return clip, item[1], coarse_example(self.body, clip, item[1], self.coarse_base, self.coarse_features)

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
                delta = coarse_forward(self.coarse_model, ex.features, clip.pair.graph, self.tensors)
            coarse_points = ex.base + delta.cpu().numpy().astype(np.float64)
        else:
            coarse_points = clip.coarse[frames].astype(np.float64)
        dx = detail_example(clip, frames, ex.posed, coarse_points)
        return clip, dx.features, dx.attributes, dx.base, dx.target


def _statistics(examples: _Examples, clips: Sequence[Clip], config: TrainConfig) -> Statistics:
    tier = examples.tier
    feats = Moments(coarse_feature_count(examples.coarse_features) if tier is Tier.COARSE else DETAIL_FEATURES)
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


def _forward(model, tensors: Tensors, clip: Clip, features: np.ndarray, attributes: np.ndarray | None) -> torch.Tensor:
    if attributes is None:
        return coarse_forward(model, features, clip.pair.graph, tensors)
    return detail_forward(model, features, attributes, clip.pair.graph, tensors)


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


_FORMED: dict = {}
"""The last data set :func:`_formed` made: ``(id, target, heading) -> (data, formed)``."""


def _formed(data: DataSet, target, heading) -> DataSet:
    """``data`` with its coarse target and heading applied, made once for a data set that
    trains both tiers in one process (the latest one is kept; a data set is never changed)."""
    key = (id(data), str(target), str(heading))
    hit = _FORMED.get(key)
    if hit is None or hit[0] is not data:
        _FORMED.clear()
        hit = _FORMED[key] = (data, with_heading(with_coarse_target(data, target), heading))
    return hit[1]


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
    tier = trainable(tier)
    if config.objective is not Objective.SUPERVISED:
        raise ArgumentError(f"train: objective {config.objective.value!r} trains on a data set config, not on "
                            "simulated data (cloth_usd.nn.physics_train.train_physics; cloth-usd train coarse "
                            "--objective physics|hybrid --data CONFIG)")
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
    form = (coarse.config if coarse is not None else config).coarse_form  # a detail run runs as its coarse run
    data = _formed(data, config.coarse_target, form.heading)
    train_clips, val_clips = data.split(Split.TRAIN), data.split(Split.VAL)
    if not train_clips:
        raise ArgumentError(f"--data {data_dir}: no accepted training sequences")
    if not val_clips:
        log.warning("%s: no validation sequences; the best model is the last one", data_dir)
    info = {"format": RUN_FORMAT, "tier": tier.value, "config": config.to_json(),
            "model_config": dataclasses.asdict(model_config(tier, config)),
            "data": {"path": str(Path(data_dir).resolve()), "manifest_sha256": data.manifest_sha256,
                     "train_sequences": len(train_clips), "val_sequences": len(val_clips)},
            "coarse_run": coarse_run_record(coarse) if coarse is not None else None,
            "body_model_sha256": data.body.sha256, "torch": torch.__version__}
    examples = _Examples(tier, data.body, train_clips, config, coarse.model if coarse else None, dev, form.base,
                         form.features)
    val_examples = _Examples(tier, data.body, val_clips, config, coarse.model if coarse else None, dev, form.base,
                             form.features)

    torch.manual_seed(config.seed)
    model = build_model(tier, config).to(dev)
    optimizer = torch.optim.Adam(model.parameters(), lr=config.lr)
    history: list[EpochRecord] = []
    best_loss, best_epoch, start = math.inf, -1, 0
    if resume:
        old = read_run_json(run_dir)
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
        state = torch_load(run_dir / CHECKPOINT, dev)
        model.load_state_dict(state["model"])
        optimizer.load_state_dict(state["optimizer"])
        set_rng_state(state["rng"])
        history = [EpochRecord(**r) for r in state["history"]]
        best_loss, best_epoch, start = state["best_loss"], state["best_epoch"], int(state["epoch"]) + 1
        log.info("%s: resuming after epoch %d", run_dir, start - 1)
    else:
        try:
            run_dir.mkdir(parents=True, exist_ok=True)
        except OSError as exc:
            raise OutputWriteError(f"--out {run_dir}: cannot create the run folder ({exc.strerror or exc})") from None
        stats = _statistics(examples, train_clips, config)
        _apply_statistics(model, stats)
        stats.save(run_dir / STATS)
    info["config"]["epochs"] = config.epochs
    atomic_text(json.dumps(info, indent=2, sort_keys=True) + "\n", run_dir / RUN)

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
        best_loss, best_epoch = record_epoch(run_dir, model, optimizer, history, record, best_loss, best_epoch)
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

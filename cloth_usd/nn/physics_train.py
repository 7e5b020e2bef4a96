"""Training the generators on the garment's own physics: no simulated data.

The objective is the garment's energy (:mod:`cloth_usd.nn.physics`) at the model's
output, quasi-static: membrane strain against the rest garment, bending against its
rest angles, gravity, and a one-sided contact penalty against the posed body (each
garment vertex against the tangent plane of its associated body vertex, the point and
normal the features and the post-process use). Minimising it per frame asks for the
garment at rest in that pose, which is what a per-frame model can learn (SNUG, PBNS).

The poses, bodies and garments are a data set config's (:class:`~cloth_usd.datagen.factory.
FactoryConfig`, the file ``cloth-usd datagen`` reads): the same garment-body pairs, motions
and splits, planned but never simulated. The fit attribute's factor analysis is fitted on
its training pairs, as the factory does, and saved in the run folder.

The coarse model is made smooth by a stiffer bending (``TrainConfig.bending_scale``):
the coarse tier should drape, not wrinkle. The detail model (parser included) then
minimises the energy of the material as it is (``bending_scale`` 1) starting from the
coarse model's garment ``M_coarse``, which it sees as the runtime makes it. The run folder has the supervised runs' layout
(``run.json``, ``best.pt``, ``history.csv``, ``curve.png``), so ``load_run`` reads it; its
losses are energies [J]; validation is relative to the base garment's (the skinned one for
the coarse tier, ``M_coarse`` for the detail tier; below 0: the model found a state of
lower energy). Shape letters: B frames, N garment vertices.
"""

from __future__ import annotations

import dataclasses
import json
import logging
import math
import time
from dataclasses import dataclass
from pathlib import Path
from typing import Callable, Sequence

import numpy as np
import torch

from ..core.body import BodyModel, load_body_model
from ..core.fit import FitModel
from ..core.heading import Heading, heading_frame
from ..core.pipeline import (CoarseBase, GarmentPair, coarse_base_points, coarse_model_features, detail_model_inputs,
                             pose_body, prepare_pair)
from ..core.scene import Tier
from ..errors import ArgumentError, ClothUsdError
from .data import Moments, Split, plan_batches
from .physics import GarmentRest, Material, garment_energy, garment_rest
from .train import (CHECKPOINT, CURVE, RUN, RUN_FORMAT, EpochRecord, Objective, TrainConfig, TrainResult, _atomic_text,
                    _coarse_forward, _detail_forward, _record_epoch, _start_epoch, _step, _Tensors, build_model,
                    plot_history)

__all__ = ["PhysicsClip", "PhysicsSet", "physics_set", "train_physics", "PHYSICS_FIT", "OUTPUT_SCALE"]

log = logging.getLogger(__name__)

#: The fit model of a physics run's pairs, in its run folder.
PHYSICS_FIT = "fit.npz"
#: The coarse model's output scale [m] per axis under the physics objective (no target
#: to measure it on): the order of a T-shirt's departure from skinning.
OUTPUT_SCALE = 0.02
#: A fresh model's last layer is multiplied by this (see :func:`_statistics`).
START_SHRINK = 0.05
#: A fresh model's magnitude before the ReLU, in units of :data:`OUTPUT_SCALE` (1 mm). The
#: magnitude head ends in one output, so its bias is one number: shrunk with the weights, a
#: negative one left every vertex at zero magnitude and zero gradient (a detail run, seed 0,
#: stayed exactly at M_coarse for 3 epochs).
START_MAGNITUDE = 0.05


@dataclass(frozen=True, eq=False)
class PhysicsClip:
    """One planned garment-body-motion sequence, in the frame the models see."""

    name: str
    split: Split
    pair: GarmentPair
    """Association, graph and fit attribute, as the runtime computes them."""
    rest: GarmentRest
    """The rest garment's metric, masses and bending rest state."""
    rest_points: np.ndarray
    """(N, 3) float64 rest garment [m], canonical body frame."""
    poses: np.ndarray
    """(T, 72) float64 axis-angle [rad], heading taken out when the run is canonical."""
    transl: np.ndarray
    """(T, 3) float64 root translation [m]."""
    meta: dict

    @property
    def num_frames(self) -> int:
        """T."""
        return int(self.poses.shape[0])


@dataclass(frozen=True)
class PhysicsSet:
    """The pairs and motions of a data set config, planned and prepared."""

    config_sha256: str
    """sha256 of the config file's bytes (recorded with the run)."""
    fit: FitModel
    material: Material
    clips: tuple[PhysicsClip, ...]

    def split(self, split: Split | str) -> list[PhysicsClip]:
        split = Split(split)
        return [c for c in self.clips if c.split is split]


def physics_set(config_path: str | Path, body: BodyModel | None = None, *, heading: Heading | str = Heading.CANONICAL,
                splits: Sequence[Split | str] | None = None, max_frames: int | None = None,
                bending_scale: float = 1.0) -> PhysicsSet:
    """Plan a data set config's sequences (no simulation) for the physics objective.

    Args:
        config_path: a ``cloth-usd datagen`` config (.json / .toml).
        body: the body model (the embedded one when None).
        heading: the frame the models see (:class:`~cloth_usd.core.heading.Heading`).
        splits: the splits to keep (all when None).
        max_frames: cut every sequence to its first frames.
        bending_scale: multiplies the material's bending stiffness.
    """
    from ..core.files import file_sha256
    from ..datagen.factory import fit_training_pairs, load_config, plan_jobs
    from ..datagen.simulate import SimConfig

    config_path = Path(config_path)
    body = body if body is not None else load_body_model()
    factory = load_config(config_path)
    jobs = plan_jobs(factory, body)
    fit, _ = fit_training_pairs(jobs, body)
    base = Material.from_sim_config(SimConfig(**factory.sim))
    material = dataclasses.replace(base, bend_stiffness=base.bend_stiffness * bending_scale)
    keep = None if splits is None else {Split(s) for s in splits}
    pairs: dict[str, tuple[GarmentPair, GarmentRest]] = {}
    clips = []
    for job in jobs:
        split = Split(job.meta["split"])
        if keep is not None and split not in keep:
            continue
        key = f"shirt{job.meta['shirt']}.{job.meta['body']}"
        if key not in pairs:
            pair = prepare_pair(body, job.betas, job.garment_vertices, job.garment_faces, fit)
            pairs[key] = pair, garment_rest(job.garment_vertices, job.garment_faces, material)
        pair, rest = pairs[key]
        poses, transl = job.poses[:max_frames], job.transl[:max_frames]
        if Heading(heading) is Heading.CANONICAL:
            poses = heading_frame(poses, transl, pair.joints[0]).canonical_poses(poses)
        clips.append(PhysicsClip(name=job.name, split=split, pair=pair, rest=rest,
                                 rest_points=np.asarray(job.garment_vertices, dtype=np.float64),
                                 poses=np.asarray(poses, dtype=np.float64),
                                 transl=np.asarray(transl, dtype=np.float64), meta=dict(job.meta)))
    return PhysicsSet(config_sha256=file_sha256(config_path), fit=fit, material=material, clips=tuple(clips))


@dataclass(frozen=True)
class _Inputs:
    """A batch's model inputs and the garment its displacement is added to (numpy)."""

    features: np.ndarray
    """(B, N, F) node features."""
    attributes: np.ndarray | None
    """(B, 85) parser attributes (detail tier), else None."""
    base: np.ndarray
    """(B, N, 3) float64 [m]: the skinned garment (coarse) or ``M_coarse`` (detail)."""
    body_points: np.ndarray
    """(B, N, 3) float64 [m] each garment vertex's associated posed body vertex."""
    body_normals: np.ndarray
    """(B, N, 3) float64 the body normals there."""


class _Tier:
    """What one tier's physics training computes per batch, the model call included."""

    def __init__(self, tier: Tier, body: BodyModel, base: CoarseBase, tensors: _Tensors, coarse_model=None) -> None:
        self.tier, self.body, self.base, self.tensors, self.coarse_model = tier, body, base, tensors, coarse_model

    def inputs(self, clip: PhysicsClip, frames: np.ndarray) -> _Inputs:
        poses, transl = clip.poses[frames], clip.transl[frames]
        posed = pose_body(self.body, clip.pair, poses, transl)
        feats = coarse_model_features(clip.pair, posed, transl)
        base = coarse_base_points(self.body, clip.pair, posed, poses, transl, self.base)
        if self.tier is Tier.COARSE:
            return _Inputs(feats, None, base, posed.garment_points, posed.garment_normals)
        with torch.no_grad():  # the coarse model's M_coarse, as the runtime makes it (before the post-process)
            m_coarse = base + _coarse_forward(self.coarse_model, feats, clip.pair.graph, self.tensors).cpu().numpy()
        feats, attrs = detail_model_inputs(clip.pair, m_coarse, posed, poses, transl)
        return _Inputs(feats, attrs, m_coarse, posed.garment_points, posed.garment_normals)

    def forward(self, model, clip: PhysicsClip, inp: _Inputs) -> torch.Tensor:
        """(B, N, 3) float64 the model's garment [m]."""
        if inp.attributes is None:
            delta = _coarse_forward(model, inp.features, clip.pair.graph, self.tensors)
        else:
            delta = _detail_forward(model, inp.features, inp.attributes, clip.pair.graph, self.tensors)
        return torch.from_numpy(inp.base).to(delta.device) + delta.double()


def _energy(clip: PhysicsClip, x: torch.Tensor, inp: _Inputs, material: Material) -> torch.Tensor:
    """(B,) the quasi-static energy [J] of garments ``x`` (B, N, 3)."""
    return garment_energy(x, clip.rest, material, body_points=torch.from_numpy(inp.body_points).to(x),
                          body_normals=torch.from_numpy(inp.body_normals).to(x)).total


def _statistics(model, step: _Tier, clips: Sequence[PhysicsClip], config: TrainConfig) -> None:
    """Input statistics from the training frames, the fixed :data:`OUTPUT_SCALE`, and a start
    near the base: the last layers are shrunk so a fresh model moves the garment by about a
    millimetre, not by :data:`OUTPUT_SCALE` in random directions (which tears the membrane:
    hundreds of J against the skinned garment's few, a hole the optimiser climbs out of slowly)."""
    feats, attrs = Moments(7 if step.tier is Tier.COARSE else 30), Moments(85)
    for k, frames in plan_batches(clips, config.batch, frames=config.stat_frames):
        inp = step.inputs(clips[k], frames)
        feats.add(inp.features)
        if inp.attributes is not None:
            attrs.add(inp.attributes)
    model.set_statistics(torch.from_numpy(feats.mean), torch.from_numpy(feats.std),
                         torch.full((3,), OUTPUT_SCALE))
    if step.tier is Tier.DETAIL:
        model.set_attribute_statistics(torch.from_numpy(attrs.mean), torch.from_numpy(attrs.std))
    head = model.head.magnitude if model.head.magnitude is not None else model.head.direction
    with torch.no_grad():
        head[-1].weight.mul_(START_SHRINK)
        if model.head.magnitude is not None:  # ReLU magnitude: a bias <= 0 would start every vertex dead
            head[-1].bias.fill_(START_MAGNITUDE)
        else:
            head[-1].bias.mul_(START_SHRINK)


def _validate(model, step: _Tier, clips: Sequence[PhysicsClip], config: TrainConfig,
              material: Material) -> tuple[float, float]:
    """(mean energy relative to the base garment's [J], mean distance from it [mm]); the base is
    the skinned garment (coarse tier) or the coarse model's (detail tier)."""
    if not clips:
        return math.nan, math.nan
    model.eval()
    rel = dist = 0.0
    count = vertices = 0
    with torch.no_grad():
        for k, frames in plan_batches(clips, config.batch, frames=config.val_frames or None):
            clip = clips[k]
            inp = step.inputs(clip, frames)
            x = step.forward(model, clip, inp).cpu()
            base = torch.from_numpy(inp.base)
            rel += float((_energy(clip, x, inp, material) - _energy(clip, base, inp, material)).sum())
            dist += float(torch.linalg.vector_norm(x - base, dim=-1).sum())
            count += len(frames)
            vertices += x.shape[0] * x.shape[1]
    return rel / count, dist / vertices * 1000.0


def train_physics(config_path: str | Path, run_dir: str | Path, config: TrainConfig = TrainConfig(
        objective=Objective.PHYSICS, coarse_base=CoarseBase.SKINNED), *, tier: Tier | str = Tier.COARSE,
        coarse_run: str | Path | None = None, device: str | None = "auto", body: BodyModel | None = None,
        progress: Callable[[EpochRecord], None] | None = None) -> TrainResult:
    """Train a generator on the physics objective (see the module docstring).

    Args:
        config_path: the data set config whose pairs and motions it trains on.
        run_dir: the run folder to create.
        config: ``objective`` must be ``physics``; ``bending_scale`` scales the bending
            (10 for the coarse tier's drape; 1, the material's, for the detail tier).
        tier: coarse, or detail on top of ``coarse_run`` (its predictions are ``M_coarse``;
            the detail run takes its heading and coarse base).
        coarse_run: the trained coarse run folder (detail only).
        device: torch device (auto: CUDA when available).
        progress: called after every epoch.
    Raises:
        ArgumentError: a run exists in ``run_dir``, the config has no training pairs, or
            the tier and ``coarse_run`` do not go together.
    """
    from .train import _coarse_run_record, _trainable, load_run, pick_device

    tier = _trainable(tier, "train_physics: tier")
    if config.objective is not Objective.PHYSICS:
        raise ArgumentError(f"train_physics: config.objective is {config.objective.value!r}, not 'physics'")
    if (tier is Tier.DETAIL) != (coarse_run is not None):
        raise ArgumentError("train_physics: the detail tier needs --coarse-run (the trained coarse run), "
                            "the coarse tier takes none")
    run_dir = Path(run_dir)
    if (run_dir / CHECKPOINT).exists():
        raise ArgumentError(f"--out {run_dir}: a run exists there; pick a new folder")
    dev = pick_device(device)
    body = body if body is not None else load_body_model()
    coarse = load_run(coarse_run, device=dev) if coarse_run is not None else None
    if coarse is not None and coarse.tier is not Tier.COARSE:
        raise ArgumentError(f"--coarse-run {coarse_run}: is a {coarse.tier.value} run, not a coarse one")
    heading = coarse.config.heading if coarse is not None else config.heading
    base = coarse.config.coarse_base if coarse is not None else config.coarse_base
    data = physics_set(config_path, body, heading=heading, splits=(Split.TRAIN, Split.VAL),
                       max_frames=config.max_frames or None, bending_scale=config.bending_scale)
    train_clips, val_clips = data.split(Split.TRAIN), data.split(Split.VAL)
    if not train_clips:
        raise ArgumentError(f"{config_path}: no training sequences")
    tensors = _Tensors(dev)
    step = _Tier(tier, body, base, tensors, coarse.model if coarse is not None else None)
    torch.manual_seed(config.seed)
    model = build_model(tier, config).to(dev)
    _statistics(model, step, train_clips, config)
    optimizer = torch.optim.Adam(model.parameters(), lr=config.lr)
    run_dir.mkdir(parents=True, exist_ok=True)
    data.fit.save(run_dir / PHYSICS_FIT)
    info = {"format": RUN_FORMAT, "tier": tier.value, "config": config.to_json(),
            "model_config": dataclasses.asdict(model.config),
            "data": {"path": str(Path(config_path).resolve()), "manifest_sha256": data.config_sha256,
                     "train_sequences": len(train_clips), "val_sequences": len(val_clips), "kind": "physics"},
            "physics": {"material": dataclasses.asdict(data.material), "fit": PHYSICS_FIT},
            "coarse_run": _coarse_run_record(coarse) if coarse is not None else None,
            "body_model_sha256": body.sha256, "torch": torch.__version__}
    _atomic_text(json.dumps(info, indent=2, sort_keys=True) + "\n", run_dir / RUN)
    against = "skinning" if tier is Tier.COARSE else "the coarse garment"
    history: list[EpochRecord] = []
    best_loss, best_epoch = math.inf, -1
    for epoch in range(config.epochs):
        began = time.perf_counter()
        lr, batches = _start_epoch(model, optimizer, train_clips, config, epoch)
        total = 0.0
        for k, frames in batches:
            clip = train_clips[k]
            inp = step.inputs(clip, frames)
            total += _step(model, optimizer, _energy(clip, step.forward(model, clip, inp), inp, data.material).mean(),
                           config.grad_clip)
        val_loss, val_mm = _validate(model, step, val_clips, config, data.material)
        record = EpochRecord(epoch=epoch, train_loss=total / max(len(batches), 1), val_loss=val_loss, val_mm=val_mm,
                             lr=lr, seconds=time.perf_counter() - began)
        best_loss, best_epoch = _record_epoch(run_dir, model, optimizer, history, record, best_loss, best_epoch)
        plot_history(history, run_dir / CURVE, title=f"{tier.value} (physics): {run_dir.name}",
                     loss_label=f"energy [J] (validation: relative to {against})",
                     mm_label=f"validation: distance from {against} [mm]", log_loss=False)
        log.info("physics %s epoch %d: train %.4g J, val %+.4g J vs %s (%.1f mm from it), %.1f s", tier.value,
                 epoch, record.train_loss, val_loss, against, val_mm, record.seconds)
        if progress is not None:
            progress(record)
    if not history:
        raise ClothUsdError(f"{run_dir}: no epoch was trained")
    return TrainResult(run_dir=run_dir, history=tuple(history), best_epoch=best_epoch, model=model.eval())

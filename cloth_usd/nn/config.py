"""How a generator is trained: :class:`TrainConfig` (the ``--config`` file keys), the
tiers that train, and the fresh model a config asks for."""

from __future__ import annotations

import dataclasses
import enum
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Mapping

import torch

from ..core.files import read_config
from ..core.heading import Heading
from ..core.pipeline import CoarseBase, CoarseFeatures, CoarseForm, coarse_feature_count
from ..core.scene import Tier
from ..errors import ArgumentError
from .data import CoarseTarget
from .models import CoarseConfig, CoarseGenerator, DetailConfig, DetailGenerator

__all__ = ["TRAINABLE_TIERS", "trainable", "Objective", "CoarseInput", "TrainConfig", "load_train_config",
           "model_config", "MAGNITUDE_BIAS", "build_model"]

#: The tiers that have a generator to train (skinning has no model).
TRAINABLE_TIERS = (Tier.COARSE, Tier.DETAIL)


def trainable(tier: Tier | str, where: str = "tier") -> Tier:
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
    HYBRID = "hybrid"
    """The physics objective plus a supervised term (``supervised_weight``) on the sequences
    that were simulated (:mod:`cloth_usd.nn.physics_train`)."""


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
    contact_margin: float | None = None
    """Physics and hybrid objectives only [m]: the body contact's margin ``r`` (the contact
    energy starts ``r`` in front of the body, its weight stays the simulator's stiffness over
    ``r``); None: the simulator's (4 mm). A larger one keeps the learned garment further off
    the body, so that less of it ends inside before the post-process."""
    supervised_weight: float = 1000.0
    """Hybrid objective only [1/s^2]: the supervised term of a frame is
    ``supervised_weight / 2 * sum_n m_n |x_n - y_n|^2`` [J] (``m_n`` the vertex masses [kg],
    ``y`` the simulated frame), a spring that pulls each vertex toward the simulation with an
    acceleration ``supervised_weight x distance``: as strong as gravity at ``9.81 /
    supervised_weight`` [m] (1 cm at the default; a starting point, not tuned). 0: the physics
    objective's loss."""
    coarse_features: CoarseFeatures = CoarseFeatures.BODY
    """Coarse only: the coarse model's node features: ``body`` (docs/method.md's, at the
    associated body vertex) or ``contact`` (those and the nearest body under the garment,
    :class:`~cloth_usd.core.pipeline.CoarseFeatures`; a detail run takes its coarse run's)."""
    heading: Heading = Heading.CANONICAL
    """Coarse only: the frame the models see the body in (a detail run takes its coarse
    run's): ``canonical`` turns every frame's body to face +Z (the garment turned with it), so
    the models give the same local garment whichever way a character faces; ``world`` is how
    runs before this key were trained (their run.json reads as ``world``)."""

    def __post_init__(self) -> None:
        for key, kind in (("coarse_input", CoarseInput), ("coarse_target", CoarseTarget), ("coarse_base", CoarseBase),
                          ("coarse_features", CoarseFeatures), ("heading", Heading), ("objective", Objective)):
            value = getattr(self, key)
            if value not in {k.value for k in kind}:  # str enums: a member equals its value
                raise ArgumentError(f"TrainConfig: {key}={value!r} is not one of {', '.join(k.value for k in kind)}")
            object.__setattr__(self, key, kind(value))
        checks = {"epochs": self.epochs >= 1, "lr": self.lr > 0, "lr_decay": 0 < self.lr_decay <= 1,
                  "batch": self.batch >= 1, "width": self.width > 0, "grad_clip": self.grad_clip >= 0,
                  "stat_frames": self.stat_frames >= 1, "val_frames": self.val_frames >= 0,
                  "max_batches": self.max_batches >= 0, "max_frames": self.max_frames >= 0,
                  "prefetch": self.prefetch >= 0, "bending_scale": self.bending_scale > 0,
                  "supervised_weight": self.supervised_weight >= 0,
                  "contact_margin": self.contact_margin is None or self.contact_margin > 0}
        bad = [k for k, ok in checks.items() if not ok]
        if bad:
            raise ArgumentError(f"TrainConfig: out of range: {', '.join(f'{k}={getattr(self, k)!r}' for k in bad)}")

    @property
    def coarse_form(self) -> CoarseForm:
        """A coarse run's :class:`~cloth_usd.core.pipeline.CoarseForm`: how its model is run
        (``coarse_base``, ``heading``, ``coarse_features``)."""
        return CoarseForm(self.coarse_base, self.heading, self.coarse_features)

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


def model_config(tier: Tier | str, config: TrainConfig) -> CoarseConfig | DetailConfig:
    """The model config a TrainConfig asks for (paper widths times ``width``)."""
    if trainable(tier) is Tier.COARSE:
        return CoarseConfig(in_features=coarse_feature_count(config.coarse_features), width=config.width,
                            decompose=config.decompose)
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

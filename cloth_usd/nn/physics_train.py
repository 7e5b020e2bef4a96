"""Training the generators on the garment's own physics: no simulated data.

The objective is the garment's energy (:mod:`cloth_usd.nn.physics`) at the model's
output, quasi-static: membrane strain against the rest garment, bending against its
rest angles, gravity, and a one-sided contact penalty against the posed body (each
garment vertex against the tangent plane of the body vertex nearest to it, found again for
every garment the objective sees, among the associated body vertices: HOOD's and SNUG's
choice; :class:`ContactPoints` ``associated``, tshirt-v4's, keeps each vertex's own
associated body vertex, which pushes back a vertex that slides along the body). Minimising
it per frame asks for the garment at rest in that pose, which is what a per-frame model can
learn (SNUG, PBNS).

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

The dynamic variant (:class:`PhysicsOptions` ``dynamic``, the ``"physics"`` table of the
run's ``--config`` file, :func:`load_physics_config`) trains on windows of three
consecutive frames ``t-2, t-1, t`` of one clip: the model is evaluated on all three and the
energy at ``t`` adds implicit Euler's inertia ``inertia_energy(x_t, x_{t-1}, x_{t-2},
dt=1/fps)`` (and, optionally, the lagged friction against the body), SNUG's and HOOD's
objective for a per-frame model. The history is detached by default: then a minimum of the
loss satisfies the implicit Euler step ``m (x_t - 2 x_{t-1} + x_{t-2}) / h^2 = -grad E(x_t)``
at every frame, the equation of motion. Backpropagated through, a minimum also answers for
each frame's part in the next two frames' inertia: the summed squared accelerations of the
clip are smoothed, which is not the equation of motion. (Measured on the probe of docs/models.md,
"Training on the garment's physics", the inertia there is 1e-5 of the energy and the two
gradients differ by 2e-5 of their norm.)
The clip's frame rate is its motion's (``MotionSpec.fps``); frames before ``t = 2`` and a
clip's warm-up are never ``t``.

The hybrid objective (``TrainConfig.objective`` ``hybrid``, ``sim_data`` a ``cloth-usd
datagen`` folder of the same config) adds, on every clip whose sequence was simulated there,
a supervised term at each frame ``t``: ``supervised_weight / 2 * sum_n m_n |x_n - y_n|^2``
[J], ``m_n`` the vertex masses and ``y`` the tier's supervised target (the coarse tier: the
simulation smoothed as ``TrainConfig.coarse_target`` says, as supervised training; the detail
tier: the simulation), turned into the frame the models see like the poses. Weighted by mass,
the term is a spring pulling every vertex with the acceleration ``supervised_weight x
distance`` whatever the garment's size or resolution, so the weight [1/s^2] compares with
gravity (equal at ``9.81 / supervised_weight`` m). Other clips train on the energy alone. A
shard is used only when its manifest status is ``ok`` and its poses, translation, body and
garment topology are the clip's (the shard's frames are the clip's one to one, warm-up
included; the warm-up is never ``t``). Validation reports the energy as for physics and, as
``val_mm``, the mean distance [mm] to the target on the validation clips that were simulated.
"""

from __future__ import annotations

import copy
import dataclasses
import enum
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
from ..core.heading import Heading, HeadingFrame, heading_frame
from ..core.pipeline import (CoarseBase, CoarseFeatures, GarmentPair, coarse_base_points, coarse_model_features,
                             detail_model_inputs, pose_body, prepare_pair)
from ..core.postprocess import nearest_vertex
from ..core.scene import Category, Tier
from ..errors import ArgumentError, ClothUsdError
from .data import CoarseTarget, Moments, Split, plan_batches
from .physics import GarmentRest, Material, contact_normal_force, friction_energy, garment_energy, garment_rest
from .train import (CHECKPOINT, CURVE, RUN, RUN_FORMAT, EpochRecord, Objective, TrainConfig, TrainResult, _atomic_text,
                    _coarse_forward, _detail_forward, _record_epoch, _start_epoch, _step, _Tensors, build_model,
                    plot_history)

__all__ = ["PhysicsClip", "PhysicsSet", "PhysicsOptions", "ContactPoints", "physics_set", "load_physics_config", "window_batches",
           "train_physics", "PHYSICS_FIT", "VAL_TERMS", "OUTPUT_SCALE", "TERMS"]

log = logging.getLogger(__name__)

#: The fit model of a physics run's pairs, in its run folder.
PHYSICS_FIT = "fit.npz"
#: Per epoch, the validation energy terms of the model's garment and of its base [J a frame].
VAL_TERMS = "val_terms.csv"
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
#: The energy terms of the objective, in order (``total`` is their sum).
TERMS = ("membrane", "bending", "gravity", "contact", "inertia", "friction")
#: A dynamic window: the frames ``t - 2, t - 1, t`` as offsets from ``t``.
WINDOW = (-2, -1, 0)


class ContactPoints(str, enum.Enum):
    """The body point a garment vertex's contact term is measured against."""

    NEAREST = "nearest"
    """The associated body vertex nearest to where the vertex is now (found again for every
    garment the objective sees, as HOOD and SNUG do). The default: measured on the Newton test
    set, Newton's own garment is then near a minimum (4-10 J a frame against skinning's
    2500-3000), where with ``associated`` it scored 15,000-73,000 J, ten to thirty times
    worse than skinning (docs/models.md, ``bench/bench_energy_minimum.py``)."""
    ASSOCIATED = "associated"
    """The vertex's own associated body vertex, fixed from the rest pose (tshirt-v4's
    objective): a vertex that slides along the body is measured against the plane of a body
    point it has left, and pushed back."""


@dataclass(frozen=True)
class PhysicsOptions:
    """The physics objective's own settings: the ``"physics"`` table of a physics run's
    ``--config`` file (:func:`load_physics_config`), recorded in run.json."""

    dynamic: bool = False
    """Train on windows of frames ``t-2, t-1, t`` of one clip, the energy at ``t`` with
    implicit Euler's inertia over the window (``dt`` = 1 / the clip's fps); False: the
    quasi-static energy per frame. A batch is ``batch`` windows (three frames each)."""
    detach_history: bool = True
    """Dynamic only: ``x_{t-1}`` and ``x_{t-2}`` enter the inertia (and friction) as
    constants, so a minimum is an implicit Euler step at every frame; False backpropagates
    into them too (the clip's squared accelerations smoothed, not the equation of motion)."""
    friction: bool = False
    """Dynamic only: add the lagged smooth Coulomb friction against the body over the step
    ``t-1 -> t`` (:func:`~cloth_usd.nn.physics.friction_energy`, the normal force held at
    ``x_t``'s contact force)."""
    friction_epsilon: float = 1.0e-2
    """Slip speed [m/s] below which friction is smoothed (Newton's ``friction_epsilon``)."""
    contact: ContactPoints = ContactPoints.NEAREST
    """Which body point each garment vertex's contact is measured against
    (:class:`ContactPoints`)."""
    anchor_weight: float = 0.0
    """Only with an initial run (``cloth-usd train --init``) [1/s^2]: adds
    ``anchor_weight / 2 * sum_n m_n |x_n - x0_n|^2`` [J] at every frame ``t``, ``x0`` the
    initial run's own garment for the same inputs (the hybrid objective's spring, pulling
    toward the model the run started from instead of toward a simulation). It keeps what the
    initial model learned (from simulated frames that stayed on the machine that made them)
    while the energy takes out what is not cloth in it: the body inside the garment and
    stretched triangles. 0: the physics objective alone from the initial weights."""

    def __post_init__(self) -> None:
        try:
            object.__setattr__(self, "contact", ContactPoints(self.contact))
        except ValueError:
            raise ArgumentError(f"PhysicsOptions.contact must be one of {', '.join(c.value for c in ContactPoints)}, "
                                f"got {self.contact!r}") from None
        for name in ("dynamic", "detach_history", "friction"):
            if not isinstance(getattr(self, name), bool):
                raise ArgumentError(f"PhysicsOptions.{name} must be true or false, got {getattr(self, name)!r}")
        if not (isinstance(self.friction_epsilon, (int, float)) and self.friction_epsilon > 0):
            raise ArgumentError(f"PhysicsOptions.friction_epsilon must be > 0 [m/s], got {self.friction_epsilon!r}")
        if self.friction and not self.dynamic:
            raise ArgumentError("PhysicsOptions.friction needs dynamic: true (friction acts over a time step)")
        if not (isinstance(self.anchor_weight, (int, float)) and self.anchor_weight >= 0):
            raise ArgumentError(f"PhysicsOptions.anchor_weight must be >= 0 [1/s^2], got {self.anchor_weight!r}")

    @property
    def window(self) -> tuple[int, ...]:
        """Frame offsets from ``t`` of one example: (-2, -1, 0) dynamic, (0,) quasi-static."""
        return WINDOW if self.dynamic else (0,)

    def to_json(self) -> dict:
        return {**dataclasses.asdict(self), "contact": self.contact.value}

    @classmethod
    def from_mapping(cls, raw, source: str = "physics") -> PhysicsOptions:
        """Build from a mapping; unknown keys are an error that names them and the valid ones."""
        from ..core.files import check_keys

        return cls(**check_keys(raw, cls, source))


def load_physics_config(path: str | Path | None, **overrides) -> tuple[TrainConfig, PhysicsOptions]:
    """A physics run's ``--config`` file: TrainConfig keys plus an optional ``"physics"`` table
    of :class:`PhysicsOptions` keys. ``overrides`` (None values ignored) set TrainConfig keys.

    Raises:
        ArgumentError: an unreadable file, unknown keys, or values out of range.
    """
    from ..core.files import read_config

    raw: dict = {}
    if path is not None:
        raw = read_config(Path(path), "the --config training config")
        if not isinstance(raw, dict):
            raise ArgumentError(f"--config {path}: expected a table of TrainConfig keys")
    raw = dict(raw)
    options = PhysicsOptions.from_mapping(raw.pop("physics", {}), f"--config {path}: physics")
    train_raw = {**raw, **{k: v for k, v in overrides.items() if v is not None}}
    return TrainConfig.from_mapping(train_raw, str(path) if path is not None else "config"), options


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
    fps: float = 24.0
    """Frame rate of the motion [1/s] (its ``MotionSpec.fps``); the dynamic objective's
    time step is ``1 / fps``."""
    target: np.ndarray | None = None
    """(T', N, 3) float32 the hybrid objective's simulated target [m] (the simulation, or its
    coarse target), in the frame of ``poses``: of every frame (T' = T), or of the first T' where
    the simulation went unstable and the data set kept its frames before (``SimConfig.keep_partial``);
    None: the sequence was not simulated."""

    @property
    def num_frames(self) -> int:
        """T."""
        return int(self.poses.shape[0])

    @property
    def dt(self) -> float:
        """Time between frames [s]."""
        return 1.0 / self.fps


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
                bending_scale: float = 1.0, contact_margin: float | None = None,
                mocap_dir: str | Path | None = None,
                sim_data: str | Path | None = None, sim_target: CoarseTarget | str | None = None,
                fit: FitModel | None = None) -> PhysicsSet:
    """Plan a data set config's sequences (no simulation) for the physics objective.

    Args:
        config_path: a ``cloth-usd datagen`` config (.json / .toml).
        body: the body model (the embedded one when None).
        heading: the frame the models see (:class:`~cloth_usd.core.heading.Heading`).
        splits: the splits to keep (all when None).
        max_frames: cut every sequence to its first frames.
        bending_scale: multiplies the material's bending stiffness.
        contact_margin: the contact margin [m] instead of the simulator's (``TrainConfig.contact_margin``).
        mocap_dir: the folder the config's BVH motions are relative to (see
            :func:`~cloth_usd.datagen.factory.load_config`).
        sim_data: a ``cloth-usd datagen`` folder of this config: every clip whose sequence it
            holds (status ``ok``) gets its :attr:`PhysicsClip.target` (the hybrid objective).
        sim_target: the target made from the simulation: a coarse target
            (:class:`~cloth_usd.nn.data.CoarseTarget`), or the simulation itself when None.
        fit: the fit attribute model (an initial run's); None fits one on the config's training
            pairs as planned.
    Raises:
        ArgumentError: ``sim_data`` is not a data set of this config (one line naming it).
    """
    from ..core.files import file_sha256
    from ..datagen.factory import fit_training_pairs, load_config, plan_jobs
    from ..datagen.simulate import SimConfig

    config_path = Path(config_path)
    body = body if body is not None else load_body_model()
    factory = load_config(config_path, mocap_dir=mocap_dir)
    jobs = plan_jobs(factory, body)
    if fit is None:
        fit, _ = fit_training_pairs(jobs, body)
    base = Material.from_sim_config(SimConfig(**factory.sim))
    material = dataclasses.replace(base, bend_stiffness=base.bend_stiffness * bending_scale)
    if contact_margin is not None:
        material = dataclasses.replace(material, contact_margin=float(contact_margin))
    keep = None if splits is None else {Split(s) for s in splits}
    simulated = _sim_entries(Path(sim_data), config_path, jobs, base) if sim_data is not None else {}
    pairs: dict[str, tuple[GarmentPair, GarmentRest]] = {}
    clips = []
    for job in jobs:
        split = Split(job.meta["split"])
        if keep is not None and split not in keep:
            continue
        key = f"shirt{job.meta['shirt']}.{job.meta['body']}"
        if key not in pairs:
            pair = prepare_pair(body, job.betas, job.garment_vertices, job.garment_faces, fit,
                                category=job.meta.get("category", Category.TSHIRT.value))
            pairs[key] = pair, garment_rest(job.garment_vertices, job.garment_faces, material)
        pair, rest = pairs[key]
        poses, transl = job.poses[:max_frames], job.transl[:max_frames]
        target = None
        if job.name in simulated:  # the shard's frames are the job's, one to one
            target = _sim_frames(Path(sim_data), simulated[job.name], job, config_path, sim_target)[:max_frames]
        if Heading(heading) is Heading.CANONICAL:
            frame = heading_frame(poses, transl, pair.joints[0])
            poses = frame.canonical_poses(poses)
            if target is not None:  # a kept part of an unstable sequence covers its first frames only
                first = HeadingFrame(frame.yaw[:len(target)], frame.pivot[:len(target)])
                target = first.to_canonical(target).astype(np.float32)
        clips.append(PhysicsClip(name=job.name, split=split, pair=pair, rest=rest,
                                 rest_points=np.asarray(job.garment_vertices, dtype=np.float64),
                                 poses=np.asarray(poses, dtype=np.float64),
                                 transl=np.asarray(transl, dtype=np.float64), meta=dict(job.meta),
                                 fps=float(job.meta["fps"]),
                                 target=target))
    return PhysicsSet(config_sha256=file_sha256(config_path), fit=fit, material=material, clips=tuple(clips))


def _sim_entries(sim_data: Path, config_path: Path, jobs, material: Material) -> dict[str, dict]:
    """The manifest entries of ``sim_data`` (status ``ok``) by job name, once the folder is
    known to be simulated from ``config_path``: it shares sequences with it and its solver
    settings give the same ``material``.

    Raises:
        ArgumentError: naming ``sim_data``, when it is not a data set of this config.
    """
    from ..core.shards import DatasetError, Manifest
    from ..datagen.simulate import SimConfig

    try:
        manifest = Manifest.read(sim_data)
    except DatasetError:
        raise ArgumentError(f"--sim-data {sim_data}: not a data set folder (no readable manifest.json; make one "
                            f"with cloth-usd datagen {config_path})") from None
    names = {job.name for job in jobs}
    if not names & set(manifest.sequences):
        raise ArgumentError(f"--sim-data {sim_data}: none of its sequences is one {config_path} plans "
                            "(a data set of another config?)")
    try:
        same = Material.from_sim_config(SimConfig(**manifest.config)) == material
    except (TypeError, ValueError, ClothUsdError) as exc:
        raise ArgumentError(f"--sim-data {sim_data}: its manifest's solver settings are unreadable ({exc})") from None
    if not same:
        raise ArgumentError(f"--sim-data {sim_data}: simulated with another material than {config_path}'s sim "
                            "settings (a data set of another config?)")
    return {name: entry for name, entry in manifest.sequences.items()
            if name in names and entry.get("status") == "ok" and entry.get("shard")}


def _sim_frames(sim_data: Path, entry: dict, job, config_path: Path,
                sim_target: CoarseTarget | str | None) -> np.ndarray:
    """(T', N, 3) float32 a job's simulated target [m], world frame: every frame of the job, or its
    first T' where the data set kept the part of an unstable sequence (``SimConfig.keep_partial``).

    Raises:
        ArgumentError: the shard is unreadable, or holds another sequence than ``job``.
    """
    from ..core.shards import DatasetError, read_shard

    path = sim_data / entry["shard"]
    try:
        shard = read_shard(path)
    except DatasetError as exc:
        raise ArgumentError(f"--sim-data: {exc}") from None

    def same(a, b) -> bool:
        a, b = np.asarray(a), np.asarray(b)
        return a.shape == b.shape and np.allclose(a, b, rtol=0.0, atol=1e-9)

    frames = shard.poses.shape[0]
    if not (same(shard.poses, job.poses[:frames]) and same(shard.transl, job.transl[:frames])
            and same(shard.betas, job.betas) and same(shard.garment_faces, job.garment_faces)):
        raise ArgumentError(f"--sim-data {sim_data}: {path.name} holds another sequence than the one {config_path} "
                            f"plans as {job.name} (poses, body or garment differ: a data set of another config?)")
    if sim_target is None:
        return shard.positions.astype(np.float32)
    if CoarseTarget(sim_target) is CoarseTarget.STORED:
        return shard.coarse.astype(np.float32)
    from .data import taubin_smooth

    return taubin_smooth(shard.positions.astype(np.float64), shard.garment_faces).astype(np.float32)


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
    cloud_points: np.ndarray
    """(B, C, 3) float64 the posed associated body vertices [m], each once: the candidates
    of :attr:`ContactPoints.NEAREST`."""
    cloud_normals: np.ndarray
    """(B, C, 3) float64 their normals."""


class _Tier:
    """What one tier's physics training computes per batch, the model call included."""

    def __init__(self, tier: Tier, body: BodyModel, base: CoarseBase, tensors: _Tensors, coarse_model=None,
                 features: CoarseFeatures = CoarseFeatures.BODY) -> None:
        self.tier, self.body, self.base, self.tensors, self.coarse_model = tier, body, base, tensors, coarse_model
        self.features = features

    def inputs(self, clip: PhysicsClip, frames: np.ndarray) -> _Inputs:
        poses, transl = clip.poses[frames], clip.transl[frames]
        posed = pose_body(self.body, clip.pair, poses, transl)
        base = coarse_base_points(self.body, clip.pair, posed, poses, transl, self.base)
        feats = coarse_model_features(clip.pair, posed, transl, self.features, base=base)
        cloud = clip.pair.patch.contact
        contact = (posed.garment_points, posed.garment_normals, posed.patch_points[:, cloud],
                   posed.patch_normals[:, cloud])
        if self.tier is Tier.COARSE:
            return _Inputs(feats, None, base, *contact)
        with torch.no_grad():  # the coarse model's M_coarse, as the runtime makes it (before the post-process)
            m_coarse = base + _coarse_forward(self.coarse_model, feats, clip.pair.graph, self.tensors).cpu().numpy()
        feats, attrs = detail_model_inputs(clip.pair, m_coarse, posed, poses, transl)
        return _Inputs(feats, attrs, m_coarse, *contact)

    def forward(self, model, clip: PhysicsClip, inp: _Inputs) -> torch.Tensor:
        """(B, N, 3) float64 the model's garment [m]."""
        if inp.attributes is None:
            delta = _coarse_forward(model, inp.features, clip.pair.graph, self.tensors)
        else:
            delta = _detail_forward(model, inp.features, inp.attributes, clip.pair.graph, self.tensors)
        return torch.from_numpy(inp.base).to(delta.device) + delta.double()


def _energy(clip: PhysicsClip, x: torch.Tensor, inp: _Inputs, material: Material,
            contact: ContactPoints = ContactPoints.NEAREST) -> torch.Tensor:
    """(B,) the quasi-static energy [J] of garments ``x`` (B, N, 3), each at its own frame of ``inp``."""
    return _terms(clip, x, _Window(inp, np.arange(x.shape[0])[None]), material,
                  PhysicsOptions(contact=contact))["total"]


def _statistics(model, step: _Tier, clips: Sequence[PhysicsClip], config: TrainConfig) -> None:
    """Input statistics from the training frames, the fixed :data:`OUTPUT_SCALE`, and a start
    near the base: the last layers are shrunk so a fresh model moves the garment by about a
    millimetre, not by :data:`OUTPUT_SCALE` in random directions (which tears the membrane:
    hundreds of J against the skinned garment's few, a hole the optimiser climbs out of slowly)."""
    feats, attrs = Moments(model.config.in_features), Moments(85)
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


def window_batches(clips: Sequence[PhysicsClip], batch: int, rng: np.random.Generator | None = None, *,
                   frames: int | None = None, window: Sequence[int] = WINDOW) -> list[tuple[int, np.ndarray]]:
    """Batches of examples, each a window of frames ``t + window`` of one clip (a batch shares
    one garment graph), as :func:`~cloth_usd.nn.data.plan_batches` plans frames.

    Every ``t`` whose window lies inside the clip and after its warm-up (``meta["warmup_frames"]``,
    the frames a mocap clip eases in over) is an example: ``t >= 2`` for the dynamic window
    (-2, -1, 0); a clip too short for one window gives none.

    Args:
        clips: the clips.
        batch: windows per batch (B).
        rng: shuffles the windows of every clip and the batch order; None keeps both in order.
        frames: use only this many evenly spread windows per clip (all when None).
        window: frame offsets from ``t``, all <= 0 (:attr:`PhysicsOptions.window`).
    Returns:
        ``[(clip index, t (B',) int64), ...]``, B' <= B.
    """
    if batch < 1:
        raise ArgumentError(f"batch must be >= 1 window, got {batch}")
    if not window or max(window) != 0:
        raise ArgumentError(f"window: offsets from t ending at 0, got {tuple(window)}")
    first = [max(-min(window), int(clip.meta.get("warmup_frames", 0))) for clip in clips]
    return plan_batches(clips, batch, rng, frames=frames, first=first)


@dataclass(frozen=True)
class _Window:
    """A batch of windows: the inputs of their distinct frames and where each window's are."""

    inputs: _Inputs
    """Of the U distinct frames of the batch, ascending."""
    index: np.ndarray
    """(W, B) int64 rows of ``inputs``: frame ``t_b + window[w]`` (the last row: t)."""


def _window(step: _Tier, clip: PhysicsClip, t: np.ndarray, options: PhysicsOptions) -> _Window:
    frames = np.asarray(t, dtype=np.int64)[None, :] + np.asarray(options.window, dtype=np.int64)[:, None]
    distinct, index = np.unique(frames, return_inverse=True)  # overlapping windows share their frames
    return _Window(step.inputs(clip, distinct), index.reshape(frames.shape))


def _terms(clip: PhysicsClip, x: torch.Tensor, win: _Window, material: Material,
           options: PhysicsOptions) -> dict[str, torch.Tensor]:
    """The objective's terms at each window's frame t, each (B,) [J], and their ``total``.

    Args:
        x: (U, N, 3) float64 garments [m] at the window's distinct frames.
    """
    index = torch.from_numpy(win.index).to(x.device)
    now = index[-1]
    x_t = x[now]
    if options.contact is ContactPoints.NEAREST:
        nearest = nearest_vertex(x_t.detach().cpu().numpy(), win.inputs.cloud_points[win.index[-1]])
        rows = torch.arange(len(nearest), device=x.device)[:, None]
        nearest = torch.from_numpy(nearest).to(x.device)
        points = torch.from_numpy(win.inputs.cloud_points).to(x)[index][:, rows, nearest]
        normals = torch.from_numpy(win.inputs.cloud_normals).to(x)[index][:, rows, nearest]
    else:
        points = torch.from_numpy(win.inputs.body_points).to(x)[index]
        normals = torch.from_numpy(win.inputs.body_normals).to(x)[index]
    p_t, n_t = points[-1], normals[-1]
    previous = None
    if options.dynamic:
        previous = (x[index[1]], x[index[0]])
        if options.detach_history:
            previous = (previous[0].detach(), previous[1].detach())
    terms = garment_energy(x_t, clip.rest, material, body_points=p_t, body_normals=n_t, previous=previous,
                           dt=clip.dt if previous is not None else None).as_dict()
    terms.pop("total")
    terms["friction"] = x_t.new_zeros(x_t.shape[0])
    if options.friction:
        force = contact_normal_force(x_t, p_t, n_t, material)  # lagged: a constant of this step
        terms["friction"] = friction_energy(x_t, previous[0], p_t, points[1], n_t, force, material,
                                            dt=clip.dt, epsilon=options.friction_epsilon)
    terms["total"] = sum(terms[name] for name in TERMS)
    return terms


def _spring(clip: PhysicsClip, x_t: torch.Tensor, y: torch.Tensor, weight: float) -> torch.Tensor:
    """(B,) ``weight / 2 * sum_n m_n |x_n - y_n|^2`` [J] of garments ``x_t`` (B, N, 3) [m]
    against ``y`` (B, N, 3) [m], ``m_n`` the clip's vertex masses, ``weight`` [1/s^2]."""
    masses = clip.rest.masses.to(x_t)
    return 0.5 * weight * (masses * ((x_t - y.to(x_t)) ** 2).sum(-1)).sum(-1)


def _supervised(clip: PhysicsClip, x_t: torch.Tensor, t: np.ndarray, weight: float) -> torch.Tensor | None:
    """(B,) the hybrid objective's supervised term [J] at frames ``t`` (B,) of garments
    ``x_t`` (B, N, 3) [m]: :func:`_spring` toward the clip's :attr:`~PhysicsClip.target`, 0 at a
    frame past the target's last (a kept part of an unstable sequence); None for a clip without
    one, or where no frame of ``t`` has a target."""
    have = _targeted(clip, t)
    if have is None:
        return None
    t = np.minimum(np.asarray(t, dtype=np.int64), clip.target.shape[0] - 1)
    term = _spring(clip, x_t, torch.from_numpy(clip.target[t]), weight)
    return term * torch.from_numpy(have).to(term)


def _targeted(clip: PhysicsClip, t: np.ndarray) -> np.ndarray | None:
    """(B,) bool: which of frames ``t`` have a simulated target; None where none has."""
    if clip.target is None:
        return None
    have = np.asarray(t, dtype=np.int64) < clip.target.shape[0]
    return have if have.any() else None


@dataclass(frozen=True)
class _Anchor:
    """:attr:`PhysicsOptions.anchor_weight`'s spring toward the initial run's garment."""

    model: torch.nn.Module
    """The initial run's model, frozen."""
    weight: float
    """[1/s^2]."""

    def garment(self, step: "_Tier", clip: PhysicsClip, win: "_Window") -> torch.Tensor:
        """(B, N, 3) the initial model's garment [m] at the window's frames t."""
        with torch.no_grad():
            return step.forward(self.model, clip, _rows(win.inputs, win.index[-1]))

    def term(self, clip: PhysicsClip, x_t: torch.Tensor, x0: torch.Tensor) -> torch.Tensor:
        """(B,) the spring [J] of garments ``x_t`` toward :meth:`garment` ``x0``."""
        return _spring(clip, x_t, x0, self.weight)


def _rows(inputs: _Inputs, rows: np.ndarray) -> _Inputs:
    """``inputs`` of the frames ``rows`` only."""
    values = (getattr(inputs, f.name) for f in dataclasses.fields(inputs))
    return _Inputs(*(None if value is None else value[rows] for value in values))


@dataclass(frozen=True)
class _Validation:
    """Validation means per window (frame t) [J], and the distance from the base [mm]."""

    model: dict[str, float]
    base: dict[str, float]
    mm: float
    supervised: float = 0.0
    """Hybrid: the supervised term's mean per window [J] (0 on windows without a target)."""
    sim_mm: float = math.nan
    """Hybrid: the mean distance [mm] to the target over the windows that have one (NaN: none)."""
    anchor: float = 0.0
    """With an anchor: its spring's mean per window [J]."""
    anchor_mm: float = math.nan
    """With an anchor: the mean distance [mm] from the initial run's garment (NaN: no anchor)."""

    @property
    def relative(self) -> float:
        """The model's total energy above its base's [J] (below 0: lower)."""
        return self.model["total"] - self.base["total"]


def _validate(model, step: _Tier, clips: Sequence[PhysicsClip], config: TrainConfig, material: Material,
              options: PhysicsOptions = PhysicsOptions(), weight: float | None = None,
              anchor: _Anchor | None = None) -> _Validation:
    """The objective on the validation windows, for the model's garment and its base (the
    skinned garment for the coarse tier, the coarse model's for the detail tier; dynamic: each
    with its own history), and the mean distance between them at frame t. ``weight`` (the
    hybrid objective's, None: physics) adds the supervised term and the distance to the target;
    ``anchor`` its spring and the distance to the initial run's garment."""
    names = (*TERMS, "total")
    if not clips:
        nan = {name: math.nan for name in names}
        return _Validation(nan, dict(nan), math.nan, math.nan if weight is not None else 0.0)
    model.eval()
    sums = {"model": dict.fromkeys(names, 0.0), "base": dict.fromkeys(names, 0.0)}
    dist = supervised = sim_dist = spring = anchor_dist = 0.0
    count = vertices = sim_vertices = 0
    with torch.no_grad():
        for k, t in window_batches(clips, config.batch, frames=config.val_frames or None, window=options.window):
            clip = clips[k]
            win = _window(step, clip, t, options)
            x = step.forward(model, clip, win.inputs).cpu()
            base = torch.from_numpy(win.inputs.base)
            for who, garment in (("model", x), ("base", base)):
                for name, value in _terms(clip, garment, win, material, options).items():
                    sums[who][name] += float(value.sum())
            now = torch.from_numpy(win.index[-1])
            dist += float(torch.linalg.vector_norm(x[now] - base[now], dim=-1).sum())
            count += len(t)
            vertices += len(t) * x.shape[1]
            term = _supervised(clip, x[now], t, weight) if weight is not None else None
            if term is not None:
                supervised += float(term.sum())
                have = _targeted(clip, t)
                y = torch.from_numpy(clip.target[np.asarray(t, dtype=np.int64)[have]]).to(x)
                sim_dist += float(torch.linalg.vector_norm(x[now][torch.from_numpy(have)] - y, dim=-1).sum())
                sim_vertices += int(have.sum()) * x.shape[1]
            if anchor is not None:
                x0 = anchor.garment(step, clip, win).cpu()
                spring += float(anchor.term(clip, x[now], x0).sum())
                anchor_dist += float(torch.linalg.vector_norm(x[now] - x0, dim=-1).sum())
    if not count:
        raise ArgumentError(f"no validation window: every validation clip is shorter than {len(options.window)} "
                            "frames (after its warm-up)")
    mean = {who: {name: v / count for name, v in terms.items()} for who, terms in sums.items()}
    return _Validation(mean["model"], mean["base"], dist / vertices * 1000.0, supervised / count,
                       sim_dist / sim_vertices * 1000.0 if sim_vertices else math.nan, spring / count,
                       anchor_dist / vertices * 1000.0 if anchor is not None else math.nan)


def _write_val_terms(path: Path, rows: list[tuple[int, _Validation]], hybrid: bool = False,
                     anchored: bool = False) -> None:
    """``val_terms.csv``; ``hybrid`` adds the supervised term [J] and the distance to the target [mm],
    ``anchored`` the anchor's spring [J] and the distance to the initial run's garment [mm]."""
    names = (*TERMS, "total")
    extra = (["supervised", "sim_mm"] if hybrid else []) + (["anchor", "anchor_mm"] if anchored else [])
    lines = [",".join(["epoch", *(f"{who}_{n}" for who in ("model", "base") for n in names), "mm", *extra])]
    for epoch, v in rows:
        more = ([f"{v.supervised:.9g}", f"{v.sim_mm:.6g}"] if hybrid else []) + \
            ([f"{v.anchor:.9g}", f"{v.anchor_mm:.6g}"] if anchored else [])
        lines.append(",".join([str(epoch), *(f"{getattr(v, who)[n]:.9g}" for who in ("model", "base") for n in names),
                               f"{v.mm:.6g}", *more]))
    _atomic_text("\n".join(lines) + "\n", path)


def _hybrid_record(sim_data: Path, config: TrainConfig, tier: Tier, train_clips: Sequence[PhysicsClip],
                   val_clips: Sequence[PhysicsClip]) -> dict:
    """run.json's ``hybrid``: the simulated data, the weight and target, the clips with frames."""
    from ..core.files import file_sha256

    with_target = {name: sum(c.target is not None for c in clips)
                   for name, clips in (("train", train_clips), ("val", val_clips))}
    if not with_target["train"]:
        log.warning("--sim-data %s: no training sequence was simulated there; the hybrid run trains on the energy "
                    "alone", sim_data)
    if val_clips and not with_target["val"]:
        log.warning("--sim-data %s: no validation sequence was simulated there; val_mm is NaN", sim_data)
    return {"sim_data": str(sim_data.resolve()), "sim_manifest_sha256": file_sha256(sim_data / "manifest.json"),
            "supervised_weight": config.supervised_weight, "supervised_weight_unit": "1/s^2",
            "target": "simulation" if tier is Tier.DETAIL else f"coarse target ({config.coarse_target.value})",
            "train_sequences_simulated": with_target["train"], "val_sequences_simulated": with_target["val"],
            "val_mm": "mean distance to the target [mm] on the simulated validation sequences"}


def _initial_run(init_run: str | Path, tier: Tier, config: TrainConfig, form, device):
    """``init_run`` loaded, once it is known to be a run this one can start from, and the fit
    attribute model it was trained with (a physics run's ``fit.npz``, else its data set's;
    the attributes the detail model learned are that model's, and the bundle ships it).

    Raises:
        ArgumentError: naming ``init_run``: another tier or model (width, decomposition,
            parser), a coarse run of another ``form`` (base, heading, features), or no fit
            attribute model at hand.
    """
    from .train import load_run

    init = load_run(init_run, device=device)
    where = f"--init {init_run}"
    if init.tier is not tier:
        raise ArgumentError(f"{where}: a {init.tier.value} run; this run trains the {tier.value} tier")
    for key in ("width", "decompose", "use_parser"):
        if getattr(init.config, key) != getattr(config, key):
            raise ArgumentError(f"{where}: its {key} is {getattr(init.config, key)!r}, the --config's "
                                f"{getattr(config, key)!r}; give the config the initial run's")
    if tier is Tier.COARSE and init.config.coarse_form != form:
        raise ArgumentError(f"{where}: its coarse_base, heading and coarse_features are {init.config.coarse_form}, "
                            f"the --config's {form}; give the config the initial run's")
    own = [Path(init_run) / PHYSICS_FIT]  # a physics run's own; a supervised run's data set's
    if (init.info.get("data") or {}).get("path"):
        own.append(Path(init.info["data"]["path"]) / PHYSICS_FIT)
    found = next((path for path in own if path.is_file()), None)
    if found is None:
        raise ArgumentError(f"{where}: its fit attribute model is not at hand (no {' or '.join(map(str, own))}); "
                            f"copy the fit.npz of the data set it was trained on into {init_run}")
    return init, FitModel.load(found)


def train_physics(config_path: str | Path, run_dir: str | Path, config: TrainConfig = TrainConfig(
        objective=Objective.PHYSICS, coarse_base=CoarseBase.SKINNED), *, tier: Tier | str = Tier.COARSE,
        coarse_run: str | Path | None = None, device: str | None = "auto", body: BodyModel | None = None,
        progress: Callable[[EpochRecord], None] | None = None,
        options: PhysicsOptions = PhysicsOptions(), mocap_dir: str | Path | None = None,
        sim_data: str | Path | None = None, init_run: str | Path | None = None) -> TrainResult:
    """Train a generator on the physics (or hybrid) objective (see the module docstring).

    Args:
        config_path: the data set config whose pairs and motions it trains on.
        run_dir: the run folder to create.
        config: ``objective`` must be ``physics`` or ``hybrid`` (its ``supervised_weight``
            weighs the supervised term); ``bending_scale`` scales the bending
            (10 for the coarse tier's drape; 1, the material's, for the detail tier).
        tier: coarse, or detail on top of ``coarse_run`` (its predictions are ``M_coarse``;
            the detail run takes its heading and coarse base).
        coarse_run: the trained coarse run folder (detail only).
        device: torch device (auto: CUDA when available).
        progress: called after every epoch.
        options: the objective (quasi-static or dynamic, friction; :class:`PhysicsOptions`),
            recorded in run.json under ``physics.options``. Dynamic: ``config.batch`` counts
            windows of three frames, and the validation energy (and ``val_terms.csv``)
            includes each garment's inertia over its own history.
        mocap_dir: the folder the config's BVH motions are relative to.
        sim_data: hybrid only (and needed there): the ``cloth-usd datagen`` folder simulated
            from ``config_path``; its training and validation sequences are the targets.
            run.json records it under ``hybrid`` (how many clips had simulated frames), and
            ``val_mm`` is the validation distance to the target [mm].
        init_run: start from this trained run's best model (its weights and input statistics)
            instead of a fresh one: a run of the same tier, width and form (a coarse run's base,
            heading and features), trained on any objective, e.g. supervised on simulated
            frames that never left the machine that made them. ``options.anchor_weight`` then
            adds the spring toward its garment; ``val_mm`` is the validation distance to it
            [mm] when the anchor is on. run.json records it under ``init_run``.
    Raises:
        ArgumentError: a run exists in ``run_dir``, the config has no training pairs, the
            tier and ``coarse_run`` do not go together, ``sim_data`` is missing, not
            wanted or not a data set of ``config_path``, or ``init_run`` is not a run this
            one can start from (another tier, width or form, no fit attribute model at hand),
            or an anchor is asked for without it.
    """
    from .train import _coarse_run_record, _trainable, load_run, pick_device

    tier = _trainable(tier, "train_physics: tier")
    if config.objective not in (Objective.PHYSICS, Objective.HYBRID):
        raise ArgumentError(f"train_physics: config.objective is {config.objective.value!r}, not 'physics' or 'hybrid'")
    hybrid = config.objective is Objective.HYBRID
    if hybrid != (sim_data is not None):
        raise ArgumentError("--sim-data: the hybrid objective needs the datagen folder simulated from --data, "
                            "and only the hybrid objective reads one")
    if (tier is Tier.DETAIL) != (coarse_run is not None):
        raise ArgumentError("train_physics: the detail tier needs --coarse-run (the trained coarse run), "
                            "the coarse tier takes none")
    if options.anchor_weight and init_run is None:
        raise ArgumentError("physics.anchor_weight: the anchor pulls toward the initial run's garment; give --init RUN")
    run_dir = Path(run_dir)
    if (run_dir / CHECKPOINT).exists():
        raise ArgumentError(f"--out {run_dir}: a run exists there; pick a new folder")
    dev = pick_device(device)
    body = body if body is not None else load_body_model()
    coarse = load_run(coarse_run, device=dev) if coarse_run is not None else None
    if coarse is not None and coarse.tier is not Tier.COARSE:
        raise ArgumentError(f"--coarse-run {coarse_run}: is a {coarse.tier.value} run, not a coarse one")
    form = (coarse.config if coarse is not None else config).coarse_form  # a detail run runs as its coarse run
    init, init_fit = _initial_run(init_run, tier, config, form, dev) if init_run is not None else (None, None)
    data = physics_set(config_path, body, heading=form.heading, splits=(Split.TRAIN, Split.VAL),
                       max_frames=config.max_frames or None, bending_scale=config.bending_scale,
                       contact_margin=config.contact_margin,
                       mocap_dir=mocap_dir, sim_data=sim_data,
                       sim_target=config.coarse_target if tier is Tier.COARSE else None, fit=init_fit)
    train_clips, val_clips = data.split(Split.TRAIN), data.split(Split.VAL)
    if not train_clips:
        raise ArgumentError(f"{config_path}: no training sequences")
    if not window_batches(train_clips, 1, window=options.window):
        raise ArgumentError(f"{config_path}: no training sequence has {len(options.window)} frames for the "
                            "dynamic objective's window (raise max_frames)")
    tensors = _Tensors(dev)
    step = _Tier(tier, body, form.base, tensors, coarse.model if coarse is not None else None, form.features)
    torch.manual_seed(config.seed)
    anchor = None
    if init is not None:
        model = init.model.train()
        if options.anchor_weight:
            anchor = _Anchor(copy.deepcopy(init.model).eval().requires_grad_(False), options.anchor_weight)
    else:
        model = build_model(tier, config).to(dev)
        _statistics(model, step, train_clips, config)
    optimizer = torch.optim.Adam(model.parameters(), lr=config.lr)
    run_dir.mkdir(parents=True, exist_ok=True)
    data.fit.save(run_dir / PHYSICS_FIT)
    info = {"format": RUN_FORMAT, "tier": tier.value, "config": config.to_json(),
            "model_config": dataclasses.asdict(model.config),
            "data": {"path": str(Path(config_path).resolve()), "manifest_sha256": data.config_sha256,
                     "train_sequences": len(train_clips), "val_sequences": len(val_clips),
                     "kind": config.objective.value},
            "physics": {"material": dataclasses.asdict(data.material), "fit": PHYSICS_FIT,
                        "options": options.to_json(), "fps": sorted({c.fps for c in data.clips})},
            "coarse_run": _coarse_run_record(coarse) if coarse is not None else None,
            "init_run": _coarse_run_record(init) if init is not None else None,
            "body_model_sha256": body.sha256, "torch": torch.__version__}
    weight = config.supervised_weight if hybrid else None
    if hybrid:
        info["hybrid"] = _hybrid_record(Path(sim_data), config, tier, train_clips, val_clips)
    _atomic_text(json.dumps(info, indent=2, sort_keys=True) + "\n", run_dir / RUN)
    against = "skinning" if tier is Tier.COARSE else "the coarse garment"
    target = "the simulation" if tier is Tier.DETAIL else "the simulation's coarse target"
    measured_from = target if hybrid else "the initial run's garment" if anchor is not None else against
    history: list[EpochRecord] = []
    best_loss, best_epoch = math.inf, -1
    terms_rows: list[tuple[int, _Validation]] = []
    for epoch in range(config.epochs):
        began = time.perf_counter()
        lr, _ = _start_epoch(model, optimizer, train_clips, config, epoch)
        batches = window_batches(train_clips, config.batch, np.random.default_rng([config.seed, epoch]),
                                 window=options.window)
        if config.max_batches:
            batches = batches[:config.max_batches]
        total = 0.0
        for k, t in batches:
            clip = train_clips[k]
            win = _window(step, clip, t, options)
            x = step.forward(model, clip, win.inputs)
            loss = _terms(clip, x, win, data.material, options)["total"]
            x_t = x[torch.from_numpy(win.index[-1]).to(x.device)]  # the garments at each window's t
            term = _supervised(clip, x_t, t, weight) if hybrid else None
            if term is not None:
                loss = loss + term
            if anchor is not None:
                loss = loss + anchor.term(clip, x_t, anchor.garment(step, clip, win))
            total += _step(model, optimizer, loss.mean(), config.grad_clip)
        val = _validate(model, step, val_clips, config, data.material, options, weight, anchor)
        record = EpochRecord(epoch=epoch, train_loss=total / max(len(batches), 1),
                             val_loss=val.relative + val.supervised + val.anchor,
                             val_mm=val.sim_mm if hybrid else val.anchor_mm if anchor is not None else val.mm,
                             lr=lr, seconds=time.perf_counter() - began)
        best_loss, best_epoch = _record_epoch(run_dir, model, optimizer, history, record, best_loss, best_epoch)
        terms_rows.append((epoch, val))
        _write_val_terms(run_dir / VAL_TERMS, terms_rows, hybrid, anchor is not None)
        kind = config.objective.value + (", dynamic" if options.dynamic else "")
        plot_history(history, run_dir / CURVE, title=f"{tier.value} ({kind}): {run_dir.name}",
                     loss_label=f"energy + supervised [J] (validation: energy relative to {against} + supervised)"
                     if hybrid else f"energy [J] (validation: relative to {against})",
                     mm_label=f"validation: distance from {measured_from} [mm]", log_loss=False)
        log.info("%s %s epoch %d: train %.4g J, val %+.4g J vs %s (%.1f mm from it), %.1f s", kind, tier.value,
                 epoch, record.train_loss, val.relative, against, val.mm, record.seconds)
        if hybrid:
            log.info("hybrid %s epoch %d: val supervised %.4g J, %.2f mm from %s", tier.value, epoch, val.supervised,
                     val.sim_mm, target)
        if anchor is not None:
            log.info("anchored %s epoch %d: val anchor %.4g J, %.2f mm from the initial run's garment", tier.value,
                     epoch, val.anchor, val.anchor_mm)
        if progress is not None:
            progress(record)
    if not history:
        raise ClothUsdError(f"{run_dir}: no epoch was trained")
    return TrainResult(run_dir=run_dir, history=tuple(history), best_epoch=best_epoch, model=model.eval())

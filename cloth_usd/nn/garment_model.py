"""A model of one garment: its pose-dependent displacement, trained on its own physics
(``cloth-usd train-garment``'s ``garment`` form).

The paper's models read a garment of any topology through its graph; trained on the
garment's energy they leave its membrane about where skinning put it (docs/method.md,
"A garment's own model"). A model of one garment can do what they cannot: a multilayer
perceptron maps the pose and the body's shape to a displacement of every vertex of this
garment in its unposed frame, and the garment's own skinning then poses it (SNUG's form,
Santesteban et al. 2022, without its recurrent state):

    x_n = sum_j w_nj T_j(theta) (X_n + P_n(theta) + d_n(theta, beta))

``X`` the rest garment on the character, ``P`` the pose correctives skinning adds, ``w``
and ``T`` the garment's skinning weights and joint transforms. Inputs: the 24 joints'
rotation matrices minus the identity, with the heading taken out of the root (216 numbers,
:func:`pose_features`; the displacement is in the unposed frame, so a turned character gets
the same garment turned), of which it reads those of the joints that move the garment
(:func:`~cloth_usd.core.garment_inputs.read_joints`, :attr:`GarmentModelConfig.joints`), and the
body's 10 shape coefficients. Its last layer starts at
zero: an untrained model is the skinned garment.

Two tiers, as the paper's: the coarse model is trained with the stiffer bending the coarse
tier is trained with (``bending_scale`` 10); the detail model adds a second displacement
on top of the frozen coarse one, trained with the material's own bending. The detail
tier's exported file holds the detail model alone, and the runtime adds the coarse file's
displacement to it (the manifest's ``models.detail.adds``), so a bundle holds each network
once. The files store the weights as float16 (half the size; the runtime computes in
float32): the rounding moves the garment by hundredths of a millimetre, measured at export
(``metrics.float16_weights``).

Training needs no simulation: batches of frames of the data set config's planned training
sequences (the garment carried onto the training bodies), the quasi-static energy of
:mod:`cloth_usd.nn.physics` (membrane, bending, gravity, the cubic contact against the
nearest posed body vertex under the garment) minimised with Adam, in float32 (:data:`TRAIN_DTYPE`).
With Newton's frames of some training sequences (``train-garment --sim-data``) the objective is hybrid: a
share of the batches adds a spring toward them (:attr:`GarmentModelConfig.supervised_weight`).
"""

from __future__ import annotations

import copy
import csv
import dataclasses
import hashlib
import json
import logging
import math
import time
from dataclasses import dataclass
from pathlib import Path
from typing import Callable, Sequence

import numpy as np
import torch
from torch import nn

from ..core.body import BodyModel
from ..core.garment_inputs import (POSE_FEATURES, READ_REACH, SHAPE_FEATURES, faces_sha256, pose_features,
                                   read_joints, shape_features, skin_parts)
from ..core.postprocess import nearest_vertex
from ..core.scene import Tier
from ..core.smpl import JOINT_NAMES, NUM_JOINTS
from ..errors import ArgumentError, ClothUsdError

__all__ = ["GarmentModelConfig", "GarmentNet", "HalfStored", "rounded_to_half", "train_garment_model",
           "load_garment_run", "export_garment_bundle"]

log = logging.getLogger(__name__)

#: A run folder's files.
RUN, MODEL, HISTORY = "run.json", "model.pt", "history.csv"
RUN_KIND = "garment-model"


#: :attr:`GarmentModelConfig.sim_target`'s values.
SIM_TARGETS = ("simulation", "taubin")
#: :attr:`GarmentModelConfig.joints`' values.
JOINT_CHOICES = ("garment", "all")
#: The precision a garment model trains in (its network, the posed garment and the energy; a run records it
#: as ``dtype``). The exported files compute in float32 from float16 weights; the runs before stop 65 trained
#: in float64. On one thread beside a Newton simulation, alternated: the sample shirt's coarse model, 300 steps,
#: 55.3 / 59.8 s in float64 and 39.7 / 40.4 in float32 (validation energy 63.05 / 62.55 J a frame); MakeHuman's
#: sport top (911 vertices) from mesh to bundle 260 / 269 s and 216 / 236 s, its detail tier 17.43 and 17.24 mm
#: from Newton on its test set. Each term of the energy is float64's to 2e-7 - 6e-6 on the sample shirt (tests: 1e-4).
TRAIN_DTYPE = torch.float32


@dataclass(frozen=True)
class GarmentModelConfig:
    """One garment model's training (a ``cloth-usd train-garment`` run of the ``garment`` form)."""

    hidden: int = 256
    """Units of each hidden layer."""
    layers: int = 3
    """Hidden layers."""
    steps: int = 3000
    """Adam steps of ``batch`` frames."""
    batch: int = 8
    lr: float = 1e-3
    lr_final: float = 1e-4
    """The learning rate decays exponentially from ``lr`` to this over the steps."""
    bending_scale: float = 1.0
    """Multiplies the material's bending stiffness (10 for the coarse tier, as the paper's coarse tier)."""
    contact_margin: float = 0.008
    """Distance [m] to the body below which the contact term acts (``tshirt-v6``'s)."""
    output_scale: float = 0.05
    """The last layer's output times this is the displacement [m]."""
    val_every: int = 250
    """Steps between validations; the best validation energy's weights are kept (a hybrid run
    keeps its last: Newton's garment is not a minimum of the energy)."""
    seed: int = 0
    supervised_weight: float = 3.0e7
    """The hybrid objective (training sequences with Newton's frames): the spring toward them,
    ``supervised_weight / 2 * sum_n m_n |x_n - y_n|^2`` [1/s^2], added to the energy of their
    batches (at 1e7 a vertex 1 micrometre off is pulled as hard as gravity pulls it). The
    default of ``train-garment --sim-weight``: on the sample shirt's test set, ten simulated
    sequences, 1e7 measured 16.65 mm and 1e6 18.91; 52 sequences mirrored, 12000 steps, 3e7
    measured 13.47 mm, 1e7 14.59 and 1e8 13.45 (14.75 on the unseen body, 3e7 14.34; the detail
    tier, strain limit 1.05)."""
    supervised_share: float = 0.5
    """The hybrid objective: the share of the batches drawn from the simulated sequences."""
    sim_target: str = "simulation"
    """The hybrid objective's target: Newton's frames (``simulation``), or them Taubin-smoothed
    (``taubin``, coarse tier only: the paper's coarse ground truth, the wrinkles left to the detail
    tier; :attr:`~cloth_usd.nn.data.CoarseTarget.TAUBIN`)."""

    mirror: bool = False
    """Train on every training sequence and its mirror image, left for right
    (:mod:`cloth_usd.nn.mirror`; a symmetric garment only): twice the frames, Newton's ones included."""
    joints: str = "garment"
    """The joints whose rotations the model reads: ``garment``, those that move the garment
    (:func:`~cloth_usd.core.garment_inputs.read_joints` of its skinning weights and of the body it
    lies on, on the training bodies; the run records them as ``pose_joints``), or ``all`` 24 (the
    bundles before stop 52).
    With the joints that cannot move them left out, the sample trousers' and dress's own bundles
    came 1.4 and 3.8 mm closer to Newton on their test sets (docs/models.md)."""

    def __post_init__(self) -> None:
        if not isinstance(self.mirror, bool):
            raise ArgumentError(f"garment model mirror must be true or false, got {self.mirror!r}")
        for name in ("hidden", "layers", "steps", "batch", "val_every"):
            value = getattr(self, name)
            if not isinstance(value, int) or isinstance(value, bool) or value < 1:
                raise ArgumentError(f"garment model {name} must be an integer >= 1, got {value!r}")
        if not (isinstance(self.supervised_share, (int, float)) and 0 <= self.supervised_share <= 1):
            raise ArgumentError(f"garment model supervised_share must be within 0..1, got {self.supervised_share!r}")
        for name in ("lr", "lr_final", "bending_scale", "contact_margin", "output_scale", "supervised_weight"):
            value = getattr(self, name)
            if not (isinstance(value, (int, float)) and math.isfinite(value) and value > 0):
                raise ArgumentError(f"garment model {name} must be a number > 0, got {value!r}")
        if self.joints not in JOINT_CHOICES:
            raise ArgumentError(f"garment model joints must be one of {', '.join(JOINT_CHOICES)}, got {self.joints!r}")
        if self.sim_target not in SIM_TARGETS:
            raise ArgumentError(f"garment model sim_target must be one of {', '.join(SIM_TARGETS)}, "
                                f"got {self.sim_target!r}")

    def to_json(self) -> dict:
        return dataclasses.asdict(self)


class GarmentNet(nn.Module):
    """Pose (T, 216) and shape (T, 10) -> displacement (T, N, 3) [m] of one garment's vertices.
    ``joints``: (24,) bool the joints whose pose features it reads (None: all); the others' reach
    its first layer as zeros."""

    def __init__(self, num_vertices: int, hidden: int = 256, layers: int = 3, output_scale: float = 0.05,
                 joints: np.ndarray | None = None) -> None:
        super().__init__()
        self.num_vertices, self.output_scale = int(num_vertices), float(output_scale)
        read = np.ones(NUM_JOINTS, dtype=bool) if joints is None else np.asarray(joints, dtype=bool)
        if read.shape != (NUM_JOINTS,):
            raise ArgumentError(f"GarmentNet joints must be ({NUM_JOINTS},) bool, got shape {read.shape}")
        # not saved with the weights: the run records the joints (``pose_joints``), and runs from before kept all
        self.register_buffer("pose_mask", torch.from_numpy(np.repeat(read, 9).astype(np.float32)), persistent=False)
        dims = [POSE_FEATURES + SHAPE_FEATURES] + [hidden] * layers
        blocks: list[nn.Module] = []
        for a, b in zip(dims[:-1], dims[1:]):
            blocks += [nn.Linear(a, b), nn.ReLU()]
        self.body = nn.Sequential(*blocks)
        self.out = nn.Linear(dims[-1], 3 * self.num_vertices)
        nn.init.zeros_(self.out.weight)
        nn.init.zeros_(self.out.bias)

    @property
    def joints(self) -> np.ndarray:
        """(24,) bool the joints it reads."""
        return self.pose_mask.reshape(NUM_JOINTS, 9)[:, 0].cpu().numpy() > 0

    def forward(self, pose: torch.Tensor, betas: torch.Tensor) -> torch.Tensor:
        h = self.body(torch.cat([pose * self.pose_mask, 0.5 * betas], dim=-1))
        return (self.output_scale * self.out(h)).reshape(pose.shape[0], self.num_vertices, 3)


class HalfStored(nn.Module):
    """A :class:`GarmentNet` whose weights are stored as float16 and computed in float32 (the
    exported form: half the file; onnxruntime casts the weights once when it loads them). The
    joints it does not read have their columns of the first layer zeroed: the same function,
    the same graph."""

    def __init__(self, net: GarmentNet) -> None:
        super().__init__()
        linears = [m for m in net.body if isinstance(m, nn.Linear)] + [net.out]
        mask = torch.cat([net.pose_mask.double(), torch.ones(SHAPE_FEATURES, dtype=torch.float64)])
        for i, layer in enumerate(linears):
            weight = layer.weight.detach() * mask.to(layer.weight) if i == 0 else layer.weight.detach()
            self.register_buffer(f"w{i}", weight.to(torch.float16))
            self.register_buffer(f"b{i}", layer.bias.detach().to(torch.float16))
        self.count, self.num_vertices, self.output_scale = len(linears), net.num_vertices, net.output_scale

    def forward(self, pose: torch.Tensor, betas: torch.Tensor) -> torch.Tensor:
        h = torch.cat([pose, 0.5 * betas], dim=-1)
        for i in range(self.count):
            h = nn.functional.linear(h, getattr(self, f"w{i}").float(), getattr(self, f"b{i}").float())
            h = torch.relu(h) if i < self.count - 1 else h
        return (self.output_scale * h).reshape(pose.shape[0], self.num_vertices, 3)


def rounded_to_half(net: GarmentNet) -> GarmentNet:
    """A float64 copy of ``net`` with its weights rounded to float16 (what :class:`HalfStored` computes)."""
    out = copy.deepcopy(net).double()
    with torch.no_grad():
        for p in out.parameters():
            p.copy_(p.to(torch.float16).double())
    return out


@dataclass
class _Clip:
    """A planned sequence with what its batches need, made once."""

    source: object
    """The :class:`~cloth_usd.nn.physics_train.PhysicsClip`."""
    pose: np.ndarray
    """(T, 216) pose features."""
    betas: np.ndarray
    """(T, 10)."""


def _energy(clip, x: torch.Tensor, frames: np.ndarray, body: BodyModel, material) -> dict[str, torch.Tensor]:
    """(B,) each term of the quasi-static energy [J] of garments ``x`` (B, N, 3) at ``frames``."""
    from ..core.pipeline import pose_body
    from .physics import garment_energy

    pair = clip.pair
    posed = pose_body(body, pair, clip.poses[frames], clip.transl[frames])
    cloud = pair.patch.contact
    points, normals = posed.patch_points[:, cloud], posed.patch_normals[:, cloud]
    nearest = nearest_vertex(x.detach().cpu().numpy(), points)
    rows = np.arange(len(frames))[:, None]
    terms = garment_energy(x, clip.rest, material, body_points=torch.from_numpy(points[rows, nearest]).to(x),
                           body_normals=torch.from_numpy(normals[rows, nearest]).to(x))
    return {"membrane": terms.membrane, "bending": terms.bending, "gravity": terms.gravity,
            "contact": terms.contact, "total": terms.total}


def _garment(net: nn.Module | None, clip: _Clip, frames: np.ndarray, body: BodyModel,
             fixed: nn.Module | None = None) -> torch.Tensor:
    """(B, N, 3) the posed garment of ``net`` (None: no displacement of its own) plus a frozen ``fixed``
    displacement [m], in the models' precision (both the same; :data:`TRAIN_DTYPE` without either)."""
    src = clip.source
    sk = skin_parts(src.pair.binding, src.poses[frames], src.transl[frames], body.parents)
    model = net if net is not None else fixed
    dtype = next(model.parameters()).dtype if model is not None else TRAIN_DTYPE
    pose, betas = torch.from_numpy(clip.pose[frames]).to(dtype), torch.from_numpy(clip.betas[frames]).to(dtype)
    d = net(pose, betas) if net is not None else torch.zeros(sk.base.shape, dtype=dtype)
    if fixed is not None:
        with torch.no_grad():
            frozen = fixed(pose, betas)
        d = d + frozen
    linear = torch.from_numpy(sk.linear).to(dtype)
    return torch.from_numpy(sk.base).to(dtype) + torch.einsum("tnab,tnb->tna", linear, d)


def _prepared(clips) -> list[_Clip]:
    return [_Clip(source=c, pose=pose_features(c.poses), betas=shape_features(c.pair.betas, c.num_frames))
            for c in clips]


def _pair_joints(pair, body: BodyModel) -> np.ndarray:
    """(24,) bool :func:`~cloth_usd.core.garment_inputs.read_joints` of a garment-body pair: its
    skinning weights and the body's under its rest garment."""
    from ..core.pipeline import body_under

    near = body_under(pair.v_shaped, pair.binding.rest_points, reach=READ_REACH)
    return read_joints(pair.binding.sparse_weights, body.weights[near])


def _sim_targets(clips: Sequence[_Clip], how: str) -> dict[int, np.ndarray]:
    """The hybrid objective's target of each clip with Newton's frames, by its index: the frames
    themselves, or (``taubin``) them smoothed as the paper's coarse ground truth is."""
    from .data import taubin_smooth

    out = {}
    for k, c in enumerate(clips):
        target = c.source.target
        if target is not None:
            out[k] = taubin_smooth(target, c.source.pair.faces) if how == "taubin" else target
    return out


def _trained_poses(poses: np.ndarray, config: dict) -> np.ndarray:
    """(T', 72) the training motions' poses ``poses`` (T, 72) as a run of ``config`` (its
    ``run.json`` config) saw them: with their mirror images where it trained mirrored, so the
    bundle's recorded pose range covers both sides."""
    from .mirror import mirror_poses

    return np.concatenate([poses, mirror_poses(poses)]) if config.get("mirror") else poses


def _mirrored(clips, name: str) -> list:
    """Each clip mirrored left for right, one map per rest garment (each body wears its own)."""
    from .mirror import mirror_map, mirrored_clip

    maps: dict[bytes, object] = {}
    out = []
    for c in clips:
        key = np.ascontiguousarray(c.rest_points).tobytes()
        if key not in maps:
            maps[key] = mirror_map(c.rest_points, c.pair.faces, name=f"{name}: the garment of {c.name}")
        out.append(mirrored_clip(c, maps[key]))
    return out


def _first(clip) -> int:
    return min(int(clip.meta.get("warmup_frames", 0)), clip.num_frames - 1)


def _validate(net, fixed, clips: Sequence[_Clip], body, material, frames: int = 8) -> tuple[float, float, float]:
    """Mean energy [J a frame] of the model's garment and of its start (skinned, or the frozen
    coarse one) over evenly spread validation frames, and the mean distance between them [mm]."""
    model_e, start_e, mm, n = 0.0, 0.0, 0.0, 0
    with torch.no_grad():
        for clip in clips:
            lo = _first(clip.source)
            pick = np.unique(np.linspace(lo, clip.source.num_frames - 1, frames).round().astype(np.int64))
            x = _garment(net, clip, pick, body, fixed)
            x0 = _garment(None, clip, pick, body, fixed)
            model_e += float(_energy(clip.source, x, pick, body, material)["total"].sum())
            start_e += float(_energy(clip.source, x0, pick, body, material)["total"].sum())
            mm += 1000 * float((x - x0).norm(dim=-1).mean(-1).sum())
            n += len(pick)
    return model_e / max(n, 1), start_e / max(n, 1), mm / max(n, 1)


def train_garment_model(data_config: str | Path, run_dir: str | Path, config: GarmentModelConfig, *,
                        tier: Tier | str = Tier.COARSE, coarse_run: str | Path | None = None,
                        mocap_dir: str | Path | None = None, body: BodyModel | None = None,
                        physics=None, sim_data: str | Path | None = None,
                        progress: Callable[[dict], None] | None = None) -> dict:
    """Train one tier's garment model on a data set config's planned sequences of one garment.

    With Newton's frames of some training sequences (``sim_data``, or ``physics`` planned with
    them) the objective is hybrid: ``config.supervised_share`` of the batches come from those
    sequences and add the spring toward Newton's garment to the energy
    (``config.supervised_weight``); the others train on the energy alone.

    Args:
        data_config: a ``cloth-usd datagen`` config whose sequences all wear one garment
            (``train-garment``'s ``data.json``).
        run_dir: the run folder to write (``run.json``, ``model.pt``, ``history.csv``).
        config: the training settings.
        tier: coarse, or detail (on top of ``coarse_run``'s frozen model).
        coarse_run: the coarse run (detail only).
        physics: the config's :class:`~cloth_usd.nn.physics_train.PhysicsSet` when the caller
            planned it already (the same config, canonical heading; with ``sim_data``'s targets
            for a hybrid run).
        sim_data: a ``cloth-usd datagen`` folder simulated from ``data_config`` (some of its
            training sequences): the hybrid objective. Ignored when ``physics`` is given.
        progress: called with each validation's row.
    Returns:
        The run's record (what ``run.json`` holds).
    Raises:
        ArgumentError: the sequences wear garments of different triangles, no training or
            validation sequence, a detail run without a coarse run of the same garment.
    """
    from ..core.body import load_body_model
    from .physics_train import physics_set

    tier = Tier(tier)
    if tier is Tier.SKINNING:
        raise ArgumentError("train_garment_model: tier must be coarse or detail")
    if (tier is Tier.DETAIL) != (coarse_run is not None):
        raise ArgumentError("a garment model's detail tier trains on its coarse run (and only it does): "
                            "give coarse_run for detail, none for coarse")
    if tier is Tier.DETAIL and config.sim_target != "simulation":
        raise ArgumentError(f"a garment model's detail tier trains toward Newton's frames themselves "
                            f"(sim_target simulation), not {config.sim_target!r}")
    body = body if body is not None else load_body_model()
    torch.manual_seed(config.seed)
    rng = np.random.default_rng(config.seed)
    began = time.perf_counter()
    data = physics if physics is not None else physics_set(data_config, body, mocap_dir=mocap_dir, sim_data=sim_data)
    material = dataclasses.replace(data.material, contact_margin=config.contact_margin,
                                   bend_stiffness=data.material.bend_stiffness * config.bending_scale)
    train, val = _prepared(data.split("train")), _prepared(data.split("val"))
    if not train or not val:
        raise ArgumentError(f"{data_config}: a garment model needs training and validation sequences "
                            f"(has {len(train)} and {len(val)})")
    faces = {faces_sha256(c.source.pair.faces) for c in train + val}
    if len(faces) != 1:
        raise ArgumentError(f"{data_config}: its sequences wear {len(faces)} different garments; a garment model "
                            "learns one (train one bundle per garment)")
    if config.mirror:
        train = train + _prepared(_mirrored(data.split("train"), str(data_config)))
    num_vertices = train[0].source.pair.num_vertices
    fixed = None
    record_coarse = None
    if coarse_run is not None:
        fixed, coarse_info = load_garment_run(coarse_run)
        if coarse_info["faces_sha256"] != next(iter(faces)):
            raise ArgumentError(f"--coarse-run {coarse_run}: trained on another garment than {data_config}'s")
        fixed = fixed.to(TRAIN_DTYPE).eval()
        record_coarse = {"path": str(Path(coarse_run).resolve()),
                         "model_sha256": hashlib.sha256((Path(coarse_run) / MODEL).read_bytes()).hexdigest()}
    joints = None
    if config.joints == "garment":  # those that move the garment on any of the bodies it is trained on
        pairs = {id(c.source.pair): c.source.pair for c in train + val}.values()  # each body's once
        joints = np.logical_or.reduce([_pair_joints(pair, body) for pair in pairs])
    net = GarmentNet(num_vertices, config.hidden, config.layers, config.output_scale, joints=joints)
    net = net.to(TRAIN_DTYPE)
    opt = torch.optim.Adam(net.parameters(), lr=config.lr)
    decay = (config.lr_final / config.lr) ** (1.0 / max(config.steps, 1))
    sched = torch.optim.lr_scheduler.ExponentialLR(opt, decay)
    targets = _sim_targets(train, config.sim_target)
    examples = [(k, t) for k, c in enumerate(train) for t in range(_first(c.source), c.source.num_frames)]
    simulated = [(k, t) for k, t in examples if k in targets and t < len(targets[k])]
    share = config.supervised_share if simulated else 0.0
    run = Path(run_dir)
    run.mkdir(parents=True, exist_ok=True)
    rows: list[dict] = []
    val_e, start_e, val_mm = _validate(net, fixed, val, body, material)
    best = (val_e, 0, {k: v.clone() for k, v in net.state_dict().items()}, val_mm)
    rows.append({"step": 0, "seconds": round(time.perf_counter() - began, 1), "train_energy": float("nan"),
                 "val_energy": val_e, "val_start_energy": start_e, "val_mm": val_mm, "train_sim_mm": float("nan")})
    if progress is not None:
        progress(rows[0])
    acc: list[float] = []
    sim_mm: list[float] = []
    for step in range(1, config.steps + 1):
        supervised = share > 0 and rng.random() < share
        pool = simulated if supervised else examples
        k, _ = pool[int(rng.integers(len(pool)))]  # a batch shares one clip (one body)
        clip = train[k]
        lo = _first(clip.source)
        # a supervised batch draws from the frames with a target (a kept part of an unstable
        # sequence has its first frames only)
        hi = min(clip.source.num_frames, len(targets[k])) if supervised else clip.source.num_frames
        frames = np.sort(rng.integers(lo, hi, config.batch))
        x = _garment(net, clip, frames, body, fixed)
        loss = _energy(clip.source, x, frames, body, material)["total"].mean()
        if supervised:
            from .physics_train import _spring

            target = torch.from_numpy(targets[k][frames])
            loss = loss + _spring(clip.source, x, target, config.supervised_weight).mean()
            sim_mm.append(1000 * float((x.detach() - target.to(x)).norm(dim=-1).mean()))
        if not torch.isfinite(loss):
            raise ClothUsdError(f"{run}: the energy became {float(loss)} at step {step}; lower lr "
                                f"({config.lr}) and train again")
        opt.zero_grad()
        loss.backward()
        torch.nn.utils.clip_grad_norm_(net.parameters(), 1.0)
        opt.step()
        sched.step()
        acc.append(float(loss.detach()))
        if step % config.val_every == 0 or step == config.steps:
            val_e, start_e, val_mm = _validate(net, fixed, val, body, material)
            row = {"step": step, "seconds": round(time.perf_counter() - began, 1),
                   "train_energy": float(np.mean(acc)), "val_energy": val_e, "val_start_energy": start_e,
                   "val_mm": val_mm, "train_sim_mm": float(np.mean(sim_mm)) if sim_mm else float("nan")}
            rows.append(row)
            acc, sim_mm = [], []
            if val_e < best[0] or (share > 0 and step == config.steps):
                # a hybrid run keeps its last weights: Newton's garment is not a minimum of this
                # energy, so moving toward it can raise the validation energy
                best = (val_e, step, {k: v.clone() for k, v in net.state_dict().items()}, val_mm)
            log.info("%s step %d: energy %.2f J a frame (start %.2f), %.2f mm from it", tier.value, step, val_e,
                     start_e, val_mm)
            if progress is not None:
                progress(row)
    torch.save({"state": best[2], "num_vertices": num_vertices}, run / MODEL)
    with open(run / HISTORY, "w", newline="") as f:
        w = csv.DictWriter(f, fieldnames=list(rows[0]))
        w.writeheader()
        w.writerows(rows)
    info = {"kind": RUN_KIND, "tier": tier.value, "config": config.to_json(), "num_vertices": num_vertices,
            "faces_sha256": next(iter(faces)), "dtype": str(TRAIN_DTYPE).removeprefix("torch."),
            "pose_joints": [JOINT_NAMES[j] for j in np.flatnonzero(net.joints)],
            "best_step": best[1], "best_val_energy": best[0],
            "best_val_mm": best[3],
            "val_start_energy": rows[0]["val_start_energy"], "seconds": round(time.perf_counter() - began, 1),
            "data": {"path": str(Path(data_config).resolve()), "config_sha256": data.config_sha256,
                     "train_sequences": len(train), "val_sequences": len(val), "mirrored": config.mirror},
            "hybrid": None if not simulated else {
                "simulated_sequences": len({k for k, _ in simulated}), "simulated_frames": len(simulated),
                "supervised_weight": config.supervised_weight, "supervised_weight_unit": "1/s^2",
                "supervised_share": config.supervised_share, "sim_target": config.sim_target},
            "coarse_run": record_coarse}
    (run / RUN).write_text(json.dumps(info, indent=1) + "\n")
    return info


def load_garment_run(run_dir: str | Path) -> tuple[GarmentNet, dict]:
    """A garment model run's best model (float64, eval mode) and its ``run.json`` record.

    Raises:
        ArgumentError: not a garment model run (one line naming the folder).
    """
    run = Path(run_dir)
    try:
        info = json.loads((run / RUN).read_text())
    except (OSError, ValueError) as exc:
        raise ArgumentError(f"{run}: not a garment model run ({exc})") from None
    if not isinstance(info, dict) or info.get("kind") != RUN_KIND:
        raise ArgumentError(f"{run}: not a garment model run (run.json kind is not '{RUN_KIND}')")
    try:
        saved = torch.load(run / MODEL, map_location="cpu", weights_only=True)
    except Exception as exc:  # noqa: BLE001 - torch.load raises unpickling and runtime errors alike
        raise ArgumentError(f"{run}: {MODEL} is not a garment model ({' '.join(str(exc).split())[:200]})") from None
    if not isinstance(saved, dict) or not {"state", "num_vertices"} <= saved.keys():
        raise ArgumentError(f"{run}: {MODEL} is not a garment model (no state and num_vertices)")
    cfg = GarmentModelConfig(**info["config"])
    read = info.get("pose_joints", list(JOINT_NAMES))  # a run from before stop 52 read every joint
    if not isinstance(read, list) or not set(read) <= set(JOINT_NAMES):
        raise ArgumentError(f"{run}: run.json pose_joints must list SMPL joint names, got {read!r}")
    net = GarmentNet(int(saved["num_vertices"]), cfg.hidden, cfg.layers, cfg.output_scale,
                     joints=np.isin(JOINT_NAMES, read)).double()
    net.load_state_dict(saved["state"])
    return net.eval(), info


def _read_range(record: dict, joints: np.ndarray) -> dict:
    """A bundle's pose range ``record`` (:func:`~cloth_usd.core.limits.pose_range_record`) with every
    joint its models do not read (``joints`` (24,) bool False) given the whole circle: a bake warns
    of no pose of a joint that cannot change the garment (a T-shirt's hand)."""
    euler = {name: (rows if joints[JOINT_NAMES.index(name)] else [[-180.0, 180.0]] * 3)
             for name, rows in record["euler_deg"].items()}
    return {**record, "euler_deg": euler}


def _export(model: HalfStored, path: Path) -> Path:
    """``model`` as ONNX at ``path``, as :mod:`cloth_usd.nn.export` exports the graph models."""
    from ..runtime.io import GARMENT_INPUTS
    from .export import _export as export_onnx

    example = {"pose": torch.zeros(2, POSE_FEATURES), "betas": torch.zeros(2, SHAPE_FEATURES)}
    return export_onnx(model, GARMENT_INPUTS, Path(path), example)


def export_garment_bundle(coarse_run: str | Path, detail_run: str | Path | None, data_config: str | Path,
                          out_dir: str | Path, *, name: str, category: str | None = None, description: str = "",
                          force: bool = False, mocap_dir: str | Path | None = None, body: BodyModel | None = None,
                          physics=None, tolerance: float = 1e-5, metrics: dict | None = None) -> Path:
    """Export a garment's coarse (and detail) model as a verified bundle bound to its triangles.

    Each file holds one model with float16 weights (:class:`HalfStored`); the detail file's
    displacement is added to the coarse file's (``models.detail.adds``). The ONNX files are
    checked against the torch models with the same rounded weights on the validation
    sequences' frames (largest displacement difference at most ``tolerance`` [m]); what the
    rounding itself moves is measured there too (``metrics.float16_weights``). The manifest
    records the garment's vertex count and triangles' sha256, which a bake checks the scene's
    garment against, and the training poses' and bodies' ranges, and ``metrics`` (``cloth-usd
    evaluate``'s ``metrics.json``) as ``metrics.evaluation``, marked whether it was measured on
    these very files (re-exporting the same runs writes byte-identical ONNX files). ``category``:
    None takes the garment's own (the data config's garment file records it); another is refused.
    """
    import tempfile

    from ..core.body import load_body_model
    from ..core.heading import Heading
    from ..core.limits import betas_range_record, pose_range_record
    from ..core.pipeline import CoarseBase, CoarseFeatures, CoarseForm
    from ..datagen.factory import load_config, load_own_garment, own_garment_files, train_betas, train_poses
    from ..runtime.bundle import GarmentIdentity, load_bundle, write_bundle
    from ..runtime.session import ModelSession
    from ..runtime.io import OUTPUT
    from .export import OPSET, _check_evaluated
    from .physics_train import physics_set

    body = body if body is not None else load_body_model()
    coarse, c_info = load_garment_run(coarse_run)
    detail, d_info = (load_garment_run(detail_run) if detail_run is not None else (None, None))
    if c_info["tier"] != "coarse" or (d_info is not None and d_info["tier"] != "detail"):
        raise ArgumentError(f"{coarse_run}, {detail_run}: expected a coarse and a detail garment model run")
    if d_info is not None and (d_info.get("coarse_run") or {}).get("model_sha256") != hashlib.sha256(
            (Path(coarse_run) / MODEL).read_bytes()).hexdigest():
        raise ArgumentError(f"{detail_run}: was trained on another coarse model than {coarse_run}'s")
    data = physics if physics is not None else physics_set(data_config, body, mocap_dir=mocap_dir)
    if c_info["data"]["config_sha256"] != data.config_sha256:
        raise ArgumentError(f"{coarse_run}: trained on another data set config than {data_config}")
    factory = load_config(data_config, mocap_dir=mocap_dir)
    garment_file = own_garment_files(factory)[0]
    own = load_own_garment(garment_file)  # the garment as trained: its rest on its own body
    if category is not None and category != own.category:
        raise ArgumentError(f"--category {category}: the runs were trained on a {own.category} "
                            f"({garment_file}); leave --category out")
    nets = {"coarse": coarse} if detail is None else {"coarse": coarse, "detail": detail}
    val = _prepared(data.split("val"))
    with tempfile.TemporaryDirectory(prefix="cloth-usd-export-") as tmp:
        tmp = Path(tmp)
        files, worst, rounding = {}, {}, {}
        for tier, net in nets.items():
            files[tier] = _export(HalfStored(net), tmp / f"{tier}.onnx")
            session = ModelSession(files[tier], prefer_gpu=False)
            reference = rounded_to_half(net)  # the float64 torch model the file is checked against
            exact = copy.deepcopy(net).double()
            worst[tier], rounding[tier] = 0.0, 0.0
            for clip in val:
                pose, betas = clip.pose.astype(np.float32), clip.betas.astype(np.float32)
                got = session.run({"pose": pose, "betas": betas})[OUTPUT]
                with torch.no_grad():
                    args = torch.from_numpy(clip.pose), torch.from_numpy(clip.betas)
                    want = reference(*args).numpy()
                    rounding[tier] = max(rounding[tier], float(np.abs(want - exact(*args).numpy()).max()))
                worst[tier] = max(worst[tier], float(np.abs(got - want).max()))
        if not max(worst.values()) <= tolerance:
            raise ClothUsdError(f"export parity failed: ONNX and torch differ by {max(worst.values()) * 1000:.4f} "
                                f"mm on the validation frames (tolerance {tolerance * 1000:.4f} mm); nothing was "
                                "written")
        fit = tmp / "fit.npz"
        data.fit.save(fit)
        training = {"manifest_sha256": data.config_sha256,
                    "description": description or f"{c_info['data']['train_sequences']} planned sequences of "
                                                  f"{Path(data_config).name}",
                    "poses": _read_range(
                        pose_range_record(_trained_poses(train_poses(factory, body), c_info["config"])),
                        np.logical_or.reduce([n.joints for n in nets.values()])),
                    "bodies": betas_range_record(train_betas(factory))}
        configs = {"coarse": {"garment_model": c_info["config"], "best_step": c_info["best_step"],
                              "pose_joints": [JOINT_NAMES[j] for j in np.flatnonzero(coarse.joints)]}}
        metrics_out = {"export_parity": {f"{t}_max_m": v for t, v in worst.items()},
                       "float16_weights": {f"{t}_max_m": v for t, v in rounding.items()},
                       "validation": {"coarse": {"energy": c_info["best_val_energy"],
                                                 "skinned_energy": c_info["val_start_energy"]}}}
        if metrics:
            metrics_out["evaluation"] = _check_evaluated(metrics, files["coarse"], files.get("detail"), log)
        if d_info is not None:
            configs["detail"] = {"garment_model": d_info["config"], "best_step": d_info["best_step"],
                                 "pose_joints": [JOINT_NAMES[j] for j in np.flatnonzero(detail.joints)]}
            metrics_out["validation"]["detail"] = {"energy": d_info["best_val_energy"],
                                                   "coarse_energy": d_info["val_start_energy"]}
        out = write_bundle(out_dir, name=name, category=own.category, coarse_onnx=files["coarse"],
                           detail_onnx=files.get("detail"), fit_npz=fit, configs=configs,
                           training_data=training, metrics=metrics_out, opset=OPSET, force=force,
                           form=CoarseForm(CoarseBase.SKINNED, Heading.CANONICAL, CoarseFeatures.BODY),
                           detail_adds_coarse=True, garment_rest=(own.vertices, own.betas),
                           garment=GarmentIdentity(vertices=int(c_info["num_vertices"]),
                                                   faces_sha256=c_info["faces_sha256"]))
    load_bundle(out)
    return out

"""A model bundle for a garment of the user's own, or for several of one category, from
their meshes alone (``cloth-usd train-garment``).

Each garment (its rest points as worn, triangles, the betas of the body it was made for,
and its category) is written into a work folder beside a data set config that names them
(:attr:`~cloth_usd.datagen.factory.FactoryConfig.garment`): each is worn by its own body
and carried onto four more shapes across the shape space (slim, broad, short and fat,
tall and thin), the five training pairs per garment the fit attribute needs. A dress is
bound as a bake binds it (:func:`~cloth_usd.core.skinning.bind_worn`: the skirt's loose
vertices take blended weights), so the models learn on the skinned garment a bake starts from.
The motions are the seven procedural ones and real ones: by default the 24 CMU stretches shipped with
the package (:data:`~cloth_usd.datagen.mocap.STORED_MOTIONS`, retargeted already), else those the
user lists (clips of a mocap folder among them; an empty list trains on the procedural ones alone).
Then the coarse model and the detail model are trained on the garment's own physics
(:func:`~cloth_usd.nn.physics_train.train_physics`: no simulation), and both are
exported and verified as a bundle (:func:`~cloth_usd.nn.export.export_bundle`). The work
folder keeps the config and both runs (curves, histories), so each step can be rerun by
hand with ``cloth-usd train`` and ``cloth-usd export``, and a second config, ``testset.json``:
the same garments and bodies, whose held-out motions alone ``cloth-usd datagen`` simulates, a
Newton test set for ``cloth-usd evaluate`` (by default three more CMU stretches shipped with the
package, :data:`~cloth_usd.datagen.mocap.STORED_TEST_MOTIONS`, none of them trained on).
"""

from __future__ import annotations

import json
import logging
import shutil
import time
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING, Callable, Sequence

import numpy as np

from ..core.body import BodyModel, load_body_model
from ..core.scene import Category, Tier
from ..errors import ArgumentError

if TYPE_CHECKING:
    from ..datagen.factory import OwnGarment

__all__ = ["OwnGarmentPlan", "OwnGarmentResult", "PROCEDURAL_MOTIONS", "stored_motions", "stored_test_motions",
           "TEST_SET_CONFIG", "HYBRID_CONFIG", "TRAIN_BODIES", "train_own_garment"]

log = logging.getLogger(__name__)

#: The shapes the garment is carried onto, besides its own body (``own``).
TRAIN_BODIES = ("slim", "broad", "short_fat", "tall_thin")
#: A body no pair trains on: the validation sequence wears the garment on it.
VAL_BODY = "medium_thin"
#: The procedural motions every run trains on (1 s at 30 fps, blended in from rest).
PROCEDURAL_MOTIONS = tuple({"kind": k, "seconds": 1.0, "fps": 30, "seed": i, "blend_seconds": 0.25}
                           for i, k in enumerate(("walk", "run", "arm_raise", "arm_swing", "torso_twist",
                                                  "torso_bend", "dance")))
#: The held-out motions of the training config: its validation sequence wears the last. (The
#: test set config, :data:`TEST_SET_CONFIG`, holds out real motion: :func:`stored_test_motions`.)
TEST_MOTIONS = ({"kind": "dance", "seconds": 2.0, "fps": 30, "seed": 100, "blend_seconds": 0.25},
                {"kind": "walk", "seconds": 2.0, "fps": 30, "seed": 101, "blend_seconds": 0.25})
DATA_CONFIG = "data.json"
#: The work folder's test set config: ``cloth-usd datagen`` of it simulates the held-out
#: motions only (split ``test_motion``: the garment on its own body and the slim one; split
#: ``test_body``: the first motion on the validation body), not the training sequences the
#: training config plans (91 sequences for one garment trained with the ten clips of
#: ``configs/own_garment_motions.json``; this one plans 7 for one garment and three test motions).
TEST_SET_CONFIG = "testset.json"
#: The work folder's config for the hybrid objective: the training config's sequences, of which
#: ``cloth-usd datagen`` simulates :attr:`OwnGarmentPlan.sim_sequences` training ones (by default
#: :data:`HYBRID_SEQUENCES`, drawn by the config's seed) with the test set's solver settings;
#: ``train-garment --sim-data`` of that folder adds the spring toward Newton's frames to their batches.
HYBRID_CONFIG = "hybrid.json"
HYBRID_SEQUENCES = 10
#: The splits the test set config simulates.
TEST_SET_SPLITS = ("test_motion", "test_body")
#: The simulator's settings of the test set config beyond the training config's (the material):
#: those of the shipped test sets (``configs/datagen_testset.json``), the full body mesh as the
#: collider and no self-contact. (With the defaults, a decimated collider and self-contact, the
#: MakeHuman top's seven sequences took 31 min on one worker and two went unstable; without,
#: 7.9 min on two and none did.)
TEST_SET_SIM = {"collider_faces": None, "self_contact": False}
#: The simulator's settings of the hybrid config beyond the test set's: of a training sequence that
#: goes unstable, the frames before it are kept where at least half a second of the motion is
#: left past its warm-up (``SimConfig.keep_partial``): they cost their simulation already, and the
#: supervised term reaches those frames alone. (Of the sample trousers' ten sequences three went
#: unstable, all three within the warm-up, where nothing is kept.)
HYBRID_SIM = {"keep_partial": 15}
#: The garments in the work folder: ``garment.npz``, then ``garment1.npz``, ``garment2.npz``, ...
GARMENT_FILE = "garment.npz"
#: The model forms ``train-garment`` trains (:attr:`OwnGarmentPlan.form`).
FORMS = ("garment", "paper")


@dataclass(frozen=True)
class OwnGarmentPlan:
    """How much training a user's garment gets; the defaults fit about 25 minutes of a
    2-core CPU for a 3500-vertex shirt (see docs/models.md)."""

    coarse_epochs: int = 8
    """Epochs of the coarse model (``max_batches`` batches each)."""
    detail_epochs: int = 3
    """Epochs of the detail model."""
    batches: int = 100
    """Batches of 8 frames per coarse epoch; the detail model takes 60% of it."""
    coarse_width: float = 0.0625
    """The coarse model's width (the shipped bundles': the fast tier)."""
    detail_width: float = 0.125
    """The detail model's width."""
    seed: int = 0
    form: str | None = None
    """``garment``: the garment's own models (:mod:`cloth_usd.nn.garment_model`, one garment,
    ``steps`` and ``detail_steps``); ``paper``: the paper's graph models (any topology, several
    garments of a category; ``coarse_epochs``, ``detail_epochs`` and ``batches``); None: garment
    for one garment, paper for several."""
    steps: int = 3000
    """The garment form's coarse model: Adam steps of 8 frames."""
    detail_steps: int = 1500
    """The garment form's detail model: Adam steps of 8 frames."""
    sim_weight: float = 3.0e7
    """The garment form's hybrid objective (``--sim-data``): the spring toward Newton's frames
    [1/s^2] (:attr:`~cloth_usd.nn.garment_model.GarmentModelConfig.supervised_weight`)."""
    coarse_target: str = "simulation"
    """The garment form's coarse model, with ``--sim-data``: trained toward Newton's frames
    (``simulation``) or toward them Taubin-smoothed (``taubin``, the paper's coarse ground truth;
    :attr:`~cloth_usd.nn.garment_model.GarmentModelConfig.sim_target`)."""
    mirror: bool = False
    """The garment form: train both models on every training sequence and its mirror image, left
    for right (:attr:`~cloth_usd.nn.garment_model.GarmentModelConfig.mirror`; a symmetric garment)."""
    sim_sequences: int = HYBRID_SEQUENCES
    """The training sequences :data:`HYBRID_CONFIG` has ``cloth-usd datagen`` simulate. A larger
    count keeps the sequences a smaller one drew, so a folder simulated with fewer is extended,
    not simulated again."""

    def __post_init__(self) -> None:
        if self.form is not None and self.form not in FORMS:
            raise ArgumentError(f"--form must be one of {', '.join(FORMS)}, got {self.form!r}")
        for name in ("coarse_epochs", "detail_epochs", "batches", "steps", "detail_steps", "sim_sequences"):
            value = getattr(self, name)
            if not isinstance(value, int) or value < 1:
                raise ArgumentError(f"--{name.replace('_', '-')} must be an integer >= 1, got {value!r}")
        from .garment_model import SIM_TARGETS

        if self.coarse_target not in SIM_TARGETS:
            raise ArgumentError(f"--coarse-target must be one of {', '.join(SIM_TARGETS)}, got {self.coarse_target!r}")
        if not (isinstance(self.sim_weight, (int, float)) and self.sim_weight > 0):
            raise ArgumentError(f"--sim-weight must be a number > 0 [1/s^2], got {self.sim_weight!r}")

    def coarse_config(self) -> dict:
        return {"objective": "physics", "coarse_base": "skinned", "heading": "canonical", "bending_scale": 10.0,
                "epochs": self.coarse_epochs, "lr": 1e-3, "lr_decay": 0.9, "batch": 8, "width": self.coarse_width,
                "seed": self.seed, "max_batches": self.batches}

    def detail_config(self) -> dict:
        return {"objective": "physics", "bending_scale": 1.0, "epochs": self.detail_epochs, "lr": 1e-3,
                "lr_decay": 0.9, "batch": 8, "width": self.detail_width, "seed": self.seed,
                "max_batches": max(1, int(round(0.6 * self.batches)))}

    def garment_configs(self) -> dict:
        """The garment form's :class:`~cloth_usd.nn.garment_model.GarmentModelConfig` fields per tier:
        the coarse model with the stiffer bending the paper's coarse tier trains with."""
        return {"coarse": {"steps": self.steps, "bending_scale": 10.0, "seed": self.seed,
                           "supervised_weight": self.sim_weight, "sim_target": self.coarse_target,
                           "mirror": self.mirror},
                "detail": {"steps": self.detail_steps, "bending_scale": 1.0, "seed": self.seed,
                           "supervised_weight": self.sim_weight, "mirror": self.mirror}}


@dataclass(frozen=True)
class OwnGarmentResult:
    """What :func:`train_own_garment` made and how long each step took."""

    bundle: Path
    work_dir: Path
    seconds: dict
    """``{"coarse": s, "detail": s, "export": s, "total": s}`` wall time (the garment form also
    ``"plan"``: planning the sequences once for both models)."""
    coarse_val: tuple[float, float]
    """The coarse run's best validation: energy [J a frame] (the paper form: against skinning's),
    distance from skinning [mm]."""
    detail_val: tuple[float, float]
    """The detail run's best validation: energy [J] (the paper form: against the coarse garment's),
    distance from the coarse garment [mm]."""
    pose_joints: tuple[str, ...] | None = None
    """The garment form: the joints whose rotations its models read
    (:func:`~cloth_usd.core.garment_inputs.read_joints`); None for the paper form."""


def _write_json(path: Path, data: dict) -> None:
    path.write_text(json.dumps(data, indent=1) + "\n")


def _described(garments: Sequence[OwnGarment]) -> str:
    sizes = ", ".join(str(np.asarray(g.vertices).shape[0]) for g in garments)
    return f"{len(garments)} {Category(garments[0].category).value} garment(s) ({sizes} vertices)"


def _best(result) -> tuple[float, float]:
    return float(result.best.val_loss), float(result.best.val_mm)


def stored_motions() -> tuple[dict, ...]:
    """The entries of the CMU stretches shipped with the package (``{"stored": name}``): the real
    motions ``train-garment`` trains on unless the user lists others (``--motions``)."""
    from ..datagen.mocap import stored_motion_names

    return tuple({"stored": name} for name in stored_motion_names())


def stored_test_motions() -> tuple[dict, ...]:
    """The entries of the three CMU test stretches shipped with the package (05_02, 01_01 and
    06_10; ``{"stored": name}``): the held-out motions of the test set config
    (:data:`TEST_SET_CONFIG`) unless the user lists others (``--test-motions``)."""
    from ..core.files import models_dir
    from ..datagen.mocap import STORED_TEST_MOTIONS, stored_motion_names

    return tuple({"stored": name} for name in stored_motion_names(models_dir() / STORED_TEST_MOTIONS))


def _garment_file(i: int) -> str:
    return GARMENT_FILE if i == 0 else GARMENT_FILE.replace(".npz", f"{i}.npz")


def train_own_garment(garments: Sequence[OwnGarment], out_dir: str | Path, *,
                      name: str, work_dir: str | Path | None = None,
                      motions: tuple[dict, ...] | None = None, test_motions: tuple[dict, ...] | None = None,
                      mocap_dir: str | Path | None = None, sim_data: str | Path | None = None,
                      plan: OwnGarmentPlan = OwnGarmentPlan(), force: bool = False, device: str | None = "auto",
                      body: BodyModel | None = None,
                      progress: Callable[[str, object], None] | None = None) -> OwnGarmentResult:
    """Train and export a bundle for garments of one category from their meshes (see the
    module docstring).

    Args:
        garments: the garments (rest points in the canonical frame of the body they were
            made for, triangles, betas and category), all of one category: the bundle's.
        out_dir: the bundle folder to write.
        name: the bundle's name (recorded in every cache it bakes).
        work_dir: where the config and the runs go (default: ``<out_dir>.work``).
        motions: the training motions besides the procedural ones, entries as a data set config's
            ``train_motions``; None: the stored CMU stretches (:func:`stored_motions`).
        test_motions: the motions of the test set config (:data:`TEST_SET_CONFIG`), entries
            as ``motions``; None: the stored CMU test stretches (:func:`stored_test_motions`).
            Not trained on, nor checked here (the test set's ``cloth-usd datagen`` reads them).
        mocap_dir: the folder the ``bvh`` entries of ``motions`` are relative to.
        sim_data: the garment form's hybrid objective: a ``cloth-usd datagen`` folder of the work
            folder's :data:`HYBRID_CONFIG` (Newton's frames of some training sequences).
        plan: epochs, batches and widths.
        force: replace an existing bundle, and runs this command left in ``work_dir``.
        progress: called with ``(tier, EpochRecord)`` after every epoch.
    Raises:
        ArgumentError: an existing bundle or work folder without ``force``, no garment, garments
            of several categories, or a bad motion.
    """
    from ..datagen.factory import save_own_garment
    from .export import export_bundle
    from .physics_train import load_physics_config, train_physics

    if not garments:
        raise ArgumentError("train-garment: no garment given")
    form = plan.form or ("garment" if len(garments) == 1 else "paper")
    if form == "garment" and len(garments) > 1:
        raise ArgumentError(f"train-garment: {len(garments)} garments given; the garment form learns one garment "
                            "(--form paper trains one bundle for several of a category)")
    categories = sorted({Category(g.category).value for g in garments})
    if sim_data is not None and form != "garment":
        raise ArgumentError("--sim-data: the hybrid objective trains the garment form (one garment) only")
    if plan.mirror and form != "garment":
        raise ArgumentError("--mirror: mirrored sequences train the garment form (one garment) only")
    if len(categories) > 1:
        raise ArgumentError(f"train-garment: the garments are of several categories ({', '.join(categories)}); "
                            "a bundle serves one category")
    category = Category(categories[0])
    out_dir = Path(out_dir)
    work = Path(work_dir) if work_dir is not None else out_dir.with_name(out_dir.name + ".work")
    if out_dir.exists() and any(out_dir.iterdir()) and not force:
        raise ArgumentError(f"-o {out_dir}: exists and is not empty (pass --force to replace the bundle)")
    runs = {tier: work / tier for tier in ("coarse", "detail")}
    for tier, run in runs.items():
        if run.exists():
            if not force:
                raise ArgumentError(f"--work {work}: holds a {tier} run from an earlier call (pass --force to "
                                    "replace it, or pick another --work folder)")
            if not (run / "run.json").exists() and any(run.iterdir()):
                raise ArgumentError(f"--work {work}: {run} is not a training run; not removing it")
            shutil.rmtree(run)
    work.mkdir(parents=True, exist_ok=True)
    body = body if body is not None else load_body_model()
    files = [_garment_file(i) for i in range(len(garments))]
    for f, g in zip(files, garments):
        save_own_garment(work / f, g.vertices, g.faces, g.betas, category=category.value)
    data = {"garment": files[0] if len(files) == 1 else files, "bodies": ["own", *TRAIN_BODIES, VAL_BODY], "test_bodies": [VAL_BODY],
            "test_body_shirts": 1, "sim": {"fps": 30},
            "train_motions": [*PROCEDURAL_MOTIONS, *(stored_motions() if motions is None else motions)],
            "test_motions": list(TEST_MOTIONS)}
    _write_json(work / DATA_CONFIG, data)
    held_out = stored_test_motions() if test_motions is None else test_motions
    _write_json(work / TEST_SET_CONFIG, {**data, "sim": {**data["sim"], **TEST_SET_SIM},
                                         "train_motions": list(PROCEDURAL_MOTIONS),
                                         "test_motions": list(held_out),
                                         "simulate_splits": list(TEST_SET_SPLITS)})
    if form == "garment":
        _write_json(work / HYBRID_CONFIG, {**data, "sim": {**data["sim"], **TEST_SET_SIM, **HYBRID_SIM},
                                           "simulate_splits": ["train"],
                                           "simulate_sequences": {"train": plan.sim_sequences}})
    if form == "garment":
        return _train_garment_form(garments[0], work, out_dir, runs, name=name, category=category, plan=plan,
                                   force=force, body=body, mocap_dir=mocap_dir, sim_data=sim_data, progress=progress)
    _write_json(work / "coarse.json", plan.coarse_config())
    _write_json(work / "detail.json", plan.detail_config())
    seconds: dict[str, float] = {}
    began = time.perf_counter()
    results = {}
    for tier in ("coarse", "detail"):
        t0 = time.perf_counter()
        config, options = load_physics_config(work / f"{tier}.json")
        results[tier] = train_physics(
            work / DATA_CONFIG, runs[tier], config, tier=Tier(tier),
            coarse_run=runs["coarse"] if tier == "detail" else None, device=device, body=body,
            progress=(lambda r, tier=tier: progress(tier, r)) if progress is not None else None,
            options=options, mocap_dir=mocap_dir)
        seconds[tier] = time.perf_counter() - t0
    t0 = time.perf_counter()
    export_bundle(runs["coarse"], runs["detail"], work / DATA_CONFIG, out_dir, name=name, category=category.value,
                  description=f"{name}: {_described(garments)} trained on their physics by cloth-usd "
                              "train-garment", force=force, body=body, mocap_dir=mocap_dir)
    seconds["export"] = time.perf_counter() - t0
    seconds["total"] = time.perf_counter() - began
    _write_json(work / "timing.json", {k: round(v, 1) for k, v in seconds.items()})
    log.info("%s: bundle in %s after %.1f min", name, out_dir, seconds["total"] / 60)
    return OwnGarmentResult(bundle=out_dir, work_dir=work, seconds=seconds, coarse_val=_best(results["coarse"]),
                            detail_val=_best(results["detail"]))


def _train_garment_form(garment: OwnGarment, work: Path, out_dir: Path, runs: dict, *, name: str, category: Category,
                        plan: OwnGarmentPlan, force: bool, body: BodyModel, mocap_dir, sim_data,
                        progress: Callable[[str, object], None] | None) -> OwnGarmentResult:
    """:func:`train_own_garment` of the garment form: plan the sequences once, train the coarse
    and the detail garment models, export them (:mod:`cloth_usd.nn.garment_model`)."""
    from .garment_model import GarmentModelConfig, export_garment_bundle, train_garment_model
    from .physics_train import physics_set

    configs = plan.garment_configs()
    for tier, fields in configs.items():
        _write_json(work / f"{tier}.json", {**GarmentModelConfig(**fields).to_json(), "form": "garment"})
    seconds: dict[str, float] = {}
    began = time.perf_counter()
    data = physics_set(work / DATA_CONFIG, body, mocap_dir=mocap_dir, sim_data=sim_data)
    if sim_data is not None and not any(c.target is not None for c in data.split("train")):
        raise ArgumentError(f"--sim-data {sim_data}: holds none of the training sequences (simulate "
                            f"{work / HYBRID_CONFIG} into it)")
    seconds["plan"] = time.perf_counter() - began
    infos = {}
    for tier in ("coarse", "detail"):
        t0 = time.perf_counter()
        infos[tier] = train_garment_model(
            work / DATA_CONFIG, runs[tier], GarmentModelConfig(**configs[tier]), tier=Tier(tier),
            coarse_run=runs["coarse"] if tier == "detail" else None, body=body, physics=data,
            progress=(lambda row, tier=tier: progress(tier, row)) if progress is not None else None)
        seconds[tier] = time.perf_counter() - t0
    t0 = time.perf_counter()
    export_garment_bundle(runs["coarse"], runs["detail"], work / DATA_CONFIG, out_dir, name=name,
                          category=category.value, force=force, body=body, physics=data, mocap_dir=mocap_dir,
                          description=f"{name}: {_described([garment])}, its own models trained on its physics "
                                      "by cloth-usd train-garment")
    seconds["export"] = time.perf_counter() - t0
    seconds["total"] = time.perf_counter() - began
    _write_json(work / "timing.json", {k: round(v, 1) for k, v in seconds.items()})
    log.info("%s: bundle in %s after %.1f min", name, out_dir, seconds["total"] / 60)
    return OwnGarmentResult(bundle=out_dir, work_dir=work, seconds=seconds,
                            coarse_val=(infos["coarse"]["best_val_energy"], infos["coarse"]["best_val_mm"]),
                            detail_val=(infos["detail"]["best_val_energy"], infos["detail"]["best_val_mm"]),
                            pose_joints=tuple(infos["coarse"]["pose_joints"]))

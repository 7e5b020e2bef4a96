"""A bake's arguments resolved into a typed plan before any frame is computed: the
garments, each one's tier and model bundle, the frame range, the body models and the
inputs digest (:func:`resolve`); :func:`bake_plan` says whether an output already holds it."""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path
from typing import Any, Sequence

import numpy as np

from ..core.body import BodyModel
from ..core.frame_range import FrameRange, parse_frames
from ..core.garment_inputs import faces_sha256
from ..core.joint_names import as_joint_map
from ..core.scene import Character, Garment, Scene, Tier
from ..errors import ArgumentError, BodyModelError, SceneError
from ..runtime.bundle import ModelBundle, default_bundle_dir, find_bundle
from ..usd.provenance import cache_provenance
from ..usd.read import open_stage, read_scene
from ..usd.write import cache_layer_info
from .cache import ModelCache
from .digest import inputs_digest

__all__ = ["parse_tier", "TierChoice", "ResolvedBake", "BakePlan", "open_scene", "check_shape_components",
           "resolve", "is_current", "bake_plan"]


def parse_tier(value: str | Tier | None) -> Tier | None:
    """A Tier from its name; raises ArgumentError listing the valid names."""
    if value is None or isinstance(value, Tier):
        return value
    try:
        return Tier(value)
    except ValueError:
        valid = ", ".join(t.value for t in Tier)
        raise ArgumentError(f"--tier '{value}': unknown tier (valid: {valid})") from None


@dataclass(frozen=True)
class TierChoice:
    """The tier a garment is baked with and, for a learned tier, its verified bundle."""

    tier: Tier
    bundle: ModelBundle | None
    """None for the skinning tier."""


@dataclass(frozen=True)
class ResolvedBake:
    """Everything a bake resolves before computing a frame."""

    stage: Any
    """The open ``Usd.Stage`` (handed back to :mod:`cloth_usd.usd` only)."""
    scene: Scene
    protected: tuple[str, ...]
    """The stage's layer files: never overwritten."""
    chosen: tuple[Garment, ...]
    tiers: dict[str, TierChoice]
    """By garment prim path."""
    frames: FrameRange
    frames_given: bool
    """False when ``frames`` is the stage's own range."""
    bodies: dict[str, BodyModel]
    """By gender: the body models the chosen garments' characters use."""
    inputs_sha256: str

    def characters(self) -> dict[str, Character]:
        """The scene's characters by prim path."""
        return {c.prim_path: c for c in self.scene.characters}


@dataclass(frozen=True)
class BakePlan:
    """What a bake would do, known before any frame is computed (:func:`bake_plan`)."""

    frames: FrameRange
    garments: tuple[str, ...]
    """Prim paths of the garments it bakes."""
    inputs_sha256: str
    """sha256 over the stage's layer files, the frame range, the garments and their
    tiers, the body model and model bundle files, and the tool version. A cache records
    it in its provenance; the same digest means the same bake."""
    current: bool
    """True when the output already holds this bake (same digest, every frame)."""


def _select_garments(scene: Scene, names: Sequence[str] | None, source: str) -> list[Garment]:
    if not names:
        chosen = [g for g in scene.garments if g.enabled]
        if not chosen:
            raise SceneError(f"{source}: no enabled garment (a Mesh with cloth:category and "
                             "cloth:body) in this stage")
        return chosen
    by_path = {g.prim_path: g for g in scene.garments}
    chosen = []
    for name in names:
        if name not in by_path:
            valid = ", ".join(by_path) or "none"
            raise ArgumentError(f"--garment {name}: no garment at this prim path in {source} "
                                f"(garments: {valid})")
        chosen.append(by_path[name])
    return chosen


def _frame_range(scene: Scene, frames: FrameRange | None) -> FrameRange:
    if frames is not None:
        return frames
    info = scene.stage
    if info.start_time_code is None or info.end_time_code is None:
        raise SceneError(f"{info.identifier}: the stage authors no startTimeCode/endTimeCode; "
                         "pass --frames START:END")
    if info.end_time_code < info.start_time_code:
        raise SceneError(f"{info.identifier}: empty frame range (endTimeCode "
                         f"{info.end_time_code} < startTimeCode {info.start_time_code}); "
                         "pass --frames START:END")
    return FrameRange(info.start_time_code, info.end_time_code)


def _resolve_tier(garment: Garment, tier: Tier | None, source: str, *,
                  models: Sequence[str | Path] | None, found: dict) -> TierChoice:
    """The garment's tier and, for a learned tier, the verified bundle of its category.

    The garment's own bundle (``cloth-usd train-garment``) in the search folders comes before its
    category's. ``found`` caches bundles by category and garment triangles across garments.
    """
    chosen = garment.tier or tier or Tier.SKINNING
    if chosen is Tier.SKINNING:
        return TierChoice(chosen, None)
    key = (garment.category, len(garment.rest_points), faces_sha256(garment.triangles))
    if key not in found:
        found[key] = find_bundle(garment.category, models, worn=(len(garment.rest_points), garment.triangles))
    bundle = found[key]
    if bundle is None:
        dirs = ", ".join(str(d) for d in (models if models is not None else [default_bundle_dir()]))
        raise ArgumentError(
            f"{source} {garment.prim_path}: tier '{chosen.value}' needs a trained model bundle for "
            f"category '{garment.category.value}', none found in {dirs} (available: skinning)")
    if chosen not in bundle.tiers:
        raise ArgumentError(
            f"{source} {garment.prim_path}: tier '{chosen.value}' is not in bundle '{bundle.name}' "
            f"({bundle.path}) (available: skinning, {', '.join(t.value for t in bundle.tiers)})")
    return TierChoice(chosen, bundle)


def check_shape_components(char: Character, body: BodyModel, source: str) -> None:
    """BodyModelError when the stage's betas use shape components the body model lacks."""
    extra = np.flatnonzero(char.betas[body.num_betas:]) + body.num_betas
    if extra.size:
        used = int(extra[-1]) + 1
        raise BodyModelError(
            f"{source} <{char.prim_path}>: smpl:betas[{extra[0]}] is {char.betas[extra[0]]:g}, but the body "
            f"model {body.source} has only {body.num_betas} shape components (the stage's betas use {used}); "
            f"pass a body model with at least {used}, or zero the extra betas")


def open_scene(scene_path: str | Path) -> tuple[Any, tuple[str, ...]]:
    """The open stage and its layer files (which a bake must never overwrite)."""
    stage = open_stage(scene_path)
    return stage, tuple(layer.realPath for layer in stage.GetUsedLayers())


def resolve(stage, protected: Sequence[str], *, frames: FrameRange | str | None,
            garments: Sequence[str] | None, tier: Tier | str | None, body_model: str | Path | None,
            models: str | Path | Sequence[str | Path] | None, cache: ModelCache,
            joint_map: dict[str, str] | str | Path | None = None) -> ResolvedBake:
    """Resolve a bake's arguments on an open stage (arguments as for :func:`cloth_usd.baking.bake`)."""
    if isinstance(frames, str):
        frames = parse_frames(frames)
    tier = parse_tier(tier)
    joint_map = as_joint_map(joint_map)  # read once: the scene and the digest see the same map
    scene = read_scene(stage, joint_map=joint_map)
    source = scene.stage.identifier
    chosen = _select_garments(scene, garments, source)
    if isinstance(models, (str, Path)):
        models = [models]
    found = cache.bundles(models)
    tiers = {g.prim_path: _resolve_tier(g, tier, source, models=models, found=found) for g in chosen}
    frange = _frame_range(scene, frames)
    characters = {c.prim_path: c for c in scene.characters}
    bodies: dict[str, BodyModel] = {}
    for g in chosen:
        gender = characters[g.body_path].gender
        if gender not in bodies:
            bodies[gender] = cache.body(body_model, gender)
        check_shape_components(characters[g.body_path], bodies[gender], source)
    digest = inputs_digest(protected, frange, chosen, {p: (c.tier, c.bundle) for p, c in tiers.items()},
                           characters, bodies, dict(joint_map.entries) if joint_map is not None else {})
    return ResolvedBake(stage=stage, scene=scene, protected=tuple(protected), chosen=tuple(chosen), tiers=tiers,
                        frames=frange, frames_given=frames is not None, bodies=bodies, inputs_sha256=digest)


def is_current(output: str | Path, plan: ResolvedBake) -> bool:
    """True when ``output`` is a readable cache of exactly this bake."""
    info = cache_layer_info(output)
    prov = cache_provenance(info)
    if prov is None or prov.inputs_sha256 != plan.inputs_sha256:
        return False
    count = plan.frames.count()
    return all(info.samples.get(f"{g.prim_path}.points") == count for g in plan.chosen)


def bake_plan(scene_path: str | Path, output: str | Path | None = None, *,
              frames: FrameRange | str | None = None, garments: Sequence[str] | None = None,
              tier: Tier | str | None = None, body_model: str | Path | None = None,
              models: str | Path | Sequence[str | Path] | None = None,
              cache: ModelCache | None = None, joint_map: dict[str, str] | str | Path | None = None) -> BakePlan:
    """Resolve a bake without computing it: its frames, garments and inputs digest, and
    whether ``output`` already holds it. Arguments as for :func:`cloth_usd.baking.bake`."""
    stage, protected = open_scene(scene_path)
    plan = resolve(stage, protected, frames=frames, garments=garments, tier=tier, body_model=body_model,
                   models=models, cache=cache or ModelCache(), joint_map=joint_map)
    return BakePlan(frames=plan.frames, garments=tuple(g.prim_path for g in plan.chosen),
                    inputs_sha256=plan.inputs_sha256,
                    current=output is not None and is_current(output, plan))

"""Bake: a USD shot in, a garment point-cache layer out.

This module joins the USD boundary (``cloth_usd.usd``) with the numpy core; it holds
no maths of its own. Shape letters: T frames, N garment vertices.
"""

from __future__ import annotations

import logging
import re
import time
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING, Sequence

import numpy as np

from . import __version__
from .core.body import BodyModel, load_body_model, shape_body
from .core.frames import CanonicalMotion, canonical_motion
from .core.scene import Character, Garment, Scene, Tier
from .core.skinning import bind_garment, skin_garment
from .errors import ArgumentError, SceneError

if TYPE_CHECKING:
    from .runtime.bundle import ModelBundle

__all__ = ["FrameRange", "GarmentReport", "BakeResult", "bake", "parse_frames", "parse_tier"]

log = logging.getLogger(__name__)


@dataclass(frozen=True)
class FrameRange:
    """An inclusive range of time codes."""

    start: float
    end: float
    step: float = 1.0

    def times(self) -> np.ndarray:
        """(T,) float64 time codes from start to end inclusive."""
        count = int(np.floor((self.end - self.start) / self.step + 1e-9)) + 1
        return self.start + self.step * np.arange(count, dtype=np.float64)


_FRAMES = re.compile(r"^\s*(-?[\d.]+)\s*:\s*(-?[\d.]+)\s*(?::\s*([\d.]+)\s*)?$")


def parse_frames(text: str) -> FrameRange:
    """Parse ``START:END[:STEP]`` (inclusive); raises ArgumentError naming ``--frames``."""
    m = _FRAMES.match(text)
    try:
        if not m:
            raise ValueError
        start, end = float(m.group(1)), float(m.group(2))
        step = float(m.group(3)) if m.group(3) else 1.0
    except ValueError:
        raise ArgumentError(f"--frames '{text}': expected START:END or START:END:STEP, "
                            "e.g. 1001:1100 or 1:48:2") from None
    if step <= 0:
        raise ArgumentError(f"--frames '{text}': STEP must be positive")
    if end < start:
        raise ArgumentError(f"--frames '{text}': empty range (END is before START)")
    return FrameRange(start, end, step)


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
class GarmentReport:
    """What was baked for one garment."""

    prim_path: str
    tier: Tier
    vertices: int
    frames: int
    mean_body_distance_mm: float
    """Mean rest distance of the garment's vertices to the body surface [mm]."""
    bundle: str | None = None
    """Name of the model bundle that animated it (None for the skinning tier)."""
    fit: tuple[float, ...] | None = None
    """The garment-body pair's fit attribute alpha (learned tiers only)."""
    postprocess_moved: int = 0
    """Vertex-frames the post-process pushed out of the body (summed over frames)."""


@dataclass(frozen=True)
class BakeResult:
    """The outcome of :func:`bake`."""

    cache: Path
    shot: Path | None
    times: np.ndarray
    """(T,) float64 baked time codes."""
    garments: tuple[GarmentReport, ...]
    seconds: float


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


def _frame_range(scene: Scene, frames: FrameRange | str | None) -> FrameRange:
    if isinstance(frames, str):
        return parse_frames(frames)
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
                  models: Sequence[str | Path] | None = None,
                  found: dict | None = None) -> tuple[Tier, "ModelBundle | None"]:
    """The garment's tier and, for a learned tier, the verified bundle of its category.

    ``found`` caches bundles by category across garments.
    """
    chosen = garment.tier or tier or Tier.SKINNING
    if chosen is Tier.SKINNING:
        return chosen, None
    from .runtime.bundle import default_bundle_dir, find_bundle

    found = {} if found is None else found
    if garment.category not in found:
        found[garment.category] = find_bundle(garment.category, models)
    bundle = found[garment.category]
    if bundle is None:
        dirs = ", ".join(str(d) for d in (models if models is not None else [default_bundle_dir()]))
        raise ArgumentError(
            f"{source} {garment.prim_path}: tier '{chosen.value}' needs a trained model bundle for "
            f"category '{garment.category.value}', none found in {dirs} (available: skinning)")
    if chosen not in bundle.tiers:
        raise ArgumentError(
            f"{source} {garment.prim_path}: tier '{chosen.value}' is not in bundle '{bundle.name}' "
            f"({bundle.path}) (available: skinning, {', '.join(t.value for t in bundle.tiers)})")
    return chosen, bundle


def bake(scene_path: str | Path, output: str | Path, *, shot: str | Path | None = None,
         frames: FrameRange | str | None = None, garments: Sequence[str] | None = None,
         tier: Tier | str | None = None, force: bool = False,
         body_model: str | Path | None = None, chunk: int = 64,
         progress: bool = False, models: str | Path | Sequence[str | Path] | None = None,
         batch_size: int = 16) -> BakeResult:
    """Bake every enabled garment (or the named ones) of a stage into a point-cache layer.

    Args:
        scene_path: the USD stage to read; never modified.
        output: the cache layer to write (``.usdc`` by default).
        shot: optional shot layer that sublayers ``[cache, scene]``.
        frames: inclusive range, default the stage's start..end.
        garments: prim paths to bake, default every enabled garment.
        tier: default tier for garments without ``cloth:tier``.
        force: replace existing output files.
        body_model: SMPL-format file or folder, default the embedded model.
        chunk: frames evaluated per batch (skinning tier).
        progress: show a progress bar per garment.
        models: folder(s) searched for model bundles (a bundle folder, or a folder of
            bundles), default the shipped ``models/bundles``.
        batch_size: frames per model call (learned tiers).
    """
    from .usd.read import garment_from_internal, open_stage, read_motion, read_scene
    from .usd.write import CacheLayerWriter, check_output_path, write_shot_layer

    began = time.perf_counter()
    tier = parse_tier(tier)
    stage = open_stage(scene_path)
    protected = [layer.realPath for layer in stage.GetUsedLayers()]
    check_output_path(output, force=force, protected=protected)
    if shot is not None:
        check_output_path(shot, force=force, protected=protected)
    scene = read_scene(stage)
    source = scene.stage.identifier
    chosen = _select_garments(scene, garments, source)
    if isinstance(models, (str, Path)):
        models = [models]
    found: dict = {}
    tiers = {g.prim_path: _resolve_tier(g, tier, source, models=models, found=found) for g in chosen}
    frange = _frame_range(scene, frames)
    times = frange.times()

    characters = {c.prim_path: c for c in scene.characters}
    bodies: dict[str, BodyModel] = {}
    motions = {}
    reports = []
    with CacheLayerWriter(output, stage=scene.stage, start=times[0], end=times[-1],
                          force=force, protected=protected) as writer:
        for garment in chosen:
            char: Character = characters[garment.body_path]
            if char.gender not in bodies:
                bodies[char.gender] = load_body_model(body_model, gender=char.gender)
            body = bodies[char.gender]
            if char.prim_path not in motions:  # once per character, whatever it wears
                motions[char.prim_path] = canonical_motion(
                    char, read_motion(stage, char, times), shape_body(body, char.betas)[1])
            g_tier, g_bundle = tiers[garment.prim_path]
            report = _bake_garment(stage, writer, garment, char, body, motions[char.prim_path], times, g_tier,
                                   chunk=chunk, progress=progress, garment_from_internal=garment_from_internal,
                                   bundle=g_bundle, batch_size=batch_size)
            reports.append(report)
        used = {b.sha256: b for _, b in tiers.values() if b is not None}
        provenance = _provenance(scene, frange, bodies, reports, list(used.values()))
        cache = writer.commit(provenance)
    shot_path = None
    if shot is not None:
        shot_path = write_shot_layer(shot, cache=cache, scene=Path(stage.GetRootLayer().realPath),
                                     stage=scene.stage, start=times[0], end=times[-1],
                                     force=force, protected=protected)
    return BakeResult(cache=cache, shot=shot_path, times=times, garments=tuple(reports),
                      seconds=time.perf_counter() - began)


def _bake_garment(stage, writer, garment: Garment, char: Character, body: BodyModel,
                  motion: CanonicalMotion, times: np.ndarray, tier: Tier, *, chunk: int, progress: bool,
                  garment_from_internal, bundle: "ModelBundle | None" = None,
                  batch_size: int = 16) -> GarmentReport:
    from tqdm.auto import tqdm

    rest = motion.rest_points(garment.rest_points)
    binding = bind_garment(body, char.betas, rest)
    poses, transl = motion.poses, motion.transl
    to_prim = garment_from_internal(stage, garment.prim_path, times)  # (T, 4, 4)
    num_t = times.shape[0]
    learned = None
    if tier is not Tier.SKINNING:
        from .runtime.garment import LearnedGarment

        learned = LearnedGarment(bundle, body, char.betas, rest, garment.triangles, binding=binding)
        chunk = batch_size
    moved = 0
    with tqdm(total=num_t, desc=garment.prim_path, unit="frame", disable=not progress,
              leave=False) as bar:
        for lo in range(0, num_t, chunk):
            hi = min(lo + chunk, num_t)
            if learned is None:
                pts = skin_garment(binding, poses[lo:hi], transl[lo:hi], body.parents)
            else:
                frames = learned.evaluate(tier, poses[lo:hi], transl[lo:hi], batch_size=batch_size)
                pts = frames.points
                moved += int(frames.moved.sum())
            m = to_prim[lo:hi]
            local = np.einsum("tab,tnb->tna", m[:, :3, :3], pts) + m[:, None, :3, 3]
            writer.add_points(garment.prim_path, times[lo:hi], local)
            bar.update(hi - lo)
    log.info("%s: %d vertices, %d frames, tier %s", garment.prim_path, binding.rest_points.shape[0],
             num_t, tier.value)
    return GarmentReport(prim_path=garment.prim_path, tier=tier,
                         vertices=int(binding.rest_points.shape[0]), frames=num_t,
                         mean_body_distance_mm=float(binding.association.distance.mean() * 1000.0),
                         bundle=None if learned is None else bundle.name,
                         fit=None if learned is None else tuple(float(a) for a in learned.alpha),
                         postprocess_moved=moved)


def _garment_provenance(r: GarmentReport) -> dict:
    out = {"tier": r.tier.value, "vertices": r.vertices, "frames": r.frames,
           "mean_body_distance_mm": round(r.mean_body_distance_mm, 3)}
    if r.fit is None:
        out["fit"] = "not computed (skinning tier)"
    else:  # a string of numbers: VtDictionary keeps no plain list of floats
        out.update(fit=" ".join(f"{a:.6g}" for a in r.fit), model_bundle=r.bundle,
                   postprocess_moved=r.postprocess_moved)
    return out


def _provenance(scene: Scene, frange: FrameRange, bodies: dict[str, BodyModel],
                reports: list[GarmentReport], bundles: list | None = None) -> dict:
    bundles = bundles or []
    if not bundles:
        bundle = {"name": "none (skinning tier)", "sha256": ""}
    elif len(bundles) == 1:
        bundle = {"name": bundles[0].name, "sha256": bundles[0].sha256}
    else:
        bundle = {"name": ", ".join(b.name for b in bundles), "sha256": ", ".join(b.sha256 for b in bundles)}
    return {
        "cloth_usd": {
            "tool_version": __version__,
            "source_layer": scene.stage.identifier,
            "frame_range": f"{frange.start:g}:{frange.end:g}:{frange.step:g}",
            "body_models": {g: {"file": Path(b.source).name, "sha256": b.sha256}
                            for g, b in bodies.items()},
            "model_bundle": bundle,
            "garments": {r.prim_path: _garment_provenance(r) for r in reports},
        }
    }

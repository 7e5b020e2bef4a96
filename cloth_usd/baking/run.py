"""Bake: a USD shot in, a garment point-cache layer out.

Joins the USD boundary (:mod:`cloth_usd.usd`) with the numpy core; it holds no maths of
its own. Frames are computed and handed to the layer writer a batch at a time, so memory
grows with the output layer only. Shape letters: T frames.
"""

from __future__ import annotations

import logging
import os
import time
from dataclasses import dataclass
from pathlib import Path
from typing import Callable, Sequence

import numpy as np

from .._version import __version__
from ..core.body import shape_body
from ..core.frame_range import FrameRange
from ..core.frames import CanonicalMotion, canonical_motion
from ..core.guard import GuardLimits
from ..core.provenance import FileRecord, GarmentReport, Provenance
from ..core.scene import Character, Tier
from ..core.plausibility import SIZE_REFUSE, garment_scale
from ..errors import ArgumentError, GarmentError
from ..usd.provenance import to_custom_data
from ..usd.read import garment_from_internal, read_motion
from ..usd.write import CacheLayerWriter, check_output_path, remove_stale_temps, stage_shot_layer, write_shot_layer
from .cache import ModelCache
from .garment import bake_garment, range_notes
from .plan import ResolvedBake, is_current, open_scene, resolve
from .size import check_size

__all__ = ["BakeResult", "bake"]

log = logging.getLogger(__name__)


@dataclass(frozen=True)
class BakeResult:
    """The outcome of :func:`bake`."""

    cache: Path
    shot: Path | None
    times: np.ndarray
    """(T,) float64 baked time codes."""
    garments: tuple[GarmentReport, ...]
    seconds: float
    skipped: bool = False
    """True when ``skip_current`` found the cache already baked from the same inputs
    (nothing was written; ``garments`` is empty)."""
    inputs_sha256: str = ""
    """Digest of everything the bake depends on (:class:`~cloth_usd.baking.plan.BakePlan`)."""


def _same_file(a: str | Path, b: str | Path) -> bool:
    """True when two paths name one file (after links, ``./`` and ``..``; hard links too)."""
    if os.path.realpath(a) == os.path.realpath(b):
        return True
    try:
        return os.path.samefile(a, b)
    except OSError:  # one of them does not exist yet
        return False


def _provenance(plan: ResolvedBake, reports: Sequence[GarmentReport]) -> Provenance:
    bundles = list({c.bundle.sha256: c.bundle for c in plan.tiers.values() if c.bundle is not None}.values())
    if not bundles:
        bundle = FileRecord("none (skinning tier)", "")
    else:
        bundle = FileRecord(", ".join(b.name for b in bundles), ", ".join(b.sha256 for b in bundles))
    return Provenance(tool_version=__version__, source_layer=plan.scene.stage.identifier, frames=plan.frames,
                      body_models={g: FileRecord(Path(b.source).name, b.sha256) for g, b in plan.bodies.items()},
                      model_bundle=bundle, garments=tuple(reports), inputs_sha256=plan.inputs_sha256)


def _check_garment_sizes(plan: ResolvedBake) -> None:
    """GarmentError for the first chosen garment larger than SIZE_REFUSE times its body."""
    characters = plan.characters()
    for g in plan.chosen:
        scale = garment_scale(g.rest_points, characters[g.body_path].rest_joints)
        if scale.ratio > SIZE_REFUSE:
            raise GarmentError(
                f"{plan.scene.stage.identifier} <{g.prim_path}>: the garment is {scale.ratio:.2g} times its body's "
                f"height ({scale.diagonal:.3g} m bounding-box diagonal, body {scale.body_height:.2f} m), more than "
                f"{SIZE_REFUSE:g}: check its units (metersPerUnit, or a scale on the prim), or pass --allow-any-size")


def bake(scene_path: str | Path, output: str | Path, *, shot: str | Path | None = None,
         frames: FrameRange | str | None = None, garments: Sequence[str] | None = None,
         tier: Tier | str | None = None, force: bool = False,
         body_model: str | Path | None = None, chunk: int = 64,
         progress: bool = False, models: str | Path | Sequence[str | Path] | None = None,
         batch_size: int | None = None, skip_current: bool = False, cache: ModelCache | None = None,
         on_progress: Callable[[str, int, int], None] | None = None, strict: bool = False,
         guard: GuardLimits | None = None, joint_map: dict[str, str] | str | Path | None = None,
         max_cache_bytes: int | None = None, allow_any_size: bool = False) -> BakeResult:
    """Bake every enabled garment (or the named ones) of a stage into a point-cache layer.

    Args:
        scene_path: the USD stage to read; never modified.
        output: the cache layer to write (``.usdc`` by default).
        shot: optional shot layer that sublayers ``[cache, scene]``.
        frames: inclusive range (or its ``START:END[:STEP]``), default the stage's start..end.
        garments: prim paths to bake, default every enabled garment.
        tier: default tier (a :class:`~cloth_usd.core.scene.Tier` or its name) for garments
            without ``cloth:tier``.
        force: replace existing output files.
        body_model: SMPL-format file or folder, default the embedded model.
        chunk: frames evaluated per batch (skinning tier).
        progress: show a progress bar per garment.
        models: folder(s) searched for model bundles (a bundle folder, or a folder of
            bundles), default the shipped ``models/bundles``.
        batch_size: frames per model call (learned tiers); None picks about
            :data:`~cloth_usd.baking.garment.LEARNED_BATCH_VERTICES` garment vertices per call
            (at most 16 frames), which bounds memory: a 300-frame detail bake of a 4031-vertex
            shirt peaked at 1996 MiB with 16 frames per call.
        skip_current: when ``output`` already holds this very bake (its provenance has
            the same :attr:`BakePlan.inputs_sha256` and every frame), write nothing and
            return a result with ``skipped=True``. A different existing file still
            needs ``force``.
        cache: body models, bundles and bound garments to reuse across bakes.
        on_progress: called with ``(garment prim, frames done, frames total)`` after
            each batch of frames is added to the (temporary) layer.
        strict: a learned frame the guard rejects is an error (nothing is written) instead
            of falling back to the next safer tier for that frame.
        guard: when a learned frame is not a garment (:mod:`cloth_usd.core.guard`; None: each
            garment's category's, :func:`~cloth_usd.core.guard.guard_limits`).
        joint_map: ``{their joint name: SMPL joint name}`` or a JSON / TOML file of it, for
            skeletons named in no known convention (:mod:`cloth_usd.core.joint_names`).
        max_cache_bytes: refuse a bake whose cache (:func:`~cloth_usd.baking.size.cache_bytes`)
            would be larger; None: :data:`~cloth_usd.baking.size.MAX_CACHE_BYTES`, and the
            cache must fit the free space of its folder and the frames' motion the memory
            available (:func:`~cloth_usd.baking.size.check_size`). The cache itself is
            written in bounded memory (:data:`~cloth_usd.usd.write.FLUSH_BYTES` of points
            held at a time), whatever its length.
        allow_any_size: bake a garment more than
            :data:`~cloth_usd.core.plausibility.SIZE_REFUSE` times its body's height (refused
            by default: such a garment is nearly always in the wrong units).

    Raises:
        ArgumentError: among others, ``shot`` is the same file as ``output``, or the cache
            would be too large (both before anything is computed).
        GarmentError: a garment is implausibly large for its body (see ``allow_any_size``).
        OutputWriteError: a layer could not be saved (a full disk names the file and says
            "no space left on device"); neither the cache nor the shot layer is written.
    """
    began = time.perf_counter()
    cache = cache or ModelCache()
    if shot is not None and _same_file(shot, output):
        raise ArgumentError(f"--shot {shot}: is the same file as -o {output}; the shot layer sublayers the "
                            "cache, so name a different file for it")
    stage, protected = open_scene(scene_path)
    check_output_path(output, force=force or skip_current, protected=protected)
    if shot is not None:
        check_output_path(shot, force=force or skip_current, protected=protected)
    plan = resolve(stage, protected, frames=frames, garments=garments, tier=tier, body_model=body_model,
                   models=models, cache=cache, joint_map=joint_map)
    if not allow_any_size:
        _check_garment_sizes(plan)
    check_size(plan, max_cache_bytes, output=output)
    scene, times = plan.scene, plan.frames.times()
    scene_file = Path(stage.GetRootLayer().realPath)
    if skip_current and is_current(output, plan):
        log.info("%s is up to date (inputs %s); nothing to bake", output, plan.inputs_sha256[:12])
        shot_path = None
        if shot is not None:
            shot_path = Path(shot) if Path(shot).exists() and not force else write_shot_layer(
                shot, cache=output, scene=scene_file, stage=scene.stage, start=times[0], end=times[-1],
                force=True, protected=protected)
        return BakeResult(cache=Path(output), shot=shot_path, times=times, garments=(),
                          seconds=time.perf_counter() - began, skipped=True,
                          inputs_sha256=plan.inputs_sha256)
    check_output_path(output, force=force, protected=protected)
    if shot is not None:
        check_output_path(shot, force=force, protected=protected)
    for target in (output, shot):
        if target is not None:  # left by a bake of the same target that was killed
            remove_stale_temps(target)

    characters = plan.characters()
    motions: dict[str, CanonicalMotion] = {}
    notes: dict[tuple[str, str], list[str]] = {}
    reports = []
    with CacheLayerWriter(output, stage=scene.stage, start=times[0], end=times[-1],
                          force=force, protected=protected) as writer:
        for garment in plan.chosen:
            char: Character = characters[garment.body_path]
            body = plan.bodies[char.gender]
            if char.prim_path not in motions:  # once per character, whatever it wears
                motions[char.prim_path] = canonical_motion(char, read_motion(stage, char, times),
                                                           shape_body(body, char.betas)[1])
            motion = motions[char.prim_path]
            choice = plan.tiers[garment.prim_path]
            key = (char.prim_path, choice.bundle.sha256 if choice.bundle is not None else "")
            if key not in notes:  # once per character and bundle: the poses against what it was trained on
                notes[key] = range_notes(char, motion, times, choice.bundle)
            to_prim = garment_from_internal(stage, garment.prim_path, times)  # (T, 4, 4)
            reports.append(bake_garment(writer, garment, char, body, motion, times, choice.tier, to_prim,
                                        chunk=chunk, progress=progress, bundle=choice.bundle,
                                        batch_size=batch_size, cache=cache, notes=notes[key],
                                        source=scene.stage.identifier, on_progress=on_progress,
                                        strict=strict, guard=guard))
        # Both layers are saved under temporary names before either is renamed: a full disk or
        # SIGTERM leaves neither, never a cache without its shot.
        try:
            together = [] if shot is None else [stage_shot_layer(shot, cache=writer.path, scene=scene_file,
                                                                 stage=scene.stage, start=times[0], end=times[-1],
                                                                 force=force, protected=protected)]
            cache_path = writer.commit(to_custom_data(_provenance(plan, reports)), together=together)
        except BaseException:  # SIGTERM too, wherever it came: the shot's temporary file goes with the cache's
            if shot is not None:
                remove_stale_temps(shot)
            raise
    shot_path = None if shot is None else Path(shot)
    return BakeResult(cache=cache_path, shot=shot_path, times=times, garments=tuple(reports),
                      seconds=time.perf_counter() - began, inputs_sha256=plan.inputs_sha256)

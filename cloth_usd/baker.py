"""Bake: a USD shot in, a garment point-cache layer out.

This module joins the USD boundary (``cloth_usd.usd``) with the numpy core; it holds
no maths of its own. Frames are computed and handed to the layer writer a batch at a
time, so memory grows with the output layer only. Shape letters: T frames, N garment
vertices.
"""

from __future__ import annotations

import copy
import hashlib
import json
import logging
import os
import re
import time
from collections import OrderedDict
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING, Any, Callable, Sequence

import numpy as np

from ._version import __version__
from .core.body import BodyModel, load_body_model, shape_body
from .core.files import file_sha256
from .core.frames import CanonicalMotion, canonical_motion
from .core.graph import directed_edges
from .core.guard import GuardLimits, check_frames
from .core.limits import BETA_LIMIT, betas_outside, pose_outliers
from .core.scene import Character, Garment, Scene, Tier
from .core.skinning import SkinBinding, bind_garment, skin_garment
from .errors import ArgumentError, BodyModelError, GarmentError, SceneError

if TYPE_CHECKING:
    from .runtime.bundle import ModelBundle

__all__ = ["FrameRange", "GarmentReport", "BakeResult", "BakePlan", "ModelCache", "bake", "bake_plan",
           "stitch_chunks", "parse_frames", "parse_tier", "FAR_FROM_BODY", "LEARNED_BATCH_VERTICES",
           "MAX_CACHE_BYTES", "cache_bytes"]

log = logging.getLogger(__name__)

#: A garment whose rest vertices lie further than this from the body surface on
#: average [m] is warned about: its ``cloth:body`` may target the wrong character.
FAR_FROM_BODY = 0.10
#: Garment vertices per learned-model call when ``bake(batch_size=None)``: the model's
#: activations grow with frames x vertices (about 100 MiB per 4000-vertex frame at width 0.125).
LEARNED_BATCH_VERTICES = 16_000
#: Largest cache a single bake builds [bytes]: the layer is held in memory until it is
#: saved, so a longer range is refused up front (bake it in chunks, ``batch --chunk-frames``).
MAX_CACHE_BYTES = 16 * 2 ** 30


@dataclass(frozen=True)
class FrameRange:
    """An inclusive range of time codes."""

    start: float
    end: float
    step: float = 1.0

    def count(self) -> int:
        """T, the number of time codes, without making them."""
        return int(np.floor((self.end - self.start) / self.step + 1e-9)) + 1

    def times(self) -> np.ndarray:
        """(T,) float64 time codes from start to end inclusive."""
        return self.start + self.step * np.arange(self.count(), dtype=np.float64)

    def __str__(self) -> str:
        """``START:END:STEP``, as :func:`parse_frames` reads it."""
        return f"{self.start:.10g}:{self.end:.10g}:{self.step:.10g}"


_FRAMES = re.compile(r"^\s*(-?[\d.]+)\s*:\s*(-?[\d.]+)\s*(?::\s*(-?[\d.]+)\s*)?$")


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
    max_displacement_mm: float = 0.0
    """Largest distance of a baked vertex from its rest position, root translation
    removed, over all frames [mm] (canonical body frame)."""
    max_offset_mm: float = 0.0
    """Largest distance of a baked vertex from its skinned position [mm] (0 for the
    skinning tier); never more than the guard's :attr:`~cloth_usd.core.guard.GuardLimits.max_offset`."""
    fallback_coarse: int = 0
    """Detail-tier frames the guard replaced by the coarse tier (:mod:`cloth_usd.core.guard`)."""
    fallback_skinning: int = 0
    """Learned-tier frames the guard replaced by the skinning tier."""
    warnings: tuple[str, ...] = ()
    """The warnings logged for this garment (inputs outside the trained range, ...)."""


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
    """Digest of everything the bake depends on (:class:`BakePlan`)."""


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


class ModelCache:
    """Body models, model bundles and bound garments kept across bakes.

    A batch worker keeps one for all its jobs, so each body model and bundle is loaded
    (and verified) once per process and each garment is bound to its body once, even
    when its frames come in several chunks. Files are assumed not to change while a
    cache lives.

    Args:
        max_garments: bound garments kept (least recently used dropped first).
    """

    def __init__(self, max_garments: int = 8) -> None:
        self._bodies: dict[tuple[str, str], BodyModel] = {}
        self._bundles: dict[tuple[str, ...] | None, dict] = {}
        self._garments: OrderedDict[str, Any] = OrderedDict()
        self.max_garments = max_garments

    def body(self, path: str | Path | None, gender: str) -> BodyModel:
        """The body model of :func:`~cloth_usd.core.body.load_body_model`, loaded once."""
        key = ("" if path is None else os.path.abspath(path), gender)
        if key not in self._bodies:
            self._bodies[key] = load_body_model(path, gender=gender)
        return self._bodies[key]

    def bundles(self, models: Sequence[str | Path] | None) -> dict:
        """The bundles found so far in these search folders, by category."""
        key = None if models is None else tuple(os.path.abspath(m) for m in models)
        return self._bundles.setdefault(key, {})

    def garment(self, key: str, make: Callable[[], Any]) -> Any:
        """``make()`` once per ``key``."""
        if key in self._garments:
            self._garments.move_to_end(key)
            return self._garments[key]
        value = make()
        self._garments[key] = value
        while len(self._garments) > self.max_garments:
            self._garments.popitem(last=False)
        return value


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


@dataclass
class _Setup:
    """Everything a bake resolves before computing a frame."""

    stage: Any
    scene: Scene
    protected: list[str]
    chosen: list[Garment]
    tiers: dict[str, tuple[Tier, "ModelBundle | None"]]
    frange: FrameRange
    bodies: dict[str, BodyModel]
    """By gender: the body models the chosen garments' characters use."""
    inputs_sha256: str


def _open(scene_path: str | Path) -> tuple[Any, list[str]]:
    from .usd.read import open_stage

    stage = open_stage(scene_path)
    return stage, [layer.realPath for layer in stage.GetUsedLayers()]


def _setup(stage, protected: list[str], *, frames, garments, tier, body_model, models,
           cache: ModelCache, joint_map=None) -> _Setup:
    from .core.joint_names import as_joint_map

    from .usd.read import read_scene

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
    bodies = {}
    for g in chosen:
        gender = characters[g.body_path].gender
        if gender not in bodies:
            bodies[gender] = cache.body(body_model, gender)
        _check_shape_components(characters[g.body_path], bodies[gender], source)
    digest = _inputs_digest(protected, frange, chosen, tiers, characters, bodies,
                            dict(joint_map.entries) if joint_map is not None else {})
    return _Setup(stage=stage, scene=scene, protected=protected, chosen=chosen, tiers=tiers,
                  frange=frange, bodies=bodies, inputs_sha256=digest)


def _check_shape_components(char: Character, body: BodyModel, source: str) -> None:
    """BodyModelError when the stage's betas use shape components the body model lacks."""
    extra = np.flatnonzero(char.betas[body.num_betas:]) + body.num_betas
    if extra.size:
        used = int(extra[-1]) + 1
        raise BodyModelError(
            f"{source} <{char.prim_path}>: smpl:betas[{extra[0]}] is {char.betas[extra[0]]:g}, but the body "
            f"model {body.source} has only {body.num_betas} shape components (the stage's betas use {used}); "
            f"pass a body model with at least {used}, or zero the extra betas")


def cache_bytes(frames: int, vertices: Sequence[int]) -> int:
    """Estimated size [bytes] of a cache of ``frames`` time samples of garments with these
    vertex counts: float32 points (12 bytes a vertex) and a 24-byte extent per frame."""
    return int(frames) * sum(12 * int(n) + 24 for n in vertices)


def _available_memory() -> int | None:
    """Bytes of memory available to a new allocation (Linux ``MemAvailable``), or None."""
    try:
        with open("/proc/meminfo") as f:
            for line in f:
                if line.startswith("MemAvailable:"):
                    return int(line.split()[1]) * 1024
    except (OSError, ValueError, IndexError):
        pass
    return None


def _check_size(setup: "_Setup", frames_arg, limit: int | None) -> None:
    """ArgumentError, before anything is computed, for a cache too large to build in memory."""
    count = setup.frange.count()
    size = cache_bytes(count, [g.rest_points.shape[0] for g in setup.chosen])
    cap = MAX_CACHE_BYTES if limit is None else int(limit)
    available = _available_memory() if limit is None else None
    why = None
    if size > cap:
        why = f"more than the {cap / 2 ** 30:.3g} GiB a single bake builds"
    elif available is not None and size > available:
        why = f"more than the {available / 2 ** 30:.3g} GiB of memory available"
    if why is None:
        return
    what = f"--frames {frames_arg}" if isinstance(frames_arg, str) else f"frames {setup.frange}"
    raise ArgumentError(
        f"{what}: {count} frames x {sum(g.rest_points.shape[0] for g in setup.chosen)} garment vertices "
        f"make a cache of about {size / 2 ** 30:.3g} GiB, {why}; bake a smaller range, or split it with "
        "`cloth-usd batch --chunk-frames N`")


def _inputs_digest(layer_files: Sequence[str], frange: FrameRange, chosen: Sequence[Garment],
                   tiers: dict, characters: dict[str, Character], bodies: dict[str, BodyModel],
                   joint_map: dict[str, int]) -> str:
    """sha256 of everything the cache depends on (see :attr:`BakePlan.inputs_sha256`)."""
    files = [p for p in layer_files if p and os.path.isfile(p)]
    layers = [file_sha256(files[0])] + sorted(file_sha256(p) for p in files[1:]) if files else []
    payload = {
        "tool_version": __version__,
        **({"joint_map": joint_map} if joint_map else {}),  # absent without a map: older digests hold
        "layers": layers,
        "frames": [repr(float(frange.start)), repr(float(frange.end)), repr(float(frange.step))],
        "garments": {g.prim_path: {"tier": tiers[g.prim_path][0].value,
                                   "bundle": tiers[g.prim_path][1].sha256 if tiers[g.prim_path][1] else "",
                                   "body": bodies[characters[g.body_path].gender].sha256}
                     for g in chosen},
    }
    return hashlib.sha256(json.dumps(payload, sort_keys=True).encode()).hexdigest()


def _is_current(output: str | Path, setup: _Setup) -> bool:
    """True when ``output`` is a readable cache of exactly this bake."""
    from .usd.write import cache_layer_info

    info = cache_layer_info(output)
    if info is None:
        return False
    prov = info.provenance.get("cloth_usd")
    if not isinstance(prov, dict) or prov.get("inputs_sha256") != setup.inputs_sha256:
        return False
    count = setup.frange.times().shape[0]
    return all(info.samples.get(f"{g.prim_path}.points") == count for g in setup.chosen)


def bake_plan(scene_path: str | Path, output: str | Path | None = None, *,
              frames: FrameRange | str | None = None, garments: Sequence[str] | None = None,
              tier: Tier | str | None = None, body_model: str | Path | None = None,
              models: str | Path | Sequence[str | Path] | None = None,
              cache: ModelCache | None = None, joint_map: dict[str, str] | str | Path | None = None) -> BakePlan:
    """Resolve a bake without computing it: its frames, garments and inputs digest, and
    whether ``output`` already holds it. Arguments as for :func:`bake`."""
    stage, protected = _open(scene_path)
    setup = _setup(stage, protected, frames=frames, garments=garments, tier=tier, body_model=body_model,
                   models=models, cache=cache or ModelCache(), joint_map=joint_map)
    return BakePlan(frames=setup.frange, garments=tuple(g.prim_path for g in setup.chosen),
                    inputs_sha256=setup.inputs_sha256,
                    current=output is not None and _is_current(output, setup))


def bake(scene_path: str | Path, output: str | Path, *, shot: str | Path | None = None,
         frames: FrameRange | str | None = None, garments: Sequence[str] | None = None,
         tier: Tier | str | None = None, force: bool = False,
         body_model: str | Path | None = None, chunk: int = 64,
         progress: bool = False, models: str | Path | Sequence[str | Path] | None = None,
         batch_size: int | None = None, skip_current: bool = False, cache: ModelCache | None = None,
         on_progress: Callable[[str, int, int], None] | None = None, strict: bool = False,
         guard: GuardLimits = GuardLimits(), joint_map: dict[str, str] | str | Path | None = None,
         max_cache_bytes: int | None = None) -> BakeResult:
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
        batch_size: frames per model call (learned tiers); None picks about
            :data:`LEARNED_BATCH_VERTICES` garment vertices per call (at most 16 frames),
            which bounds memory: a 300-frame detail bake of a 4031-vertex shirt peaked
            at 1996 MiB with 16 frames per call.
        skip_current: when ``output`` already holds this very bake (its provenance has
            the same :attr:`BakePlan.inputs_sha256` and every frame), write nothing and
            return a result with ``skipped=True``. A different existing file still
            needs ``force``.
        cache: body models, bundles and bound garments to reuse across bakes.
        on_progress: called with ``(garment prim, frames done, frames total)`` after
            each batch of frames is added to the (temporary) layer.
        strict: a learned frame the guard rejects is an error (nothing is written) instead
            of falling back to the next safer tier for that frame.
        guard: when a learned frame is not a garment (:mod:`cloth_usd.core.guard`).
        joint_map: ``{their joint name: SMPL joint name}`` or a JSON / TOML file of it, for
            skeletons named in no known convention (:mod:`cloth_usd.core.joint_names`).
        max_cache_bytes: refuse a bake whose cache (:func:`cache_bytes`) would be larger;
            None: :data:`MAX_CACHE_BYTES` or the memory available, whichever is less.

    Raises:
        ArgumentError: among others, ``shot`` is the same file as ``output``, or the cache
            would be too large to build (both before anything is computed).
    """
    from .usd.read import garment_from_internal, read_motion
    from .usd.write import CacheLayerWriter, check_output_path, remove_stale_temps, write_shot_layer

    began = time.perf_counter()
    cache = cache or ModelCache()
    if shot is not None and _same_file(shot, output):
        raise ArgumentError(f"--shot {shot}: is the same file as -o {output}; the shot layer sublayers the "
                            "cache, so name a different file for it")
    stage, protected = _open(scene_path)
    check_output_path(output, force=force or skip_current, protected=protected)
    if shot is not None:
        check_output_path(shot, force=force or skip_current, protected=protected)
    setup = _setup(stage, protected, frames=frames, garments=garments, tier=tier, body_model=body_model,
                   models=models, cache=cache, joint_map=joint_map)
    _check_size(setup, frames, max_cache_bytes)
    scene, times = setup.scene, setup.frange.times()
    scene_file = Path(stage.GetRootLayer().realPath)
    if skip_current and _is_current(output, setup):
        log.info("%s is up to date (inputs %s); nothing to bake", output, setup.inputs_sha256[:12])
        shot_path = None
        if shot is not None:
            shot_path = Path(shot) if Path(shot).exists() and not force else write_shot_layer(
                shot, cache=output, scene=scene_file, stage=scene.stage, start=times[0], end=times[-1],
                force=True, protected=protected)
        return BakeResult(cache=Path(output), shot=shot_path, times=times, garments=(),
                          seconds=time.perf_counter() - began, skipped=True,
                          inputs_sha256=setup.inputs_sha256)
    check_output_path(output, force=force, protected=protected)
    if shot is not None:
        check_output_path(shot, force=force, protected=protected)
    for target in (output, shot):
        if target is not None:  # left by a bake of the same target that was killed
            remove_stale_temps(target)

    characters = {c.prim_path: c for c in scene.characters}
    motions: dict[str, tuple[CanonicalMotion, list[str]]] = {}
    reports = []
    with CacheLayerWriter(output, stage=scene.stage, start=times[0], end=times[-1],
                          force=force, protected=protected) as writer:
        for garment in setup.chosen:
            char: Character = characters[garment.body_path]
            body = setup.bodies[char.gender]
            if char.prim_path not in motions:  # once per character, whatever it wears
                motion = canonical_motion(char, read_motion(stage, char, times), shape_body(body, char.betas)[1])
                motions[char.prim_path] = motion, _range_notes(char, motion, times)
            motion, notes = motions[char.prim_path]
            g_tier, g_bundle = setup.tiers[garment.prim_path]
            report = _bake_garment(stage, writer, garment, char, body, motion, times, g_tier,
                                   chunk=chunk, progress=progress, garment_from_internal=garment_from_internal,
                                   bundle=g_bundle, batch_size=batch_size, cache=cache, notes=notes,
                                   source=scene.stage.identifier, on_progress=on_progress,
                                   strict=strict, guard=guard)
            reports.append(report)
        used = {b.sha256: b for _, b in setup.tiers.values() if b is not None}
        provenance = _provenance(scene, setup.frange, setup.bodies, reports, list(used.values()))
        provenance["cloth_usd"]["inputs_sha256"] = setup.inputs_sha256
        cache_path = writer.commit(provenance)
    shot_path = None
    if shot is not None:
        shot_path = write_shot_layer(shot, cache=cache_path, scene=scene_file,
                                     stage=scene.stage, start=times[0], end=times[-1],
                                     force=force, protected=protected)
    return BakeResult(cache=cache_path, shot=shot_path, times=times, garments=tuple(reports),
                      seconds=time.perf_counter() - began, inputs_sha256=setup.inputs_sha256)


def _same_file(a: str | Path, b: str | Path) -> bool:
    """True when two paths name one file (after links, ``./`` and ``..``; hard links too)."""
    if os.path.realpath(a) == os.path.realpath(b):
        return True
    try:
        return os.path.samefile(a, b)
    except OSError:  # one of them does not exist yet
        return False


def _range_notes(char: Character, motion: CanonicalMotion, times: np.ndarray) -> list[str]:
    """What in a character's shape and motion lies outside the trained range, one line each."""
    notes = []
    outside = betas_outside(char.betas)
    if outside.size:
        listed = ", ".join(f"beta[{i}] = {char.betas[i]:g}" for i in outside)
        notes.append(f"body <{char.prim_path}> has {listed}, outside the trained range "
                     f"|beta| <= {BETA_LIMIT:g}, at every frame")
    poses = pose_outliers(motion.poses)
    if poses is not None:
        first = times[poses.frames[0]]
        notes.append(f"body <{char.prim_path}> is posed outside the trained joint limits at frame "
                     f"{first:g} ({poses.joint} {poses.angle_deg:.0f} deg about {poses.axis}, trained "
                     f"{poses.low_deg:.0f}..{poses.high_deg:.0f}) and at {poses.frames.size - 1} other "
                     f"of {times.shape[0]} frames")
    return notes


def _garment_key(garment: Garment, body: BodyModel, betas: np.ndarray, rest: np.ndarray,
                 tier: Tier, bundle: "ModelBundle | None") -> str:
    h = hashlib.sha256()
    for part in (body.sha256.encode(), tier.value.encode(), (bundle.sha256 if bundle else "").encode(),
                 np.ascontiguousarray(betas, dtype=np.float64).tobytes(),
                 np.ascontiguousarray(rest, dtype=np.float64).tobytes(),
                 np.ascontiguousarray(garment.triangles, dtype=np.int64).tobytes()):
        h.update(part)
        h.update(b"|")
    return h.hexdigest()


def _bake_garment(stage, writer, garment: Garment, char: Character, body: BodyModel,
                  motion: CanonicalMotion, times: np.ndarray, tier: Tier, *, chunk: int, progress: bool,
                  garment_from_internal, bundle: "ModelBundle | None" = None,
                  batch_size: int | None = None, cache: ModelCache | None = None, notes: Sequence[str] = (),
                  source: str = "", on_progress: Callable[[str, int, int], None] | None = None,
                  strict: bool = False, guard: GuardLimits = GuardLimits()) -> GarmentReport:
    from tqdm.auto import tqdm

    cache = cache or ModelCache()
    where = f"{source} <{garment.prim_path}>"
    rest = motion.rest_points(garment.rest_points)

    def prepare() -> tuple[SkinBinding, Any]:
        binding = bind_garment(body, char.betas, rest)
        if tier is Tier.SKINNING:
            return binding, None
        from .runtime.garment import LearnedGarment

        return binding, LearnedGarment(bundle, body, char.betas, rest, garment.triangles, binding=binding)

    binding, learned = cache.garment(_garment_key(garment, body, char.betas, rest, tier, bundle), prepare)
    warnings = [f"{where}: {note}" for note in notes]
    distance = float(binding.association.distance.mean())
    if distance > FAR_FROM_BODY:
        warnings.append(f"{where}: the garment lies {distance:.2f} m from the body <{char.prim_path}> on "
                        f"average at rest (a worn garment is within {FAR_FROM_BODY:g} m); check its "
                        "cloth:body and rest points")
    for w in warnings:
        log.warning("%s", w)
    poses, transl = motion.poses, motion.transl
    to_prim = garment_from_internal(stage, garment.prim_path, times)  # (T, 4, 4)
    num_t = times.shape[0]
    if learned is not None:
        if batch_size is None:
            batch_size = max(1, min(16, LEARNED_BATCH_VERTICES // max(1, learned.num_vertices)))
        chunk = batch_size
    moved, max_disp, max_off = 0, 0.0, 0.0
    edges = directed_edges(garment.triangles, binding.rest_points.shape[0])
    edges = edges[edges[:, 0] < edges[:, 1]]
    fallbacks: list[tuple[float, Tier, str]] = []  # (time code, tier used instead, why)
    with tqdm(total=num_t, desc=garment.prim_path, unit="frame", disable=not progress,
              leave=False) as bar:
        for lo in range(0, num_t, chunk):
            hi = min(lo + chunk, num_t)
            skinned = skin_garment(binding, poses[lo:hi], transl[lo:hi], body.parents)
            pts = skinned
            if learned is not None:
                frames = learned.evaluate(tier, poses[lo:hi], transl[lo:hi], batch_size=batch_size,
                                          skinned=skinned)
                pts, used = _guarded(learned, tier, frames.points, skinned, poses[lo:hi], transl[lo:hi], edges,
                                     guard, batch_size)
                for i, (replaced_by, why) in used.items():
                    if strict:
                        raise GarmentError(f"{where}: the {tier.value} tier's frame {times[lo + i]:g} is not a "
                                           f"garment ({why}); --strict refuses it and nothing was written. Bake "
                                           "without --strict to replace such frames by a safer tier")
                    fallbacks.append((float(times[lo + i]), replaced_by, why))
                max_off = max(max_off, float(np.linalg.norm(pts - skinned, axis=-1).max(initial=0.0)))
                moved += int(frames.moved.sum())
            bad = ~np.isfinite(pts).all(axis=(1, 2))
            if bad.any():
                raise GarmentError(f"{where}: the deformed points are not finite at frame "
                                   f"{times[lo + int(np.argmax(bad))]:g} (tier {tier.value}); nothing "
                                   "was written. Check the skeleton's animation at that frame")
            disp = np.linalg.norm(pts - transl[lo:hi, None, :] - binding.rest_points, axis=-1)
            max_disp = max(max_disp, float(disp.max()))
            m = to_prim[lo:hi]
            local = np.einsum("tab,tnb->tna", m[:, :3, :3], pts) + m[:, None, :3, 3]
            writer.add_points(garment.prim_path, times[lo:hi], local)
            bar.update(hi - lo)
            if on_progress is not None:
                on_progress(garment.prim_path, hi, num_t)
    for replaced_by in (Tier.COARSE, Tier.SKINNING):
        hits = [(t, why) for t, by, why in fallbacks if by is replaced_by]
        if hits:
            w = (f"{where}: {len(hits)} of {num_t} frames of the {tier.value} tier are not a garment and were "
                 f"replaced by the {replaced_by.value} tier, first at frame {hits[0][0]:g} ({hits[0][1]})")
            log.warning("%s", w)
            warnings.append(w)
    log.info("%s: %d vertices, %d frames, tier %s", garment.prim_path, binding.rest_points.shape[0],
             num_t, tier.value)
    return GarmentReport(prim_path=garment.prim_path, tier=tier,
                         vertices=int(binding.rest_points.shape[0]), frames=num_t,
                         mean_body_distance_mm=distance * 1000.0,
                         bundle=None if learned is None else bundle.name,
                         fit=None if learned is None else tuple(float(a) for a in learned.alpha),
                         postprocess_moved=moved, max_displacement_mm=max_disp * 1000.0,
                         max_offset_mm=max_off * 1000.0, warnings=tuple(warnings),
                         fallback_coarse=sum(by is Tier.COARSE for _, by, _ in fallbacks),
                         fallback_skinning=sum(by is Tier.SKINNING for _, by, _ in fallbacks))


def _guarded(learned, tier: Tier, points: np.ndarray, skinned: np.ndarray, poses: np.ndarray,
             transl: np.ndarray, edges: np.ndarray, limits: GuardLimits, batch_size: int
             ) -> tuple[np.ndarray, dict[int, tuple[Tier, str]]]:
    """A learned tier's frames, each one that is not a garment replaced by the next safer tier.

    Args:
        learned: the garment's :class:`~cloth_usd.runtime.garment.LearnedGarment`.
        points: (T, N, 3) the ``tier`` output [m]; skinned: (T, N, 3) the skinned garment [m].
        poses: (T, 72) [rad]; transl: (T, 3) [m]: the frames, to evaluate the coarse tier on.
        edges: (E, 2) the garment's edges.
    Returns:
        ``(points (T, N, 3), {frame index: (tier used instead, why the frame was rejected)})``.
    """
    rest = learned.binding.rest_points
    faults = check_frames(points, skinned, rest, edges, limits)
    out = np.array(points, dtype=np.float64)
    bad = np.flatnonzero(~faults.ok)
    used: dict[int, tuple[Tier, str]] = {}
    if bad.size and tier is Tier.DETAIL:
        coarse = learned.evaluate(Tier.COARSE, poses[bad], transl[bad], batch_size=batch_size,
                                  skinned=skinned[bad]).points
        ok = check_frames(coarse, skinned[bad], rest, edges, limits).ok
        out[bad[ok]] = coarse[ok]
        used.update((int(i), (Tier.COARSE, faults.reasons[i])) for i in bad[ok])
        bad = bad[~ok]
    out[bad] = skinned[bad]
    used.update((int(i), (Tier.SKINNING, faults.reasons[i])) for i in bad)
    return out, used


def stitch_chunks(chunks: Sequence[str | Path], output: str | Path, *, inputs_sha256: str = "",
                  force: bool = False) -> Path:
    """Join caches that :func:`bake` wrote for consecutive frame chunks of one bake.

    The result is the cache one bake of the whole range writes: the same time samples,
    and provenance with the whole frame range, frame counts summed and, given the whole
    bake's ``inputs_sha256`` (:func:`bake_plan`), the same digest.

    Args:
        chunks: the chunk caches, in time order.
        output: the cache layer to write.
    Raises:
        ArgumentError: a chunk is missing, unreadable, or not from the same bake.
    """
    from .usd.write import cache_layer_info, stitch_layers

    provs, infos = [], []
    for c in chunks:
        info = cache_layer_info(c)
        prov = None if info is None else info.provenance.get("cloth_usd")
        if not isinstance(prov, dict):
            raise ArgumentError(f"{c}: not a cloth_usd cache layer; cannot stitch it into {output}")
        provs.append(prov)
        infos.append(info)
    if not provs:
        raise ArgumentError(f"{output}: no chunk layers to stitch")
    first = provs[0]
    for c, p in zip(chunks, provs):
        for key in ("source_layer", "model_bundle", "body_models"):
            if p.get(key) != first.get(key):
                raise ArgumentError(f"{c}: {key} differs from {chunks[0]}'s; chunks of one bake only")
        if set(p.get("garments", {})) != set(first.get("garments", {})):
            raise ArgumentError(f"{c}: bakes other garments than {chunks[0]}; chunks of one bake only")
    merged = copy.deepcopy(first)
    step = float(str(first.get("frame_range", "0:0:1")).split(":")[-1])
    merged["frame_range"] = str(FrameRange(infos[0].start, infos[-1].end, step))
    merged["inputs_sha256"] = inputs_sha256
    for prim, g in merged["garments"].items():
        parts = [p["garments"][prim] for p in provs]
        g["frames"] = sum(int(x["frames"]) for x in parts)
        for key in ("postprocess_moved", "fallback_coarse", "fallback_skinning"):
            if key in g:
                g[key] = sum(int(x.get(key, 0)) for x in parts)
        for key in ("max_displacement_mm", "max_offset_mm"):
            if key in g:
                g[key] = max(float(x.get(key, 0.0)) for x in parts)
    return stitch_layers(output, chunks, provenance={"cloth_usd": merged}, force=force)


def _garment_provenance(r: GarmentReport) -> dict:
    out = {"tier": r.tier.value, "vertices": r.vertices, "frames": r.frames,
           "mean_body_distance_mm": round(r.mean_body_distance_mm, 3),
           "max_displacement_mm": round(r.max_displacement_mm, 3)}
    if r.fit is None:
        out["fit"] = "not computed (skinning tier)"
    else:  # a string of numbers: VtDictionary keeps no plain list of floats
        out.update(fit=" ".join(f"{a:.6g}" for a in r.fit), model_bundle=r.bundle,
                   postprocess_moved=r.postprocess_moved, max_offset_mm=round(r.max_offset_mm, 3),
                   fallback_coarse=r.fallback_coarse, fallback_skinning=r.fallback_skinning)
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
            "frame_range": str(frange),
            "body_models": {g: {"file": Path(b.source).name, "sha256": b.sha256}
                            for g, b in bodies.items()},
            "model_bundle": bundle,
            "garments": {r.prim_path: _garment_provenance(r) for r in reports},
        }
    }

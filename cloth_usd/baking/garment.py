"""One garment's frames: skinned, the learned tier evaluated and guarded, written a batch
at a time. Shape letters: T frames, N garment vertices, E edges."""

from __future__ import annotations

import logging
from typing import Any, Callable, Sequence

import numpy as np
from tqdm.auto import tqdm

from ..core.body import BodyModel
from ..core.fit import FIT_LIMIT
from ..core.frames import CanonicalMotion
from ..core.graph import directed_edges
from ..core.guard import GuardLimits, check_frames, guard_limits
from ..core.limits import BETA_LIMIT, BETA_MARGIN, betas_outside, betas_outside_range, pose_outliers
from ..core.mesh import vector_lengths
from ..core.plausibility import body_notes, has_legs
from ..core.provenance import GarmentReport
from ..core.scene import Category, Character, Garment, Tier
from ..core.skinning import SkinBinding, bind_worn, skin_garment
from ..errors import BundleError, GarmentError
from ..runtime.bundle import ModelBundle
from ..runtime.garment import LearnedGarment
from .cache import ModelCache, garment_key

__all__ = ["LEARNED_BATCH_VERTICES", "range_notes", "bake_garment"]

log = logging.getLogger(__name__)

#: Garment vertices per learned-model call when ``bake(batch_size=None)``: the model's
#: activations grow with frames x vertices (about 100 MiB per 4000-vertex frame at width 0.125).
LEARNED_BATCH_VERTICES = 16_000


def range_notes(char: Character, motion: CanonicalMotion, times: np.ndarray,
                bundle: ModelBundle | None = None) -> list[str]:
    """What in a character's shape and motion lies outside the trained range, one line each.

    The shape is checked against the bodies the bundle was trained on
    (:attr:`~cloth_usd.runtime.bundle.ModelBundle.betas_limits`, give or take
    :data:`~cloth_usd.core.limits.BETA_MARGIN`), or, for the skinning tier and a bundle that
    records none, against ``|beta| <= BETA_LIMIT``. The poses are
    checked for a learned tier only (``bundle``; skinning follows any pose and was trained on
    none): against the joint angles the bundle was trained on
    (:attr:`~cloth_usd.runtime.bundle.ModelBundle.pose_limits`), or, for a bundle that records
    none, :data:`~cloth_usd.core.limits.JOINT_LIMITS`, which its procedural motions kept.

    Args:
        times: (T,) the time codes of ``motion``.
        bundle: the learned tier's bundle; None for the skinning tier.
    """
    notes = []
    limits = None if bundle is None else bundle.betas_limits
    outside = betas_outside(char.betas) if limits is None else betas_outside_range(char.betas, limits)
    if outside.size:
        listed = ", ".join(f"beta[{i}] = {char.betas[i]:g}" for i in outside)
        if limits is None:
            trained = f"the trained range |beta| <= {BETA_LIMIT:g}"
        else:  # the bodies this bundle was trained on
            lim = np.zeros((len(char.betas), 2))
            lim[:min(len(lim), len(limits))] = limits[:len(lim)]
            spans = ", ".join(f"beta[{i}] {lim[i, 0]:g}..{lim[i, 1]:g}" for i in outside)
            trained = f"the bodies bundle '{bundle.name}' was trained on ({spans}, by more than {BETA_MARGIN:g})"
        notes.append(f"body <{char.prim_path}> has {listed}, outside {trained}, at every frame")
    poses = None if bundle is None else pose_outliers(motion.poses, limits=bundle.pose_limits)
    if poses is not None:
        first = times[poses.frames[0]]
        trained = "the trained joint limits" if bundle.pose_limits is None else \
            f"the joint angles bundle '{bundle.name}' was trained on"
        notes.append(f"body <{char.prim_path}> is posed outside {trained} at frame "
                     f"{first:g} ({poses.joint} {poses.angle_deg:.0f} deg about {poses.axis}, trained "
                     f"{poses.low_deg:.0f}..{poses.high_deg:.0f}) and at {poses.frames.size - 1} other "
                     f"of {times.shape[0]} frames")
    return notes


#: A garment's rest points farther than this [m] from the rest its own bundle was trained on are
#: warned about (the same triangles, moved or reshaped: the model reads them as its own).
REST_TOLERANCE = 0.005


def _rest_notes(bundle: ModelBundle | None, rest: np.ndarray, betas: np.ndarray) -> list[str]:
    """A note when a garment's own bundle is handed its garment in another rest shape than the
    one it was trained on, on the same body (on another body the garment is carried there and
    sits elsewhere by design)."""
    trained = None if bundle is None else bundle.trained_rest(betas)
    if trained is None or trained.shape != rest.shape:
        return []
    off = float(np.linalg.norm(rest - trained, axis=1).max())
    if off <= REST_TOLERANCE:
        return []
    return [f"its rest points lie up to {off * 1000:.0f} mm from the garment bundle '{bundle.name}' was trained on "
            f"(the same triangles, moved or reshaped); the learned tiers read it as that garment (a bundle of "
            f"its own: cloth-usd train-garment)"]


def bake_garment(writer, garment: Garment, char: Character, body: BodyModel, motion: CanonicalMotion,
                 times: np.ndarray, tier: Tier, to_prim: np.ndarray, *, chunk: int, progress: bool,
                 bundle: ModelBundle | None = None, batch_size: int | None = None,
                 cache: ModelCache | None = None, notes: Sequence[str] = (), source: str = "",
                 on_progress: Callable[[str, int, int], None] | None = None, strict: bool = False,
                 guard: GuardLimits | None = None) -> GarmentReport:
    """Evaluate one garment at every time code and add its points to ``writer``.

    Args:
        writer: the :class:`~cloth_usd.usd.write.CacheLayerWriter` of the cache.
        times: (T,) time codes; motion: the character's motion at them.
        to_prim: (T, 4, 4) float64 internal world frame -> the garment prim's local frame.
        chunk: frames per batch (skinning tier; a learned tier uses ``batch_size``).
        notes: what lies outside the trained range (:func:`range_notes`), warned about.
        strict: a learned frame the guard rejects is a GarmentError instead of a fallback.
        guard: when a learned frame is not a garment (None: the garment's category's,
            :func:`~cloth_usd.core.guard.guard_limits`).
    Raises:
        GarmentError: non-finite points, or a rejected frame with ``strict``.
    """
    cache = cache or ModelCache()
    guard = guard if guard is not None else guard_limits(garment.category)
    where = f"{source} <{garment.prim_path}>"
    rest = motion.rest_points(garment.rest_points)

    def prepare() -> tuple[SkinBinding, Any]:
        binding = bind_worn(body, char.betas, rest, garment.triangles, garment.category)
        if tier is Tier.SKINNING:
            return binding, None
        try:
            return binding, LearnedGarment(bundle, body, char.betas, rest, garment.triangles, binding=binding)
        except BundleError as exc:  # a garment's own bundle given another garment: say which
            if bundle is not None and bundle.garment is not None:
                raise BundleError(f"{where}: {exc}") from None
            raise

    binding, learned = cache.garment(garment_key(garment, body, char.betas, rest, tier, bundle), prepare)
    warnings = [f"{where}: {note}" for note in notes]
    warnings += [f"{where}: {note}" for note in body_notes(binding, body, char.betas, char.prim_path)]
    measured = None if learned is None else learned.pair.alpha_measured
    if measured is not None and np.any(np.abs(measured) > FIT_LIMIT):  # None: the skinning tier
        listed = ", ".join(f"{a:.3g}" for a in measured)
        warnings.append(f"{where}: its fit on the body <{char.prim_path}> (fit attribute {listed}) lies past "
                        f"+-{FIT_LIMIT:g} on a factor, beyond the garments bundle '{bundle.name}' was trained on; the "
                        f"{tier.value} tier reads it clamped to +-{FIT_LIMIT:g} (a bundle of its own: "
                        f"cloth-usd train-garment)")
    warnings += [f"{where}: {note}" for note in _rest_notes(bundle, rest, char.betas)] if learned is not None else []
    if learned is not None and bundle.garment is None and garment.category is not Category.TROUSERS \
            and has_legs(rest, garment.triangles, np.ones(len(rest), dtype=bool), learned.pair.joints[0]):
        warnings.append(f"{where}: it has legs (two tubes below the hips: a suit or an overall in one piece), which no "
                        f"{garment.category.value} the bundle '{bundle.name}' was trained on has; its "
                        f"{tier.value} tier reads it as one (models of its own: cloth-usd train-garment)")
    for w in warnings:
        log.warning("%s", w)
    poses, transl = motion.poses, motion.transl
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
                max_off = max(max_off, float(vector_lengths(pts - skinned).max(initial=0.0)))
                moved += int(frames.moved.sum())
            bad = ~np.isfinite(pts).all(axis=(1, 2))
            if bad.any():
                raise GarmentError(f"{where}: the deformed points are not finite at frame "
                                   f"{times[lo + int(np.argmax(bad))]:g} (tier {tier.value}); nothing "
                                   "was written. Check the skeleton's animation at that frame")
            disp = vector_lengths(pts - transl[lo:hi, None, :] - binding.rest_points)
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
                         mean_body_distance_mm=float(binding.association.distance.mean()) * 1000.0,
                         bundle=None if learned is None else bundle.name,
                         fit=None if learned is None else tuple(float(a) for a in learned.alpha),
                         postprocess_moved=moved, max_displacement_mm=max_disp * 1000.0,
                         max_offset_mm=max_off * 1000.0, warnings=tuple(warnings),
                         fallback_coarse=sum(by is Tier.COARSE for _, by, _ in fallbacks),
                         fallback_skinning=sum(by is Tier.SKINNING for _, by, _ in fallbacks))


def _guarded(learned: LearnedGarment, tier: Tier, points: np.ndarray, skinned: np.ndarray, poses: np.ndarray,
             transl: np.ndarray, edges: np.ndarray, limits: GuardLimits, batch_size: int
             ) -> tuple[np.ndarray, dict[int, tuple[Tier, str]]]:
    """A learned tier's frames, each one that is not a garment replaced by the next safer tier.

    Args:
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

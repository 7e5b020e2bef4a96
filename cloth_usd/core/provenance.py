"""What a bake records: per-garment statistics and the provenance of a cache.

These are the typed forms; the USD layer turns :class:`Provenance` into a cache's
``customLayerData`` and back (:mod:`cloth_usd.usd.provenance`). Chunks of one bake are
joined here, in one place (:meth:`GarmentReport.merged`, :func:`merge_chunks`).
"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass
from typing import Mapping, Sequence

from .frame_range import FrameRange
from .scene import Tier

__all__ = ["GarmentReport", "FileRecord", "Provenance", "merge_chunks"]


@dataclass(frozen=True)
class GarmentReport:
    """What was baked for one garment (or for one frame chunk of it)."""

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
    """Vertex-frames the post-process pushed out of the body, plus those the detail tier's lift moved off it
    (summed over frames)."""
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

    def merged(self, later: "GarmentReport") -> "GarmentReport":
        """This garment's report joined with that of its next frame chunk: frames and counts
        summed, maxima taken, the rest (tier, vertices, rest distance, fit) this one's."""
        return dataclasses.replace(
            self, frames=self.frames + later.frames,
            postprocess_moved=self.postprocess_moved + later.postprocess_moved,
            fallback_coarse=self.fallback_coarse + later.fallback_coarse,
            fallback_skinning=self.fallback_skinning + later.fallback_skinning,
            max_displacement_mm=max(self.max_displacement_mm, later.max_displacement_mm),
            max_offset_mm=max(self.max_offset_mm, later.max_offset_mm),
            warnings=self.warnings + tuple(w for w in later.warnings if w not in self.warnings))


@dataclass(frozen=True)
class FileRecord:
    """A file a bake used, by name and content."""

    name: str
    sha256: str


@dataclass(frozen=True)
class Provenance:
    """Everything a cache records about the bake that wrote it."""

    tool_version: str
    source_layer: str
    """Identifier of the stage's root layer."""
    frames: FrameRange
    body_models: Mapping[str, FileRecord]
    """By gender: the body model files used."""
    model_bundle: FileRecord
    """The model bundle(s) used (names and digests joined by ``", "`` when several; the
    name ``none (skinning tier)`` and no digest when none)."""
    garments: tuple[GarmentReport, ...]
    inputs_sha256: str = ""
    """Digest of everything the bake depends on (:attr:`cloth_usd.baking.BakePlan.inputs_sha256`)."""


def merge_chunks(chunks: Sequence[Provenance], *, frames: FrameRange | None = None,
                 inputs_sha256: str = "") -> Provenance:
    """The provenance of one bake of the whole range, from that of its consecutive chunks
    (in time order; the caller checks they are chunks of one bake).

    Args:
        frames: the whole range, default the first chunk's start to the last one's end.
    """
    first = chunks[0]
    garments = []
    for g in first.garments:
        report = g
        for later in chunks[1:]:
            report = report.merged(next(x for x in later.garments if x.prim_path == g.prim_path))
        garments.append(report)
    if frames is None:
        frames = FrameRange(first.frames.start, chunks[-1].frames.end, first.frames.step)
    return dataclasses.replace(first, frames=frames, garments=tuple(garments), inputs_sha256=inputs_sha256)

"""Chunks of one bake joined into the cache one bake of the whole range writes."""

from __future__ import annotations

from pathlib import Path
from typing import Sequence

from ..core.frame_range import FrameRange
from ..core.provenance import merge_chunks
from ..errors import ArgumentError
from ..usd.provenance import cache_provenance, to_custom_data
from ..usd.write import cache_layer_info, stitch_layers

__all__ = ["stitch_chunks"]


def stitch_chunks(chunks: Sequence[str | Path], output: str | Path, *, inputs_sha256: str = "",
                  force: bool = False) -> Path:
    """Join caches that :func:`~cloth_usd.baking.bake` wrote for consecutive frame chunks of one bake.

    The result is the cache one bake of the whole range writes: the same time samples,
    and provenance with the whole frame range, frame counts summed and, given the whole
    bake's ``inputs_sha256`` (:func:`~cloth_usd.baking.bake_plan`), the same digest.

    Args:
        chunks: the chunk caches, in time order.
        output: the cache layer to write.
    Raises:
        ArgumentError: a chunk is missing, unreadable, or not from the same bake.
    """
    provs, infos = [], []
    for c in chunks:
        info = cache_layer_info(c)
        prov = cache_provenance(info)
        if prov is None:
            raise ArgumentError(f"{c}: not a cloth_usd cache layer; cannot stitch it into {output}")
        provs.append(prov)
        infos.append(info)
    if not provs:
        raise ArgumentError(f"{output}: no chunk layers to stitch")
    first = provs[0]
    for c, p in zip(chunks, provs):
        for key in ("source_layer", "model_bundle", "body_models"):
            if getattr(p, key) != getattr(first, key):
                raise ArgumentError(f"{c}: {key} differs from {chunks[0]}'s; chunks of one bake only")
        if {g.prim_path for g in p.garments} != {g.prim_path for g in first.garments}:
            raise ArgumentError(f"{c}: bakes other garments than {chunks[0]}; chunks of one bake only")
    whole = FrameRange(infos[0].start, infos[-1].end, first.frames.step)
    merged = merge_chunks(provs, frames=whole, inputs_sha256=inputs_sha256)
    return stitch_layers(output, chunks, provenance=to_custom_data(merged), force=force)

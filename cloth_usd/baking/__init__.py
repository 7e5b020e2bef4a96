"""Bake: a USD shot in, a garment point-cache layer out.

- :mod:`.plan`: the arguments resolved into a typed plan (garments, tiers, frames, bodies,
  inputs digest), before any frame is computed; :mod:`.digest`, :mod:`.size` beside it;
- :mod:`.garment`: one garment's frames, skinned, learned and guarded;
- :mod:`.run`: :func:`bake`, the plan through every garment into the cache layer;
- :mod:`.stitch`: frame chunks of one bake joined into one cache;
- :mod:`.cache`: body models, bundles and bound garments kept across bakes.

(Not ``cloth_usd.bake``: that name is the function, ``cloth_usd.bake(...)``.)
"""

from ..core.frame_range import FrameRange, parse_frames
from ..core.plausibility import FAR_FROM_BODY
from ..core.provenance import GarmentReport
from .cache import ModelCache
from .garment import LEARNED_BATCH_VERTICES
from .plan import BakePlan, bake_plan, parse_tier
from .run import BakeResult, bake
from .size import MAX_CACHE_BYTES, cache_bytes
from .stitch import stitch_chunks

__all__ = ["FrameRange", "GarmentReport", "BakeResult", "BakePlan", "ModelCache", "bake", "bake_plan",
           "stitch_chunks", "parse_frames", "parse_tier", "FAR_FROM_BODY", "LEARNED_BATCH_VERTICES",
           "MAX_CACHE_BYTES", "cache_bytes"]

"""Ground-truth factory: garments, bodies and motions (numpy), simulation (Newton, imported
lazily by ``cloth_usd.datagen.simulate``) and dataset shards (``cloth_usd.datagen.dataset``)."""

from .bodies import BODY_SHAPES, BodyShape, body_shapes
from .motion import MotionKind, MotionSpec, blend_from_rest, generate, resample, walk_cycle
from .tshirt import TShirtParams, make_tshirt, tshirt_variants

__all__ = [
    "BODY_SHAPES", "BodyShape", "body_shapes",
    "MotionKind", "MotionSpec", "blend_from_rest", "generate", "resample", "walk_cycle",
    "TShirtParams", "make_tshirt", "tshirt_variants",
]

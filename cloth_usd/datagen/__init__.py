"""Ground-truth factory: garments, bodies and motions (numpy; the simulator is optional)."""

from .bodies import BODY_SHAPES, BodyShape, body_shapes
from .motion import MotionKind, MotionSpec, blend_from_rest, generate, resample, walk_cycle
from .tshirt import TShirtParams, make_tshirt, tshirt_variants

__all__ = [
    "BODY_SHAPES", "BodyShape", "body_shapes",
    "MotionKind", "MotionSpec", "blend_from_rest", "generate", "resample", "walk_cycle",
    "TShirtParams", "make_tshirt", "tshirt_variants",
]

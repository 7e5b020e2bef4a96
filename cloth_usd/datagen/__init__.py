"""Ground-truth factory: garments, bodies and motions (numpy; the simulator is optional)."""

from .motion import walk_cycle
from .tshirt import TShirtParams, make_tshirt

__all__ = ["TShirtParams", "make_tshirt", "walk_cycle"]

"""The body shapes of the data set: spans of SMPL's first two shape components.

As the paper, 11 bodies from the first two components. In our embedded model beta0 is
height (about 1.49-1.90 m over -2..+2) and beta1 is girth at constant height.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..core.smpl import NUM_BETAS

__all__ = ["BodyShape", "BODY_SHAPES", "body_shapes"]


@dataclass(frozen=True)
class BodyShape:
    """A named body shape."""

    name: str
    betas: np.ndarray
    """(10,) float64 shape coefficients."""


def _shape(name: str, b0: float, b1: float) -> BodyShape:
    betas = np.zeros(NUM_BETAS)
    betas[:2] = (b0, b1)
    return BodyShape(name, betas)


#: 11 shapes: thin / regular / fat at short / medium / tall, and two in-betweens.
BODY_SHAPES: tuple[BodyShape, ...] = (
    _shape("short_thin", -2.0, -2.0), _shape("short_regular", -2.0, 0.0), _shape("short_fat", -2.0, 2.0),
    _shape("medium_thin", 0.0, -2.0), _shape("medium_regular", 0.0, 0.0), _shape("medium_fat", 0.0, 2.0),
    _shape("tall_thin", 2.0, -2.0), _shape("tall_regular", 2.0, 0.0), _shape("tall_fat", 2.0, 2.0),
    _shape("slim", -1.0, -1.0), _shape("broad", 1.0, 1.0),
)


def body_shapes(names: list[str] | None = None) -> list[BodyShape]:
    """The named shapes (all when None); unknown names raise ValueError listing the valid ones."""
    if names is None:
        return list(BODY_SHAPES)
    table = {s.name: s for s in BODY_SHAPES}
    missing = [n for n in names if n not in table]
    if missing:
        raise ValueError(f"unknown body shapes {missing} (valid: {', '.join(table)})")
    return [table[n] for n in names]

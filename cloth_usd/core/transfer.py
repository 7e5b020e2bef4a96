"""A garment made for one body, carried onto another body shape.

Each garment vertex keeps its offset from the nearest point of the source body's surface:
it moves with that surface point (barycentric on its triangle) when the body's shape
changes. The garment then sits on the new body as it sat on the old one, as loose or as
tight, which is what training a model for one garment over many bodies needs (and what a
tailor's grading does, roughly). The result is a starting shape, not a drape: the factory
still drapes it before it simulates. Shape letters: N garment vertices, V body vertices.
"""

from __future__ import annotations

import numpy as np

from .association import associate
from .body import BodyModel, shape_body

__all__ = ["transfer_garment"]


def transfer_garment(body: BodyModel, points: np.ndarray, betas_from: np.ndarray,
                     betas_to: np.ndarray) -> np.ndarray:
    """The garment ``points``, worn by the rest body of ``betas_from``, on the body of ``betas_to``.

    Args:
        body: the body model.
        points: (N, 3) float garment rest points [m], canonical body frame of ``betas_from``.
        betas_from: (B,) the shape the garment was made for.
        betas_to: (B',) the shape to carry it onto.
    Returns:
        (N, 3) float64 [m], canonical body frame of ``betas_to``. Equal to ``points`` when
        the two shapes are equal.
    """
    points = np.asarray(points, dtype=np.float64)
    v_from, _ = shape_body(body, np.asarray(betas_from, dtype=np.float64))
    v_to, _ = shape_body(body, np.asarray(betas_to, dtype=np.float64))
    a = associate(points, v_from, body.faces)
    corners = body.faces[a.triangle]  # (N, 3)
    moved = np.einsum("nk,nkd->nd", a.barycentric, (v_to - v_from)[corners])
    return points + moved

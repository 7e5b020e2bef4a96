"""docs/method.md's post-process: push garment vertices out of the body.

A garment vertex that penetrates the body, or sits closer than ``margin`` to it, is moved
out along the normal of its associated body vertex until it is ``margin`` in front of
that vertex's tangent plane: ``s = dot(p - b, n)``; if ``s < margin``: ``p += (margin - s) n``.
Shape letters: T frames, N garment vertices.
"""

from __future__ import annotations

import numpy as np

from ..errors import ArgumentError

__all__ = ["push_out", "DEFAULT_MARGIN"]

#: Default clearance from the body surface [m] (2 mm).
DEFAULT_MARGIN = 0.002


def push_out(points: np.ndarray, body_points: np.ndarray, body_normals: np.ndarray, *,
             margin: float = DEFAULT_MARGIN) -> tuple[np.ndarray, np.ndarray]:
    """Push penetrating (or too close) garment vertices out along the body normal.

    Args:
        points: (T, N, 3) garment points [m].
        body_points: (T, N, 3) each garment vertex's associated posed body vertex [m].
        body_normals: (T, N, 3) unit outward normals at those body vertices (a zero
            normal leaves its vertex unmoved).
        margin: clearance [m] to keep in front of the body's tangent plane.
    Returns:
        ``(points (T, N, 3) float64 [m], moved (T,) int64)``: the corrected points (a new
        array) and how many vertices moved in each frame.
    """
    p = np.asarray(points, dtype=np.float64)
    b = np.asarray(body_points, dtype=np.float64)
    n = np.asarray(body_normals, dtype=np.float64)
    if p.ndim != 3 or p.shape[-1] != 3 or b.shape != p.shape or n.shape != p.shape:
        raise ArgumentError(f"points, body_points and body_normals must all be (T, N, 3), got "
                            f"{p.shape}, {b.shape}, {n.shape}")
    if not margin >= 0:
        raise ArgumentError(f"margin must be >= 0 [m], got {margin}")
    s = np.einsum("tnc,tnc->tn", p - b, n)
    live = np.einsum("tnc,tnc->tn", n, n) > 0
    push = np.where(live & (s < margin), margin - s, 0.0)
    return p + push[..., None] * n, np.count_nonzero(push > 0, axis=1).astype(np.int64)

"""A point cache compressed to K morph targets and per-frame weights (PCA).

Frames are rows of a (T, 3N) matrix; its mean is the base mesh, the first K right
singular vectors scaled by their singular values and weight range are the morph
targets, and each frame's weights are its coordinates in that basis. The error that
matters to a game artist is the worst vertex of the worst frame, so K is chosen for a
maximum per-vertex error, measured after the float32 rounding the file stores.

Shape letters: T frames, N vertices, K morph targets.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..errors import ArgumentError

__all__ = ["MorphBasis", "fit_morph_basis", "vertex_errors"]


@dataclass(frozen=True)
class MorphBasis:
    """A point cache as ``points[t] = base + sum_k weights[t, k] * targets[k]``."""

    base: np.ndarray
    """(N, 3) float32 mean positions [m]."""
    targets: np.ndarray
    """(K, N, 3) float32 displacements [m] per unit weight."""
    weights: np.ndarray
    """(T, K) float32 per-frame weights, each column within [-1, 1]."""

    def reconstruct(self) -> np.ndarray:
        """(T, N, 3) float64 the positions the file plays back [m]."""
        base, targets = self.base.astype(np.float64), self.targets.astype(np.float64)
        return base + np.einsum("tk,knc->tnc", self.weights.astype(np.float64), targets)


def vertex_errors(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """(T, N) distance between two (T, N, 3) point sets [their unit]."""
    return np.linalg.norm(np.asarray(a, np.float64) - np.asarray(b, np.float64), axis=-1)


def _basis(points: np.ndarray, mean: np.ndarray, u: np.ndarray, s: np.ndarray, vt: np.ndarray,
           k: int) -> MorphBasis:
    t, n = points.shape[:2]
    coef = u[:, :k] * s[:k]  # (T, K)
    scale = np.abs(coef).max(axis=0) if k else np.zeros(0)
    scale = np.where(scale > 0, scale, 1.0)
    return MorphBasis(base=mean.reshape(n, 3).astype(np.float32),
                      targets=(vt[:k] * scale[:, None]).reshape(k, n, 3).astype(np.float32),
                      weights=(coef / scale).astype(np.float32))


def fit_morph_basis(points: np.ndarray, *, max_error: float | None = None, targets: int | None = None
                    ) -> MorphBasis:
    """Compress a point cache to morph targets.

    Args:
        points: (T, N, 3) positions [m].
        max_error: the largest per-vertex error allowed over all frames [m]; the
            smallest K that keeps it is chosen (at most T - 1, which is exact).
        targets: K itself; exactly one of ``max_error`` and ``targets`` is given.

    Raises:
        ArgumentError: both or neither given, ``targets`` < 0, or ``max_error`` <= 0.
    """
    if (max_error is None) == (targets is None):
        raise ArgumentError("give exactly one of --max-error and --targets")
    points = np.asarray(points, dtype=np.float64)
    t, n = points.shape[:2]
    flat = points.reshape(t, 3 * n)
    mean = flat.mean(axis=0)
    u, s, vt = np.linalg.svd(flat - mean, full_matrices=False)
    rank = int(np.sum(s > s[0] * 1e-9)) if s.size and s[0] > 0 else 0
    if targets is not None:
        if targets < 0:
            raise ArgumentError(f"--targets {targets}: must be 0 or more")
        return _basis(points, mean, u, s, vt, min(int(targets), s.size))
    if not (max_error > 0 and np.isfinite(max_error)):
        raise ArgumentError(f"--max-error {max_error * 1000:g} mm: must be a positive number of millimetres")

    def worst(k: int) -> float:
        return float(vertex_errors(_basis(points, mean, u, s, vt, k).reconstruct(), points).max())

    lo, hi = 0, rank  # worst(rank) is float32 rounding only
    if worst(hi) > max_error:
        return _basis(points, mean, u, s, vt, hi)
    while lo < hi:  # the error falls (almost always monotonically) with K: bisect
        mid = (lo + hi) // 2
        if worst(mid) <= max_error:
            hi = mid
        else:
            lo = mid + 1
    return _basis(points, mean, u, s, vt, lo)

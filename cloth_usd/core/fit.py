"""The fit attribute alpha: factor analysis over garment-body distances (docs/method.md).

For each garment-body pair, D holds the distance of N_g* garment vertices to their
associated unposed body vertices; factor analysis ``D - mu ~= L A`` gives each pair its
F = 3 factors. Garments differ in topology, so the N_g* samples are taken at fixed body
*anchor* vertices (evenly spread over the body region every garment covers): anchor k
takes the garment vertex whose associated body vertex lies nearest to it. That makes
column k of D mean the same place on the body for every pair (our choice; the paper
only says "evenly distributed"). Fitting uses scikit-learn; projecting a new pair
(``FitModel.transform``) is numpy only, so it ships with the models.
Shape letters: N garment vertices, V body vertices, G anchors (N_g*), P pairs, F factors.
"""

from __future__ import annotations

import zipfile
from dataclasses import dataclass
from pathlib import Path
from typing import Sequence

import numpy as np
from scipy.spatial import cKDTree

from .association import Association

__all__ = ["FIT_LIMIT", "FitModel", "pair_distances", "select_anchors", "common_anchors", "fit_factor_analysis"]

#: The largest ``|alpha|`` the learned tiers are given. The factors are standardised (a unit
#: normal prior): a garment-body pair past 3 on a factor is nothing the models saw (the
#: training pairs of the shipped T-shirt bundle lie within 1.6), and the detail model, read
#: that far out, tears the garment (a shirt sewn for a betas 3, 3 body, alpha -18 on the
#: third factor: the median frame's 99th-percentile stretch against skinning 1.79, 1.13 at
#: the limit). :func:`~cloth_usd.core.pipeline.prepare_pair` clamps alpha to it.
FIT_LIMIT = 3.0


@dataclass(frozen=True)
class FitModel:
    """A fitted factor-analysis model over anchor distances."""

    anchors: np.ndarray
    """(G,) int64 body vertex indices where distances are sampled."""
    mean: np.ndarray
    """(G,) float64 mean distance [m] (mu)."""
    loadings: np.ndarray
    """(G, F) float64 factor loadings (L)."""
    noise_variance: np.ndarray
    """(G,) float64 per-anchor noise variance [m^2] (Psi)."""

    def transform(self, distances: np.ndarray) -> np.ndarray:
        """Posterior mean of the factors (scikit-learn's ``FactorAnalysis.transform``).

        Args:
            distances: (G,) or (P, G) anchor distances [m].
        Returns:
            (F,) or (P, F) fit attributes alpha.
        """
        w = self.loadings.T  # (F, G)
        w_psi = w / self.noise_variance
        cov_z = np.linalg.inv(np.eye(w.shape[0]) + w_psi @ w.T)
        return ((np.asarray(distances) - self.mean) @ w_psi.T) @ cov_z

    def save(self, path: str | Path) -> None:
        np.savez(path, anchors=self.anchors, mean=self.mean, loadings=self.loadings,
                 noise_variance=self.noise_variance)

    @classmethod
    def load(cls, path: str | Path) -> "FitModel":
        """Read a :meth:`save` file.

        Raises:
            ValueError: the file is not an ``.npz`` archive, lacks a key, or holds arrays
                of the wrong shape, type or value (the message says which).
            OSError: it cannot be read.
        """
        try:
            data = np.load(path, allow_pickle=False)
        except (zipfile.BadZipFile, EOFError) as exc:
            raise ValueError(f"not a readable .npz archive ({exc or type(exc).__name__})") from exc
        if not isinstance(data, np.lib.npyio.NpzFile):
            raise ValueError("a single .npy array, not an .npz archive of anchors, mean, loadings, "
                             "noise_variance")
        with data:
            missing = [k for k in _FIT_KEYS if k not in data.files]
            if missing:
                raise ValueError(f"missing key '{missing[0]}' (has {', '.join(data.files) or 'no arrays'})")
            try:
                arrays = {k: data[k] for k in _FIT_KEYS}
            except (zipfile.BadZipFile, EOFError, OSError) as exc:
                raise ValueError(f"a truncated or corrupt .npz archive ({exc or type(exc).__name__})") from exc
        _check_fit_arrays(arrays)
        return cls(**arrays)


_FIT_KEYS = ("anchors", "mean", "loadings", "noise_variance")


def _check_fit_arrays(a: dict[str, np.ndarray]) -> None:
    """ValueError naming the first array of a fit model whose shape, type or values are wrong."""
    anchors = a["anchors"]
    if anchors.ndim != 1 or anchors.size == 0 or anchors.dtype.kind not in "iu":
        raise ValueError(f"'anchors' must be a non-empty (G,) integer array, got {anchors.dtype} "
                         f"{anchors.shape}")
    g = anchors.shape[0]
    if anchors.min() < 0:
        raise ValueError(f"'anchors' holds a negative vertex index ({int(anchors.min())})")
    want = {"mean": (g,), "noise_variance": (g,)}
    for key in ("mean", "loadings", "noise_variance"):
        arr = a[key]
        if arr.dtype.kind not in "fiu":
            raise ValueError(f"'{key}' must be numbers, got {arr.dtype}")
        shape_ok = arr.shape == want[key] if key in want else (arr.ndim == 2 and arr.shape[0] == g
                                                                and arr.shape[1] >= 1)
        if not shape_ok:
            expected = want[key] if key in want else f"({g}, F)"
            raise ValueError(f"'{key}' has shape {arr.shape}, expected {expected} for {g} anchors")
        if not np.isfinite(arr).all():
            raise ValueError(f"'{key}' holds NaN or infinite values")
    if (a["noise_variance"] <= 0).any():
        raise ValueError("'noise_variance' must be positive")


def select_anchors(body_vertices: np.ndarray, covered: np.ndarray, count: int) -> np.ndarray:
    """Evenly spread anchors: farthest-point sampling over the covered body vertices.

    Args:
        body_vertices: (V, 3) unposed body [m] (the mean shape).
        covered: (V,) bool, body vertices every garment covers.
        count: number of anchors G (N_g*), at most ``covered.sum()``.
    Returns:
        (G,) int64 body vertex indices, deterministic.
    """
    candidates = np.flatnonzero(covered)
    count = min(count, candidates.size)
    pts = body_vertices[candidates]
    chosen = np.empty(count, dtype=np.int64)
    chosen[0] = int(np.argmin(pts[:, 1]))  # start at the lowest point: deterministic
    dist = np.linalg.norm(pts - pts[chosen[0]], axis=1)
    for i in range(1, count):
        chosen[i] = int(np.argmax(dist))
        dist = np.minimum(dist, np.linalg.norm(pts - pts[chosen[i]], axis=1))
    return candidates[chosen]


def common_anchors(pairs: Sequence[tuple[Association, np.ndarray]], mean_body: np.ndarray, count: int,
                   *, reach: float = 0.02) -> np.ndarray:
    """Anchors over the body region that every pair's garment covers.

    A body vertex is covered by a pair when one of the garment's associated body
    vertices lies within ``reach`` of it.

    Args:
        pairs: per garment-body pair, its association and its (V, 3) unposed body [m].
        mean_body: (V, 3) the mean-shape body [m], where anchors are spread.
        count: anchors wanted (N_g*: the smallest garment vertex count).
    Returns:
        (G,) int64 body vertex indices.
    """
    covered = np.ones(mean_body.shape[0], bool)
    for association, body_vertices in pairs:
        covered &= cKDTree(body_vertices[association.vertex]).query(body_vertices)[0] < reach
    return select_anchors(mean_body, covered, count)


def pair_distances(garment_points: np.ndarray, association: Association, body_vertices: np.ndarray,
                   anchors: np.ndarray) -> np.ndarray:
    """D's column for one pair: at each anchor, the garment-to-body distance there.

    Args:
        garment_points: (N, 3) rest garment [m], canonical body frame.
        association: the pair's association (``vertex`` is docs/method.md's ``I``).
        body_vertices: (V, 3) the pair's unposed body [m].
        anchors: (G,) body vertex indices.
    Returns:
        (G,) float64 distances [m] ``|garment_i - body_I(i)|`` of the garment vertex i whose
        associated body vertex is nearest to each anchor.
    """
    associated = body_vertices[association.vertex]  # (N, 3)
    _, pick = cKDTree(associated).query(body_vertices[anchors])
    return np.linalg.norm(garment_points[pick] - associated[pick], axis=1)


def fit_factor_analysis(distances: np.ndarray, anchors: np.ndarray, *, factors: int = 3,
                        seed: int = 0) -> tuple[FitModel, np.ndarray]:
    """Fit ``D - mu ~= L A`` with scikit-learn's SVD-based FactorAnalysis.

    Factor signs are fixed so each factor's loadings sum positive (a1 grows with
    looseness). Args:
        distances: (P, G) one row per garment-body pair [m].
    Returns:
        ``(model, alpha (P, F))``.
    """
    from sklearn.decomposition import FactorAnalysis

    fa = FactorAnalysis(n_components=factors, svd_method="lapack", random_state=seed)
    fa.fit(distances)
    loadings = fa.components_.T.copy()  # (G, F)
    loadings *= np.where(loadings.sum(axis=0) < 0, -1.0, 1.0)
    model = FitModel(anchors=np.asarray(anchors, dtype=np.int64), mean=fa.mean_.copy(),
                     loadings=loadings, noise_variance=fa.noise_variance_.copy())
    return model, model.transform(distances)

"""The morph basis: exact at full rank, the fewest targets for a maximum error."""

from __future__ import annotations

import numpy as np
import pytest

from cloth_usd.errors import ArgumentError
from cloth_usd.export.pca import fit_morph_basis, vertex_errors

from tests.export.helpers import grid_animation


def _modes(t: int = 30, n: int = 50, k: int = 3, seed: int = 1) -> np.ndarray:
    """(T, N, 3) points that are a mean plus exactly k modes."""
    rng = np.random.default_rng(seed)
    mean = rng.normal(size=(n, 3))
    modes = rng.normal(size=(k, n, 3)) * np.array([0.1, 0.01, 0.001])[:k, None, None]
    return mean + np.einsum("tk,knc->tnc", rng.normal(size=(t, k)), modes)


def test_k_modes_need_k_targets():
    points = _modes()
    basis = fit_morph_basis(points, max_error=1e-5)
    assert basis.targets.shape[0] == 3
    assert vertex_errors(basis.reconstruct(), points).max() < 1e-5


def test_fewest_targets_within_the_error():
    points = grid_animation(t=40).points
    for mm in (5.0, 1.0, 0.2):
        basis = fit_morph_basis(points, max_error=mm / 1000)
        k = basis.targets.shape[0]
        assert vertex_errors(basis.reconstruct(), points).max() <= mm / 1000
        if k:
            fewer = fit_morph_basis(points, targets=k - 1)
            assert vertex_errors(fewer.reconstruct(), points).max() > mm / 1000


def test_weights_within_one_and_base_is_the_mean():
    points = grid_animation().points
    basis = fit_morph_basis(points, targets=4)
    assert np.abs(basis.weights).max() == pytest.approx(1.0, abs=1e-6)
    np.testing.assert_allclose(basis.base, points.mean(axis=0), atol=1e-6)
    assert basis.base.dtype == basis.targets.dtype == basis.weights.dtype == np.float32


def test_targets_beyond_the_frames_are_clamped():
    points = grid_animation(t=5).points
    basis = fit_morph_basis(points, targets=64)
    assert basis.targets.shape[0] == 5
    assert vertex_errors(basis.reconstruct(), points).max() < 1e-5


@pytest.mark.parametrize("kwargs", [{}, {"max_error": 1e-3, "targets": 3}, {"targets": -1}, {"max_error": 0.0}])
def test_bad_arguments(kwargs):
    with pytest.raises(ArgumentError):
        fit_morph_basis(grid_animation(t=4).points, **kwargs)

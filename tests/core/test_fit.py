import numpy as np
import pytest

from cloth_usd.core.association import associate
from cloth_usd.core.fit import FitModel, fit_factor_analysis, pair_distances, select_anchors


def _synthetic(p=24, g=40, seed=0):
    rng = np.random.default_rng(seed)
    looseness = rng.uniform(0.005, 0.05, size=p)
    pattern = rng.uniform(0.5, 1.5, size=g)
    d = looseness[:, None] * pattern[None] + rng.normal(0, 1e-3, size=(p, g))
    return d, looseness


def test_numpy_transform_equals_scikit_learn():
    sklearn = pytest.importorskip("sklearn.decomposition")
    d, _ = _synthetic()
    model, alpha = fit_factor_analysis(d, np.arange(d.shape[1]))
    fa = sklearn.FactorAnalysis(n_components=3, svd_method="lapack", random_state=0).fit(d)
    signs = np.where(fa.components_.sum(axis=1) < 0, -1.0, 1.0)
    np.testing.assert_allclose(alpha, fa.transform(d) * signs, atol=1e-8)
    np.testing.assert_allclose(model.transform(d[3]), alpha[3], atol=1e-12)


def test_first_factor_grows_with_looseness(tmp_path):
    pytest.importorskip("sklearn")
    d, looseness = _synthetic()
    model, alpha = fit_factor_analysis(d, np.arange(d.shape[1]))
    assert np.corrcoef(alpha[:, 0], looseness)[0, 1] > 0.99
    model.save(tmp_path / "fit.npz")
    again = FitModel.load(tmp_path / "fit.npz")
    np.testing.assert_allclose(again.transform(d), alpha)


def test_anchors_are_spread_and_distances_follow_the_offset():
    rng = np.random.default_rng(1)
    body = rng.normal(size=(300, 3))
    body /= np.linalg.norm(body, axis=1, keepdims=True)
    from scipy.spatial import ConvexHull

    faces = ConvexHull(body).simplices
    covered = body[:, 1] > -0.2
    anchors = select_anchors(body, covered, 50)
    assert np.unique(anchors).size == 50 and covered[anchors].all()
    # A garment at 1.03x the body radius: every anchor distance is about 0.03.
    garment = body[covered] * 1.03
    assoc = associate(garment, body, faces)
    d = pair_distances(garment, assoc, body, anchors)
    np.testing.assert_allclose(d, 0.03, atol=0.01)

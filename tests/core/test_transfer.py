"""A garment carried from the body it was made for onto another shape keeps its offsets."""

from __future__ import annotations

import numpy as np

from cloth_usd.core.association import associate
from cloth_usd.core.body import load_body_model, shape_body
from cloth_usd.core.transfer import transfer_garment


def _shell(body, betas, offset):
    """Points ``offset`` [m] out along the normals of a few hundred body vertices."""
    from cloth_usd.core.features import vertex_normals

    v, _ = shape_body(body, betas)
    n = vertex_normals(v, body.faces)
    pick = np.arange(0, v.shape[0], 23)
    return v[pick] + offset * n[pick]


def test_the_same_shape_leaves_the_garment_where_it_is():
    body = load_body_model()
    betas = np.zeros(10)
    points = _shell(body, betas, 0.01)
    np.testing.assert_allclose(transfer_garment(body, points, betas, betas), points, atol=1e-12)


def test_the_garment_keeps_its_distance_from_a_fatter_and_a_taller_body():
    body = load_body_model()
    src, fat, tall = np.zeros(10), np.r_[0.0, 2.0, np.zeros(8)], np.r_[2.0, np.zeros(9)]
    points = _shell(body, src, 0.01)
    d_src = associate(points, shape_body(body, src)[0], body.faces).distance
    for dst in (fat, tall):
        moved = transfer_garment(body, points, src, dst)
        v_dst = shape_body(body, dst)[0]
        d_dst = associate(moved, v_dst, body.faces).distance
        # offsets of 1 cm stay about 1 cm (the surface turns a little under the new shape)
        assert np.median(np.abs(d_dst - d_src)) < 1.5e-3, np.median(np.abs(d_dst - d_src))
        # and the garment really moved with the body: the untransferred points are off by more
        d_stay = associate(points, v_dst, body.faces).distance
        assert np.median(np.abs(d_stay - d_src)) > 3 * np.median(np.abs(d_dst - d_src))

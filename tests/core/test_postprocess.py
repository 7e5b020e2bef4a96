"""The penetration post-process moves exactly the penetrating vertices, by the right amount."""

from __future__ import annotations

import numpy as np
import pytest

from cloth_usd.core.postprocess import push_out
from cloth_usd.errors import ArgumentError


def test_pushes_exactly_the_penetrating_vertices():
    # Body plane z = 0 with normal +z at every associated vertex; garment heights per frame.
    heights = np.array([[0.010, 0.002, 0.001, -0.005, 0.0],
                        [0.003, 0.0025, 0.020, 0.030, -0.1]])
    pts = np.zeros((2, 5, 3))
    pts[..., 0] = np.arange(5)
    pts[..., 2] = heights
    body = pts.copy()
    body[..., 2] = 0.0
    normals = np.broadcast_to([0.0, 0.0, 1.0], pts.shape)
    out, moved = push_out(pts, body, normals, margin=0.002)
    assert moved.tolist() == [3, 1]  # 0.001, -0.005, 0.0 ; then -0.1 (0.002 itself is not moved)
    want = np.maximum(heights, 0.002)
    np.testing.assert_allclose(out[..., 2], want, atol=1e-15)
    np.testing.assert_array_equal(out[..., :2], pts[..., :2])  # along the normal only
    assert out is not pts and pts[0, 3, 2] == -0.005  # the input is left alone


def test_tilted_normal_and_zero_normal():
    n = np.array([0.0, 0.6, 0.8])
    body = np.array([[[1.0, 1.0, 1.0], [0, 0, 0]]])
    pts = body - 0.01 * n  # 1 cm inside
    normals = np.stack([[n, [0.0, 0.0, 0.0]]])
    out, moved = push_out(pts, body, normals, margin=0.003)
    np.testing.assert_allclose(out[0, 0], body[0, 0] + 0.003 * n, atol=1e-15)
    np.testing.assert_array_equal(out[0, 1], pts[0, 1])  # no normal, no push
    assert moved.tolist() == [1]
    with pytest.raises(ArgumentError):
        push_out(pts[0], body[0], normals[0])
    with pytest.raises(ArgumentError, match="margin"):
        push_out(pts, body, normals, margin=-1.0)

"""Node features on tiny hand-built meshes."""

from __future__ import annotations

import numpy as np
import pytest

from cloth_usd.core.features import (CONTACT_REACH, attributes, coarse_features, contact_features, detail_features,
                                     vertex_normals)
from cloth_usd.errors import ArgumentError

# A flat unit square in the z = 0 plane, two counter-clockwise triangles (seen from +z),
# plus a zero-area triangle and an isolated vertex.
SQUARE = np.array([[0, 0, 0], [1, 0, 0], [1, 1, 0], [0, 1, 0], [2, 2, 2], [5, 5, 5]], dtype=float)
FACES = np.array([[0, 1, 2], [0, 2, 3], [4, 4, 4]])


def test_normals_of_a_flat_square_and_degenerate_parts():
    n = vertex_normals(SQUARE, FACES)
    np.testing.assert_allclose(n[:4], np.tile([0, 0, 1.0], (4, 1)), atol=1e-12)
    assert (n[4:] == 0).all() and np.isfinite(n).all()  # zero-area face, isolated vertex: 0, not NaN


def test_normals_are_area_weighted_and_batched():
    # A hinge: a big triangle facing +z and a small one facing +x share the edge 0-1.
    pts = np.array([[0, 0, 0], [0, 1, 0], [-3, 0, 0], [0, 0, 0.5]], dtype=float)
    faces = np.array([[0, 1, 2], [0, 1, 3]])  # areas 1.5 (normal +z) and 0.25 (normal +x)
    want = np.array([0.25, 0, 1.5]) / np.hypot(0.25, 1.5)
    frames = np.stack([pts, pts + 7.0])
    n = vertex_normals(frames, faces)
    assert n.shape == (2, 4, 3)
    np.testing.assert_allclose(n[:, 0], [want, want], atol=1e-12)
    np.testing.assert_allclose(n[1], vertex_normals(pts, faces), atol=1e-12)
    with pytest.raises(ArgumentError):
        vertex_normals(pts[:, :2], faces)


def test_coarse_features():
    body = np.stack([SQUARE, SQUARE + [0, 0, 1]])  # (T=2, V=6, 3)
    normals = vertex_normals(body, FACES)
    transl = np.array([[0, 0, 0], [0, 0, 1.0]])
    f = coarse_features(body, normals, np.array([2, 2, 0]), transl, 0.7)
    assert f.shape == (2, 3, 7)
    np.testing.assert_allclose(f[:, :, :3], [[[0, 0, 1]] * 3] * 2)
    np.testing.assert_allclose(f[0, 0, 3:6], [1, 1, 0])
    np.testing.assert_allclose(f[1, 0, 3:6], [1, 1, 0])  # the translation is removed
    assert (f[..., 6] == 0.7).all()


def test_contact_features_read_the_signed_distance_to_the_nearest_body_vertex_plane():
    """A body of two vertices facing +z and +x; points in front of, behind, far from them."""
    body = np.array([[[0, 0, 0], [1, 0, 0]]], dtype=float)
    normals = np.array([[[0, 0, 1], [1, 0, 0]]], dtype=float)
    pts = np.array([[[0, 0, 0.01],        # 1 cm in front of vertex 0
                     [0.02, 0, -0.015],   # behind vertex 0's plane: inside
                     [1.0, 0.003, -0.2],  # nearest vertex 1 lies 0.2 m off: out of reach
                     [1.03, 0.0, 0.0],    # in front of vertex 1's plane, along +x
                     [np.nan, 0, 0]]])    # not finite: read as far
    f = contact_features(pts, body, normals)
    assert f.shape == (1, 5, 4)
    np.testing.assert_allclose(f[0, 0], [0, 0, 1, 0.01], atol=1e-12)
    np.testing.assert_allclose(f[0, 1], [0, 0, 1, -0.015], atol=1e-12)
    np.testing.assert_allclose(f[0, 2], [0, 0, 0, CONTACT_REACH])
    np.testing.assert_allclose(f[0, 3], [1, 0, 0, 0.03], atol=1e-12)
    np.testing.assert_allclose(f[0, 4], [0, 0, 0, CONTACT_REACH])
    deep = contact_features(np.array([[[0, 0, -0.049], [0, 0, -0.051]]]), body, normals)
    np.testing.assert_allclose(deep[0, :, 3], [-0.049, CONTACT_REACH], atol=1e-12)  # deeper than the reach: far
    from scipy.spatial import cKDTree

    np.testing.assert_array_equal(contact_features(pts, body, normals, trees=[cKDTree(body[0])]), f)
    with pytest.raises(ArgumentError, match="T trees"):
        contact_features(pts, body, normals, trees=[])


def test_detail_features_joint_distances():
    garment = np.stack([SQUARE[:4], SQUARE[:4] + [0, 0, 2]])  # (2, 4, 3)
    faces = FACES[:2]
    joints = np.zeros((2, 24, 3))
    joints[:, 1] = [3, 4, 0]
    joints[1] += [0, 0, 2]  # joints move with the garment: distances do not change
    transl = np.array([[0, 0, 0], [0, 0, 2.0]])
    f = detail_features(garment, faces, joints, transl)
    assert f.shape == (2, 4, 30)
    np.testing.assert_allclose(f[:, :, :3], np.broadcast_to([0, 0, 1.0], (2, 4, 3)))
    np.testing.assert_allclose(f[1, :, 3:6], SQUARE[:4])
    np.testing.assert_allclose(f[:, 0, 6], 0.0)           # vertex 0 sits on joint 0
    np.testing.assert_allclose(f[:, 0, 7], 5.0)           # |(0,0,0) - (3,4,0)|
    np.testing.assert_allclose(f[:, 2, 7], np.hypot(2, 3))
    np.testing.assert_allclose(f[0, 2, 6:], f[1, 2, 6:])
    with pytest.raises(ArgumentError, match="posed_joints"):
        detail_features(garment, faces, joints[:, :10], transl)


def test_attributes():
    poses = np.arange(3 * 72, dtype=float).reshape(3, 72)
    a = attributes(np.array([1.0, 2, 3]), np.array([0.5, -0.5]), poses)
    assert a.shape == (3, 85)
    np.testing.assert_array_equal(a[:, :3], [[1, 2, 3]] * 3)
    np.testing.assert_array_equal(a[0, 3:13], [0.5, -0.5] + [0] * 8)
    np.testing.assert_array_equal(a[:, 13:], poses)
    with pytest.raises(ArgumentError, match="alpha"):
        attributes(np.zeros(2), np.zeros(10), poses)


@pytest.mark.parametrize("dtype", [np.float32, np.float64])
@pytest.mark.parametrize("shape", [(7, 3), (2, 5, 3), (3, 4, 24, 3), (0, 3)])
def test_vector_lengths_are_numpys_norms(dtype, shape):
    """The lengths the post-process, the features and the guard take, component by component:
    numpy's norm over the last axis, in the input's dtype (a zero vector has length 0)."""
    from cloth_usd.core.mesh import vector_lengths

    v = np.random.default_rng(4).normal(0, 0.3, shape).astype(dtype)
    if v.size:
        v.reshape(-1, 3)[0] = 0.0
    out = vector_lengths(v)
    assert out.shape == shape[:-1] and out.dtype == dtype
    np.testing.assert_allclose(out, np.linalg.norm(v, axis=-1), rtol=2e-7 if dtype == np.float64 else 2e-6)
    if v.size:
        assert out.reshape(-1)[0] == 0.0


@pytest.mark.parametrize("dtype", [np.float32, np.float64])
@pytest.mark.parametrize("shapes", [((7, 3), (7, 3)), ((2, 5, 3), (5, 3)), ((4, 1, 3), (1, 6, 3)), ((0, 3), (0, 3))])
def test_cross_is_numpys_cross(dtype, shapes):
    """The cross products the normals and the closest points take, component by component: numpy's,
    broadcast as numpy broadcasts, in the inputs' dtype."""
    from cloth_usd.core.mesh import cross

    rng = np.random.default_rng(5)
    a, b = (rng.normal(0, 0.3, s).astype(dtype) for s in shapes)
    out = cross(a, b)
    assert out.dtype == dtype
    np.testing.assert_array_equal(out, np.cross(a, b))

import numpy as np
from scipy.spatial import ConvexHull

from cloth_usd.core.association import associate, closest_point_on_triangles


def _sphere(n=200, seed=0):
    rng = np.random.default_rng(seed)
    p = rng.normal(size=(n, 3))
    p /= np.linalg.norm(p, axis=1, keepdims=True)
    return p, ConvexHull(p).simplices


def _brute_force(points, verts, faces):
    tri = verts[faces]
    best = []
    for p in points:
        c, _ = closest_point_on_triangles(tri, np.repeat(p[None], len(faces), 0))
        best.append(np.linalg.norm(c - p, axis=1).min())
    return np.array(best)


def test_regions_of_one_triangle():
    tri = np.array([[[0, 0, 0], [1, 0, 0], [0, 1, 0]]], dtype=float)
    cases = {  # point -> expected closest point
        (0.2, 0.2, 1.0): (0.2, 0.2, 0.0),  # face
        (-1.0, -1.0, 0.0): (0.0, 0.0, 0.0),  # vertex a
        (2.0, -0.5, 0.0): (1.0, 0.0, 0.0),  # vertex b
        (0.5, -1.0, 0.3): (0.5, 0.0, 0.0),  # edge ab
        (1.0, 1.0, 0.0): (0.5, 0.5, 0.0),  # edge bc
        (-0.5, 0.5, 0.0): (0.0, 0.5, 0.0),  # edge ac
    }
    for p, expect in cases.items():
        c, bary = closest_point_on_triangles(tri, np.array([p], dtype=float))
        np.testing.assert_allclose(c[0], expect, atol=1e-12)
        np.testing.assert_allclose(bary.sum(), 1.0)
        assert np.all(bary >= -1e-12)


def test_degenerate_triangle_gives_finite_answer():
    tri = np.zeros((1, 3, 3))
    c, bary = closest_point_on_triangles(tri, np.ones((1, 3)))
    assert np.all(np.isfinite(c)) and np.all(np.isfinite(bary))


def test_matches_brute_force_on_a_sphere():
    verts, faces = _sphere()
    rng = np.random.default_rng(1)
    points = rng.normal(size=(300, 3)) * rng.uniform(0.5, 1.5, size=(300, 1))
    assoc = associate(points, verts, faces)
    np.testing.assert_allclose(assoc.distance, _brute_force(points, verts, faces), atol=1e-9)
    surface = np.einsum("nk,nkc->nc", assoc.barycentric, verts[faces[assoc.triangle]])
    np.testing.assert_allclose(np.linalg.norm(surface - points, axis=1), assoc.distance, atol=1e-12)
    nearest = np.argmin(np.linalg.norm(points[:, None] - verts[None], axis=2), axis=1)
    np.testing.assert_array_equal(assoc.vertex, nearest)


def test_chunking_does_not_change_the_answer():
    verts, faces = _sphere()
    points = np.random.default_rng(2).normal(size=(100, 3))
    a, b = associate(points, verts, faces), associate(points, verts, faces, chunk=7)
    np.testing.assert_array_equal(a.triangle, b.triangle)
    np.testing.assert_allclose(a.barycentric, b.barycentric)

"""Property-based tests of the numpy core (issue #6): rotations, closest points,
association and skinning. Bounded (small ``max_examples``, no deadline) so the file
runs in a few seconds."""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import HealthCheck, assume, given, settings
from hypothesis import strategies as st
from hypothesis.extra.numpy import arrays
from scipy.spatial import ConvexHull

from cloth_usd.core.association import associate, closest_point_on_triangles
from cloth_usd.core.body import body_model_from_arrays, posed_vertices
from cloth_usd.core.rotations import axis_angle_to_matrix, matrix_to_axis_angle
from cloth_usd.core.skinning import bind_garment, skin_garment
from tests.conftest import tiny_body_arrays

FAST = settings(max_examples=40, deadline=None, suppress_health_check=[HealthCheck.too_slow])
SLOW = settings(max_examples=15, deadline=None, suppress_health_check=[HealthCheck.too_slow])

finite = st.floats(-10.0, 10.0, allow_nan=False, allow_infinity=False)
vec3 = arrays(np.float64, 3, elements=finite)


@st.composite
def unit_axes(draw) -> np.ndarray:
    v = draw(vec3)
    assume(np.linalg.norm(v) > 1e-3)
    return v / np.linalg.norm(v)


#: Angles [rad] in (0, pi), weighted towards both ends where the formulas switch.
angles = st.one_of(
    st.floats(0.0, np.pi),
    st.floats(0.0, 1e-6),
    st.floats(np.pi - 1e-6, np.pi),
    st.sampled_from([0.0, 1e-300, 1e-12, np.pi / 2, np.pi - 1e-12, np.pi]),
)


# ----------------------------------------------------------------------- rotations


def _assert_rotation(r: np.ndarray) -> None:
    np.testing.assert_allclose(r @ np.swapaxes(r, -1, -2), np.broadcast_to(np.eye(3), r.shape), atol=1e-12)
    np.testing.assert_allclose(np.linalg.det(r), 1.0, atol=1e-12)


@FAST
@given(axis=unit_axes(), angle=angles)
def test_axis_angle_round_trip(axis, angle):
    aa = axis * angle
    r = axis_angle_to_matrix(aa)
    _assert_rotation(r)
    back = matrix_to_axis_angle(r)
    assert np.all(np.isfinite(back))
    assert np.linalg.norm(back) <= np.pi + 1e-12
    np.testing.assert_allclose(axis_angle_to_matrix(back), r, atol=1e-12)
    if angle < np.pi - 1e-6:
        np.testing.assert_allclose(back, aa, atol=1e-9)
    else:  # at pi, aa and -aa are the same rotation
        assert min(np.abs(back - aa).max(), np.abs(back + aa).max()) < 1e-5


@FAST
@given(aa=arrays(np.float64, (5, 3), elements=st.floats(-4 * np.pi, 4 * np.pi)))
def test_any_axis_angle_gives_a_rotation_that_round_trips(aa):
    r = axis_angle_to_matrix(aa)
    _assert_rotation(r)
    np.testing.assert_allclose(axis_angle_to_matrix(matrix_to_axis_angle(r)), r, atol=1e-10)


@FAST
@given(axis=unit_axes(), angle=angles, noise=arrays(np.float64, (3, 3), elements=st.floats(-1e-7, 1e-7)))
def test_matrix_to_axis_angle_tolerates_float32_round_off(axis, angle, noise):
    r = axis_angle_to_matrix(axis * angle)
    back = matrix_to_axis_angle(r + noise)
    assert np.all(np.isfinite(back))
    np.testing.assert_allclose(axis_angle_to_matrix(back), r, atol=1e-5)


# ------------------------------------------------------------------ closest point


@st.composite
def triangles(draw) -> np.ndarray:
    """(3, 3) corners: random, or degenerate (a repeated corner, a single point, tiny).

    Collinear corners are left out: closest_point_on_triangles sometimes misses the
    nearest point of a collinear triangle (a known bug, pinned by
    test_closest_point_on_a_collinear_triangle)."""
    a, b, c = draw(vec3), draw(vec3), draw(vec3)
    kind = draw(st.sampled_from(["random", "a=b", "a=c", "point", "tiny"]))
    if kind == "a=b":
        b = a.copy()
    elif kind == "a=c":
        c = a.copy()
    elif kind == "point":
        b, c = a.copy(), a.copy()
    elif kind == "tiny":
        b, c = a + 1e-9 * (b - a), a + 1e-9 * (c - a)
    # Known bug, pinned by test_closest_point_with_coincident_corners: b == c exactly, or
    # two corners closer than 1e-6 of the triangle's size without being equal. Exact
    # a == b, a == c and a triangle shrunk to a point are still drawn.
    gaps = [np.abs(b - a).max(), np.abs(c - a).max(), np.abs(c - b).max()]  # no underflow
    assume(not (gaps[2] == 0.0 and gaps[0] > 0.0))
    assume(not any(0.0 < g <= 1e-6 * max(gaps) for g in gaps))
    return np.stack([a, b, c])


@FAST
@given(tri=triangles(), p=vec3)
def test_closest_point_is_on_the_triangle_and_no_farther_than_a_corner(tri, p):
    closest, bary = closest_point_on_triangles(tri[None], p[None])
    closest, bary = closest[0], bary[0]
    assert np.all(np.isfinite(closest)) and np.all(np.isfinite(bary))
    assert np.all(bary >= -1e-12) and abs(bary.sum() - 1.0) < 1e-9
    np.testing.assert_allclose(closest, bary @ tri, atol=1e-9)
    scale = 1.0 + np.abs(tri).max() + np.abs(p).max()
    assert np.linalg.norm(p - closest) <= np.linalg.norm(p - tri, axis=1).min() + 1e-9 * scale


@pytest.mark.parametrize("tri, p", [
    ([[1.0, 1.0, 1.0], [2.0, 0.0, 0.0], [2.0, 0.0, 0.0]], [0.0, 0.0, 0.0]),
    ([[10.0, 0.0, 0.0], [9.0, 9.0, 9.0], [9.0, 9.0, 9.0]], [0.0, 0.0, 0.0]),
    ([[0.0, -1.0, -1.0], [2.5e-104, 2.5e-104, 2.5e-104], [2.5e-104, 0.0, 0.0]], [0.0, 0.0, 0.0]),
    ([[0.0, -1.0, -1.0], [2.5e-104, 2.5e-104, 2.5e-104], [6.2e-208, -1.0, -1.0]], [0.0, 0.0, 0.0]),
])
def test_closest_point_with_coincident_corners(tri, p):
    tri, p = np.array([tri]), np.array([p])
    closest, bary = closest_point_on_triangles(tri, p)
    assert abs(bary.sum() - 1.0) < 1e-9
    np.testing.assert_allclose(closest[0], _segment_closest(p[0], tri[0, 0], tri[0, 1]), atol=1e-9)


def test_closest_point_on_a_collinear_triangle():
    a = np.array([0.38158564846933424, 0.59192741329513521, -1.1314300735098157])
    b = np.array([1.5456242253277213, 2.2573830336046146, -0.0020076780592068614])
    tri = np.stack([a, b, a + 0.5 * (b - a)])
    p = np.array([0.02282959432882544, 1.3082105198227851, -0.06869569083463695])
    closest, _ = closest_point_on_triangles(tri[None], p[None])
    np.testing.assert_allclose(closest[0], _segment_closest(p, a, b), atol=1e-9)


def _segment_closest(p: np.ndarray, a: np.ndarray, b: np.ndarray) -> np.ndarray:
    ab = b - a
    t = 0.0 if not ab @ ab else np.clip((p - a) @ ab / (ab @ ab), 0.0, 1.0)
    return a + t * ab


def _segment_distance(p: np.ndarray, a: np.ndarray, b: np.ndarray) -> float:
    return float(np.linalg.norm(p - _segment_closest(p, a, b)))


@FAST
@given(tri=triangles(), p=vec3)
def test_closest_point_is_no_farther_than_any_edge(tri, p):
    closest, _ = closest_point_on_triangles(tri[None], p[None])
    best_edge = min(_segment_distance(p, tri[i], tri[(i + 1) % 3]) for i in range(3))
    scale = 1.0 + np.abs(tri).max() + np.abs(p).max()
    assert np.linalg.norm(p - closest[0]) <= best_edge + 1e-9 * scale


# -------------------------------------------------------------------- association


@st.composite
def small_meshes(draw) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """A closed convex mesh of 4-30 vertices around the origin and 1-20 query points."""
    seed = draw(st.integers(0, 2**32 - 1))
    rng = np.random.default_rng(seed)
    num_v = draw(st.integers(4, 30))
    v = rng.normal(size=(num_v, 3))
    v /= np.linalg.norm(v, axis=1, keepdims=True)
    v *= rng.uniform(0.5, 1.5, size=(num_v, 1))
    hull = ConvexHull(v)
    used = np.unique(hull.simplices)
    remap = np.full(num_v, -1)
    remap[used] = np.arange(used.size)
    points = rng.normal(0.0, 1.0, size=(draw(st.integers(1, 20)), 3))
    return v[used], remap[hull.simplices], points


def _brute_force(points, verts, faces):
    num_p, num_f = points.shape[0], faces.shape[0]
    tri = np.repeat(verts[faces][None], num_p, axis=0).reshape(-1, 3, 3)
    closest, _ = closest_point_on_triangles(tri, np.repeat(points, num_f, axis=0))
    dist = np.linalg.norm(closest.reshape(num_p, num_f, 3) - points[:, None], axis=2)
    nearest_vertex = np.linalg.norm(points[:, None] - verts[None], axis=2).argmin(axis=1)
    return dist.min(axis=1), nearest_vertex


@SLOW
@given(mesh=small_meshes())
def test_associate_matches_brute_force_when_every_vertex_is_a_candidate(mesh):
    verts, faces, points = mesh
    assoc = associate(points, verts, faces, candidates=verts.shape[0], chunk=7)
    dist, nearest = _brute_force(points, verts, faces)
    np.testing.assert_allclose(assoc.distance, dist, atol=1e-12)
    np.testing.assert_array_equal(assoc.vertex, nearest)
    surface = np.einsum("nk,nkc->nc", assoc.barycentric, verts[faces[assoc.triangle]])
    np.testing.assert_allclose(np.linalg.norm(surface - points, axis=1), assoc.distance, atol=1e-12)
    assert np.all(assoc.barycentric >= -1e-12)


@SLOW
@given(mesh=small_meshes().filter(lambda m: m[0].shape[0] <= 8))
def test_associate_with_default_candidates_is_exact_on_tiny_meshes(mesh):
    verts, faces, points = mesh
    assoc = associate(points, verts, faces)
    dist, _ = _brute_force(points, verts, faces)
    np.testing.assert_allclose(assoc.distance, dist, atol=1e-12)


# ----------------------------------------------------------------------- skinning


@pytest.fixture(scope="module")
def body():
    return body_model_from_arrays(tiny_body_arrays(seed=3), source="tiny")


@pytest.fixture(scope="module")
def bound(body):
    rng = np.random.default_rng(7)
    betas = rng.normal(size=10)
    garment = body.v_template[rng.choice(body.num_vertices, 30)] + rng.normal(0.0, 0.02, size=(30, 3))
    return bind_garment(body, betas, garment)


poses = arrays(np.float64, 72, elements=st.floats(-np.pi, np.pi))


@FAST
@given(pose=poses, transl=vec3, axis=unit_axes(), angle=angles, shift=vec3)
def test_skinning_is_rigidly_invariant_to_the_root(bound, body, pose, transl, axis, angle, shift):
    rot = axis_angle_to_matrix(axis * angle)
    before = skin_garment(bound, pose[None], transl[None], body.parents)[0]
    moved = pose.copy()
    moved[:3] = matrix_to_axis_angle(rot @ axis_angle_to_matrix(pose[:3]))
    j0 = bound.joints[0]
    new_transl = rot @ (j0 + transl) + shift - j0
    after = skin_garment(bound, moved[None], new_transl[None], body.parents)[0]
    np.testing.assert_allclose(after, before @ rot.T + shift, atol=1e-9)


def test_zero_pose_is_the_identity(bound, body):
    out = skin_garment(bound, np.zeros((2, 72)), np.zeros((2, 3)), body.parents)
    np.testing.assert_allclose(out, np.broadcast_to(bound.rest_points, out.shape), atol=1e-12)


@FAST
@given(pose=arrays(np.float64, (2, 72), elements=st.floats(-4 * np.pi, 4 * np.pi)),
       betas=arrays(np.float64, 10, elements=st.floats(-5.0, 5.0)),
       transl=arrays(np.float64, (2, 3), elements=st.floats(-100.0, 100.0)))
def test_extreme_poses_and_shapes_stay_finite(body, pose, betas, transl):
    garment = body.v_template[:20] + 0.01
    binding = bind_garment(body, betas, garment)
    assert np.all(np.isfinite(binding.weights)) and np.all(np.isfinite(binding.association.distance))
    np.testing.assert_allclose(binding.weights.sum(axis=1), 1.0, atol=1e-9)
    assert np.all(np.isfinite(skin_garment(binding, pose, transl, body.parents)))
    assert np.all(np.isfinite(posed_vertices(body, betas, pose, transl)))

"""The penetration post-process moves exactly the penetrating vertices, by the right amount."""

from __future__ import annotations

import numpy as np
import pytest

from cloth_usd.core.postprocess import push_out
from cloth_usd.errors import ArgumentError


def _grid_faces(columns: int, rows: int) -> np.ndarray:
    """(M, 3) the triangles of a grid of ``rows`` x ``columns`` vertices numbered row by row,
    two per cell."""
    m = columns
    return np.array([f for j in range(rows - 1) for i in range(m - 1)
                     for f in ((j * m + i, j * m + i + 1, (j + 1) * m + i),
                               (j * m + i + 1, (j + 1) * m + i + 1, (j + 1) * m + i))])


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


def test_a_vertex_is_measured_against_the_body_vertex_nearest_to_it_in_its_frame():
    """A vertex bound at rest to one body vertex but now inside another part of the body
    (a skirt swung into the other thigh) is pushed out of the part it is in."""
    from cloth_usd.core.postprocess import nearest_body_points

    cloud = np.array([[[0.0, 0.0, 0.0], [1.0, 0.0, 0.0]]])  # (T=1, K=2, 3)
    normals = np.array([[[0.0, 1.0, 0.0], [1.0, 0.0, 0.0]]])
    points = np.array([[[0.97, 0.0, 0.0], [0.01, 0.03, 0.0]]])  # inside the second; 3 cm off the first
    b, n = nearest_body_points(points, cloud, normals)
    np.testing.assert_array_equal(b[0], cloud[0, [1, 0]])
    np.testing.assert_array_equal(n[0], normals[0, [1, 0]])
    out, moved = push_out(points, b, n, margin=0.002)
    np.testing.assert_allclose(out[0, 0], [1.002, 0.0, 0.0], atol=1e-12)
    np.testing.assert_array_equal(out[0, 1], points[0, 1])
    assert moved.tolist() == [1]
    # against the vertex it was bound to (the first), it only moved along that one's normal: still inside
    bound, _ = push_out(points, np.broadcast_to(cloud[:, :1], points.shape), np.broadcast_to(normals[:, :1], points.shape))
    assert bound[0, 0, 0] == points[0, 0, 0] < 1.0
    with pytest.raises(ArgumentError):
        nearest_body_points(points, cloud[:, :0], normals[:, :0])
    # further than the search reaches from every body vertex: not near the body, left alone
    far = np.array([[[0.5, 0.5, 0.0]]])
    b, n = nearest_body_points(far, cloud, normals, reach=0.05)
    assert not n.any()
    np.testing.assert_array_equal(push_out(far, b, n)[0], far)


def test_a_coarse_garment_keeps_more_clearance_than_a_fine_one():
    from cloth_usd.core.postprocess import DEFAULT_MARGIN, LIMB_RADIUS, garment_margin

    def grid(spacing):
        xs = np.arange(6) * spacing
        return np.array([[x, y, 0.0] for y in xs for x in xs]), _grid_faces(6, 6)

    assert garment_margin(*grid(0.015)) == DEFAULT_MARGIN  # a 4000-vertex shirt's edges: the sagitta is 0.6 mm
    coarse = garment_margin(*grid(0.04))
    assert coarse > 0.004
    # the chord bulge of a 4.5 cm limb between two vertices pushed out by that margin stays under the mesh
    half = 0.02
    bulge = LIMB_RADIUS - np.sqrt(LIMB_RADIUS ** 2 - half ** 2)
    assert coarse == pytest.approx(bulge, rel=1e-9)


def test_a_non_finite_vertex_is_left_for_the_guard():
    from cloth_usd.core.postprocess import nearest_body_points

    cloud = np.array([[[0.0, 0.0, 0.0], [1.0, 0.0, 0.0]]])
    normals = np.array([[[0.0, 1.0, 0.0], [1.0, 0.0, 0.0]]])
    points = np.array([[[np.nan, 0.0, 0.0], [0.97, 0.0, 0.0]]])
    b, n = nearest_body_points(points, cloud, normals)
    np.testing.assert_array_equal(b[0, 1], cloud[0, 1])
    out, _ = push_out(points, b, n)
    assert np.isnan(out[0, 0]).any() and np.isfinite(out[0, 1]).all()


def _corner():
    """An L-shaped body, ``{z < 0} or {x > 0}``: a floor (z = 0, x <= 0) meeting a wall
    (x = 0, z >= 0) in a concave corner, as an arm lying against the torso meets it; 1 cm
    vertex spacing. Returns ``(points (V, 3), faces (M, 3), normals (V, 3))``."""
    from cloth_usd.core.features import vertex_normals

    path = [(-0.03, 0.0), (-0.02, 0.0), (-0.01, 0.0), (0.0, 0.0), (0.0, 0.01), (0.0, 0.02), (0.0, 0.03)]  # (x, z)
    ys = (-0.01, 0.0, 0.01)
    pts = np.array([[x, y, z] for y in ys for x, z in path])
    faces = _grid_faces(len(path), len(ys))
    return pts, faces, vertex_normals(pts, faces)


def _outside(p):
    """Distance [m] of points outside :func:`_corner`'s body, negative inside."""
    x, z = p[..., 0], p[..., 2]
    return np.where((x <= 0) & (z >= 0), np.minimum(-x, z), -np.maximum(x, 0) - np.maximum(-z, 0))


def test_a_vertex_in_front_of_its_nearest_body_vertex_but_inside_the_body_is_pushed_out_of_the_surface():
    from cloth_usd.core.postprocess import nearest_body_points, push_out_of_surface

    pts, faces, normals = _corner()
    assert normals[1] @ [0, 0, 1] == pytest.approx(1) and normals[5] @ [-1, 0, 0] == pytest.approx(1)
    garment = np.array([[[0.0005, 0.0, -0.004],    # 4 mm inside the floor, nearest to the corner vertex
                         [-0.015, 0.0, 0.01],      # in the open, 1 cm off both
                         [-0.02, 0.0, -0.003]]])   # 3 mm inside the floor, away from the corner
    # against the nearest vertex's plane alone the first stays inside: the corner's normal is tilted
    old, _ = push_out(garment, *nearest_body_points(garment, pts[None], normals[None]))
    assert _outside(old[0, 0]) < -1e-4
    out, moved = push_out_of_surface(garment, pts[None], normals[None], faces, np.arange(len(pts)), margin=0.002)
    assert _outside(out[0, 0]) > 0.0015  # out, near the margin in front of the floor
    np.testing.assert_array_equal(out[0, 1], garment[0, 1])
    np.testing.assert_allclose(out[0, 2], [-0.02, 0.0, 0.002], atol=1e-12)  # a plane: as push_out
    assert moved.tolist() == [2]
    assert garment[0, 0, 2] == -0.004  # the input is left alone


def test_the_surface_push_leaves_far_and_non_finite_vertices_and_checks_its_arguments():
    from cloth_usd.core.postprocess import push_out_of_surface

    pts, faces, normals = _corner()
    garment = np.array([[[np.nan, 0.0, 0.0], [-0.015, 0.0, 0.2], [-0.02, 0.0, -0.003]]])
    out, moved = push_out_of_surface(garment, pts[None], normals[None], faces, np.arange(len(pts)), reach=0.05)
    np.testing.assert_array_equal(out[0, 0], garment[0, 0])  # left for the guard
    np.testing.assert_array_equal(out[0, 1], garment[0, 1])  # 20 cm off: not near the body
    assert moved.tolist() == [1]
    only_floor = np.flatnonzero(pts[:, 2] == 0.0)
    wall = np.array([[[0.003, 0.0, 0.02]]])  # 3 mm inside the wall, 2 cm above the floor
    inside_wall, _ = push_out_of_surface(wall, pts[None], normals[None], faces, np.arange(len(pts)))
    assert _outside(inside_wall[0, 0]) == pytest.approx(0.002, abs=1e-9)
    with pytest.raises(ArgumentError, match="candidates"):
        push_out_of_surface(garment, pts[None], normals[None], faces, only_floor[:0])
    with pytest.raises(ArgumentError, match="margin"):
        push_out_of_surface(garment, pts[None], normals[None], faces, only_floor, margin=-0.001)


def test_the_surface_search_measures_each_triangle_around_the_nearest_body_vertices_once(monkeypatch):
    from cloth_usd.core import postprocess
    from cloth_usd.core.association import closest_point_on_triangles, incident_faces

    pts, faces, _ = _corner()
    ring = incident_faces(faces, len(pts))
    rng = np.random.default_rng(3)
    q = np.c_[rng.uniform(-0.03, 0.0, 40), rng.uniform(-0.01, 0.01, 40), rng.uniform(0.0, 0.03, 40)] \
        + rng.normal(0.0, 0.004, (40, 3))
    near = np.argsort(np.linalg.norm(q[:, None] - pts[None], axis=2), axis=1)[:, :4]  # neighbours: rings overlap
    found = np.ones(near.shape, dtype=bool)
    found[::5, 3] = False  # a neighbour not found: its ring is not searched
    measured = []

    def counted(tri, p):
        measured.append(len(p))
        return closest_point_on_triangles(tri, p)

    monkeypatch.setattr(postprocess, "closest_point_on_triangles", counted)
    closest, bary, corners = postprocess._closest_triangle(q, np.zeros(len(q), dtype=np.int64), near, found, pts,
                                                           faces, ring)
    around = [np.unique(ring[near[i][found[i]]]) for i in range(len(q))]
    around = [a[a >= 0] for a in around]
    assert measured == [sum(len(a) for a in around)]  # each triangle once, however many of the rings hold it
    for i, a in enumerate(around):
        c, _ = closest_point_on_triangles(pts[faces[a]], np.repeat(q[i:i + 1], len(a), axis=0))
        best = np.linalg.norm(c - q[i], axis=1).min()
        assert np.linalg.norm(closest[i] - q[i]) == pytest.approx(best, abs=1e-12)
        np.testing.assert_allclose(bary[i] @ pts[corners[i]], closest[i], atol=1e-12)


def _sheet(xs, ys, z):
    """A triangulated sheet over ``xs`` x ``ys`` at height ``z``, the body below it (normals
    +z). Returns ``(points (V, 3), faces (M, 3), normals (V, 3))``."""
    pts = np.array([[x, y, z] for y in ys for x in xs])
    return pts, _grid_faces(len(xs), len(ys)), np.tile([0.0, 0.0, 1.0], (len(pts), 1))


def _two_parts(first, second):
    """Two sheets as one body: their points, faces and normals stacked."""
    return (np.concatenate([first[0], second[0]]), np.concatenate([first[1], second[1] + len(first[0])]),
            np.concatenate([first[2], second[2]]))


def test_a_vertex_inside_a_part_whose_vertices_lie_past_another_parts_is_pushed_out_of_it():
    from cloth_usd.core.postprocess import push_out_of_surface

    # a thigh raised into a shirt's hem, coarsely: the vertex is 15 mm inside a part (z < 0)
    # whose vertices are 3 cm and more away, and 18 mm in front of a small part whose vertex
    # is its nearest (28 mm off; the search for more neighbours used to stop at 2 cm)
    body = _two_parts(_sheet(np.arange(-0.08, 0.081, 0.04), np.arange(-0.08, 0.081, 0.04), 0.0),
                      _sheet([-0.005, 0.005], [-0.005, 0.005], -0.033))
    garment = np.array([[[0.02, 0.02, -0.015]]])
    out, moved = push_out_of_surface(garment, body[0][None], body[2][None], body[1], np.arange(len(body[0])),
                                     margin=0.002)
    np.testing.assert_allclose(out[0, 0], [0.02, 0.02, 0.002], atol=1e-9)
    assert moved.tolist() == [1]


def test_a_vertex_outside_the_body_but_far_behind_its_nearest_body_vertex_plane_stays():
    from cloth_usd.core.postprocess import push_out_of_surface

    # a block (x < 0, z < 0): its top, the body under the garment (the candidates), and its
    # side wall; the top's edge vertices have the normal between the two faces'
    top = np.array([[x, y, 0.0] for y in (-0.04, 0.0, 0.04) for x in (-0.08, -0.04, 0.0)])
    wall = np.array([[0.0, y, z] for z in (-0.04, -0.08) for y in (-0.04, 0.0, 0.04)])
    pts = np.concatenate([top, wall])
    wall_index = np.array([2, 5, 8, 9, 10, 11, 12, 13, 14])  # the top's edge is the wall's first row
    faces = np.concatenate([_grid_faces(3, 3), wall_index[_grid_faces(3, 3)]])
    normals = np.tile([0.0, 0.0, 1.0], (len(pts), 1))
    normals[[2, 5, 8]] = [np.sqrt(0.5), 0.0, np.sqrt(0.5)]
    normals[9:] = [1.0, 0.0, 0.0]
    garment = np.array([[[0.01, 0.0, -0.04]]])  # 1 cm in front of the wall, 21 mm behind the edge vertex's plane
    out, moved = push_out_of_surface(garment, pts[None], normals[None], faces, np.arange(9), margin=0.002)
    np.testing.assert_array_equal(out, garment)
    assert moved.tolist() == [0]
    # measured against that plane, as before PLANE_REACH, it was pushed 23 mm
    out, _ = push_out_of_surface(garment, pts[None], normals[None], faces, np.arange(9), margin=0.002,
                                 plane_reach=np.inf)
    assert np.linalg.norm(out - garment) == pytest.approx(0.0232, abs=1e-3)


def _square_grid(n: int = 8, h: float = 0.01):
    """A flat n x n grid of squares of side ``h`` [m], two triangles each: (points, faces)."""
    i, j = np.meshgrid(np.arange(n + 1), np.arange(n + 1), indexing="ij")
    points = np.stack([i.ravel() * h, np.zeros(i.size), j.ravel() * h], axis=1).astype(np.float64)
    v = (i[:-1, :-1] * (n + 1) + j[:-1, :-1]).ravel()
    faces = np.concatenate([np.stack([v, v + n + 1, v + 1], 1), np.stack([v + 1, v + n + 1, v + n + 2], 1)])
    return points, faces


def test_the_strain_limiter_shortens_stretched_edges_and_leaves_the_rest():
    from cloth_usd.core.postprocess import StrainLimiter, mesh_edges

    rest, faces = _square_grid()
    edges = mesh_edges(faces)
    assert len(edges) == 8 * 9 * 2 + 8 * 8  # the grid's lines and one diagonal a square
    lengths = lambda p: np.linalg.norm(p[..., edges[:, 1], :] - p[..., edges[:, 0], :], axis=-1)  # noqa: E731
    limiter = StrainLimiter(rest, faces, limit=1.1)
    # moved rigidly, bent and compressed: no edge past the limit, so nothing moves
    turned = rest @ np.array([[0.0, 0.0, 1.0], [0.0, 1.0, 0.0], [-1.0, 0.0, 0.0]]) + [1.0, 2.0, 3.0]
    folded = rest.copy()
    folded[:, 1] = 0.002 * np.sin(rest[:, 0] * 40.0)  # a slope of 0.08 at most: 1.003 x longer
    squeezed = rest * [0.7, 1.0, 1.0]
    frames = np.stack([turned, folded, squeezed])
    np.testing.assert_allclose(limiter(frames), frames, atol=1e-6)
    # stretched by half along x: every edge ends within a few percent of the limit, the garment
    # where it was (its centre stays), and the frame in the middle is limited as if alone
    stretched = rest * [1.5, 1.0, 1.0]
    both = np.stack([stretched, rest, stretched])
    out = limiter(both)
    ratio = lengths(out[0]) / lengths(rest)
    assert (lengths(stretched) / lengths(rest)).max() == pytest.approx(1.5)
    assert ratio.max() < 1.13, ratio.max()
    np.testing.assert_allclose(out[0].mean(axis=0), stretched.mean(axis=0), atol=1e-4)
    # float32 solves beside the stretched frames: 1.03e-6 off on some CPUs
    np.testing.assert_allclose(out[1], rest, atol=5e-6)
    np.testing.assert_allclose(out[0], out[2], atol=1e-6)  # float32 solves


def test_the_strain_limiter_solves_on_one_blas_thread_and_gives_the_threads_back():
    """SuperLU's solve calls OpenBLAS, whose second thread spun after it and took a core from
    onnxruntime (tshirt-v6's detail tier at 4041 vertices: a median 69 -> 56 ms/frame)."""
    from threadpoolctl import threadpool_info, threadpool_limits

    from cloth_usd.core.postprocess import StrainLimiter

    def blas_threads() -> set[int]:
        return {lib["num_threads"] for lib in threadpool_info() if lib["user_api"] == "blas"}

    rest, faces = _square_grid(4)
    limiter = StrainLimiter(rest, faces)
    seen, solve = [], limiter._solve
    limiter._solve = lambda rhs: (seen.append(blas_threads()), solve(rhs))[1]
    with threadpool_limits(limits=2, user_api="blas"):
        out = limiter(np.stack([rest * [1.5, 1.0, 1.0]]))
        after = blas_threads()
    assert seen and all(threads == {1} for threads in seen), seen
    assert after == {2}
    assert np.isfinite(out).all()


def test_the_strain_limiter_leaves_a_non_finite_frame_for_the_guard_and_checks_its_arguments():
    from cloth_usd.core.postprocess import StrainLimiter

    rest, faces = _square_grid(3)
    limiter = StrainLimiter(rest, faces)
    broken = rest * [2.0, 1.0, 1.0]
    broken[4] = np.nan
    out = limiter(np.stack([broken, rest * [2.0, 1.0, 1.0]]))
    assert np.isnan(out[0, 4]).all() and np.array_equal(out[0, :4], broken[:4])
    assert np.linalg.norm(out[1, 1] - out[1, 0]) < 1.15 * np.linalg.norm(rest[1] - rest[0])
    with pytest.raises(ArgumentError, match="strain limit must be"):
        StrainLimiter(rest, faces, limit=1.0)
    with pytest.raises(ArgumentError, match=r"expected points \(T, 16, 3\)"):
        limiter(rest[None, :5])


def test_the_strain_limiter_leaves_the_free_edges_of_each_frame_as_they_are():
    from cloth_usd.core.postprocess import StrainLimiter

    rest, faces = _square_grid()
    limiter = StrainLimiter(rest, faces, limit=1.1)
    stretched = rest * [1.5, 1.0, 1.0]
    both = np.stack([stretched, stretched])
    free = np.zeros((2, len(limiter.edges)), dtype=bool)
    free[1] = True  # every edge free in the second frame: nothing moves there
    out = limiter(both, free=free)
    np.testing.assert_allclose(out[0], limiter(stretched[None])[0], atol=1e-6)
    np.testing.assert_allclose(out[1], stretched, atol=5e-6)  # float32 solves
    # the edges of the left half free: they stay longer than the limited right half's
    left = (stretched[limiter.edges, 0] < stretched[:, 0].mean()).all(axis=1)
    half = limiter(stretched[None], free=left[None])[0]
    ratio = np.linalg.norm(half[limiter.edges[:, 1]] - half[limiter.edges[:, 0]], axis=1) / limiter.rest_lengths
    assert ratio[left].mean() > 1.2 > 1.13 > ratio[~left].max(), (ratio[left].mean(), ratio[~left].max())
    with pytest.raises(ArgumentError, match="free edges"):
        limiter(both, free=free[:1])


def _lift_scene(arm: bool = False):
    """A 5 x 5 garment sheet (2 cm cells) 2 mm above a flat body (normals +z) whose vertex under the
    middle of an inner garment triangle is raised 4 mm, 2 mm in front of the garment; with ``arm``,
    another body part lies 2 mm above the garment (normals -z), as an arm over a shirt's side.
    Returns ``(garment (1, 25, 3), faces, body (1, V, 3), normals (1, V, 3), body_faces, bump)``."""
    xs = np.arange(5) * 0.02
    garment, faces, _ = _sheet(xs, xs, 0.002)
    corners = faces[12]  # an inner triangle: none of its corners is on the sheet's rim
    assert not np.isin(corners, [0, 1, 2, 3, 4, 5, 9, 10, 14, 15, 19, 20, 21, 22, 23, 24]).any()
    centre = garment[corners].mean(axis=0)
    body = _sheet(np.arange(-1, 10) * 0.01, np.arange(-1, 10) * 0.01, 0.0)
    bump = int(np.argmin(np.linalg.norm(body[0][:, :2] - centre[:2], axis=1)))
    body[0][bump] = [*centre[:2], 0.004]
    if arm:
        over = _sheet(xs, xs, 0.004)
        body = _two_parts(body, (over[0], over[1][:, ::-1], -over[2]))
    return garment[None], faces, body[0][None], body[2][None], body[1], bump


def test_the_lift_raises_a_triangle_off_the_body_in_front_of_it_and_leaves_the_rest():
    from cloth_usd.core.postprocess import LIFT_MARGIN, TriangleLift

    garment, faces, body, normals, body_faces, bump = _lift_scene()
    lift = TriangleLift(faces, garment[0], body[0], normals[0])
    out, lifted = lift(garment, body, normals, body_faces, np.arange(body.shape[1]))
    moved = np.flatnonzero(np.linalg.norm(out[0] - garment[0], axis=1) > 0)
    assert moved.tolist() == sorted(faces[12]) and lifted.tolist() == [3]
    np.testing.assert_allclose(out[0, moved, :2], garment[0, moved, :2])  # along the body's normal (+z)
    # the bump is now LIFT_MARGIN behind the triangle: barycentric weights (1/3 each) over their squares
    height = out[0, faces[12], 2].mean()
    assert height - body[0, bump, 2] == pytest.approx(LIFT_MARGIN, abs=1e-9)
    # a triangle facing away from the body vertex (a sleeve's inner side next to the torso) stays
    flipped, none = TriangleLift(faces[:, ::-1], garment[0], body[0], normals[0])(garment, body, normals, body_faces,
                                                                                  np.arange(body.shape[1]))
    np.testing.assert_array_equal(flipped, garment)
    assert none.tolist() == [0]


def test_a_lift_that_would_put_the_cloth_into_another_part_of_the_body_or_stretch_it_is_taken_back():
    from cloth_usd.core.postprocess import TriangleLift

    garment, faces, body, normals, body_faces, _ = _lift_scene(arm=True)
    lift = TriangleLift(faces, garment[0], body[0], normals[0])
    out, lifted = lift(garment, body, normals, body_faces, np.arange(body.shape[1]))
    np.testing.assert_array_equal(out, garment)  # 2.5 mm up would be 0.5 mm into the arm
    assert lifted.tolist() == [0]
    garment, _, body, normals, body_faces, _ = _lift_scene()  # no arm: the lift is kept
    broken = garment.copy()
    broken[0, 0, 0] = np.nan
    kept = TriangleLift(faces, garment[0], body[0], normals[0])
    two, lifted = kept(np.concatenate([broken, garment]), np.repeat(body, 2, axis=0), np.repeat(normals, 2, axis=0),
                       body_faces, np.arange(body.shape[1]))
    np.testing.assert_array_equal(two[0], broken[0])  # a non-finite frame is left for the guard
    assert lifted.tolist() == [0, 3]
    # nor is one that would stretch an edge past 1.5 times its rest length: cut a third smaller about the
    # lifted triangle, the sheet's edges are 1.49 times their rest, and the 2.5 mm lift would make those
    # off the triangle 1.50 (cut to 0.68, 1.47 and 1.48: kept)
    centre = garment[0, faces[12]].mean(axis=0)
    for cut, kept in ((0.67, 0), (0.68, 3)):
        shrunk = TriangleLift(faces, centre + (garment[0] - centre) * [cut, cut, 1.0], body[0], normals[0])
        assert shrunk(garment, body, normals, body_faces, np.arange(body.shape[1]))[1].tolist() == [kept]
    with pytest.raises(ArgumentError, match=r"points \(T, 25, 3\)"):
        lift(garment[:, :5], body, normals, body_faces, np.arange(body.shape[1]))
    with pytest.raises(ArgumentError, match="candidates"):
        lift(garment, body, normals, body_faces, np.arange(5))


def test_a_lift_kept_beside_one_taken_back_does_not_leave_their_edge_stretched():
    from cloth_usd.core.postprocess import LIFT_STRETCH, TriangleLift

    garment, faces, body, normals, body_faces, _ = _lift_scene()  # the lift raises triangle 12's corners 2.5 mm
    lift = TriangleLift(faces, garment[0], body[0], normals[0])
    a, b, c = faces[12]
    edges = [tuple(e) for e in lift.all_edges.tolist()]
    outside = next(e for e in edges if a in e and not set(e) & {b, c})  # from ``a`` to a vertex the lift leaves

    def at(e, ratio):  # the edge's rest length set so that it now lies at ``ratio`` times it
        k = edges.index(tuple(sorted(e)))
        lift.rest_lengths[k] = np.linalg.norm(garment[0, e[1]] - garment[0, e[0]]) / ratio

    # lifting ``a`` stretches ``outside`` past LIFT_STRETCH: ``a`` goes back; then a-b, which the lift of both
    # ends left as it was, has ``b`` 2.5 mm above ``a``: past LIFT_STRETCH too, so ``b`` goes back as well
    at(outside, LIFT_STRETCH - 0.005)
    at((a, b), LIFT_STRETCH - 0.003)
    out, lifted = lift(garment, body, normals, body_faces, np.arange(body.shape[1]))
    moved = np.flatnonzero(np.linalg.norm(out[0] - garment[0], axis=1) > 0)
    assert moved.tolist() == [c] and lifted.tolist() == [1]
    e = lift.all_edges
    ratio = np.linalg.norm(out[0, e[:, 1]] - out[0, e[:, 0]], axis=1) / lift.rest_lengths
    before = np.linalg.norm(garment[0, e[:, 1]] - garment[0, e[:, 0]], axis=1) / lift.rest_lengths
    assert not np.any((ratio > LIFT_STRETCH) & (ratio > before))


def test_the_lift_raises_the_cloth_off_the_skin_between_body_vertices():
    from cloth_usd.core.postprocess import (LIFT_MARGIN, TriangleLift, body_ahead, edge_midpoints, inner_triangles,
                                            mesh_edges)

    # a garment 4 mm above a flat body at 1.2 mm, but for a valley along its middle column (x = 4 cm) down to
    # 1 mm: the body's vertices (a 1 cm grid at x = 0.5, 1.5, ... cm) all lie more than LIFT_MARGIN behind
    # it (those beside the valley 0.55 mm), but the midpoints of the body's edges across the valley 0.2 mm in
    # front of it: skin a render shows between the body's vertices
    xs = np.arange(5) * 0.02
    garment, faces, _ = _sheet(xs, xs, 0.004)
    valley = np.flatnonzero(np.isclose(garment[:, 0], 0.04))
    garment[valley, 2] = 0.001
    bx = 0.005 + np.arange(8) * 0.01
    body, body_faces, normals = _sheet(bx, bx, 0.0012)
    cand = np.arange(len(body))
    vertices_only = TriangleLift(faces, garment, body, normals)
    out, lifted = vertices_only(garment[None], body[None], normals[None], body_faces, cand)
    np.testing.assert_array_equal(out[0], garment)
    surface = TriangleLift(faces, garment, body, normals, body_faces=body_faces)
    out, lifted = surface(garment[None], body[None], normals[None], body_faces, cand)
    moved = np.flatnonzero(np.linalg.norm(out[0] - garment, axis=1) > 0)
    inner = valley[(garment[valley, 1] > 0.0) & (garment[valley, 1] < 0.08)]  # not on the sheet's rim
    assert set(inner) <= set(moved) and lifted.tolist() == [moved.size]
    np.testing.assert_allclose(out[0, moved, :2], garment[moved, :2])  # along the body's normal (+z)
    # the midpoints in front of the cloth before, none after: all LIFT_MARGIN or more behind it
    mids, up = edge_midpoints(body, normals, mesh_edges(body_faces))
    np.testing.assert_allclose(up, np.tile([0.0, 0.0, 1.0], (len(mids), 1)))
    inner_faces, ring = inner_triangles(faces, len(garment))
    before = body_ahead(garment, inner_faces, ring, mids, up)[0]
    after = body_ahead(out[0], inner_faces, ring, mids, up)[0]
    assert np.sum(before > 0) > 0 and np.nanmax(after) <= -LIFT_MARGIN + 1e-9


def test_the_skin_bared_through_a_garment_is_found_with_the_cloth_around_it():
    from cloth_usd.core.postprocess import TriangleLift

    garment, faces, body, normals, _, _ = _lift_scene()  # a body vertex 2 mm in front of triangle 12
    lift = TriangleLift(faces, garment[0], body[0], normals[0])
    cand = np.arange(body.shape[1])
    broken = garment.copy()
    broken[0, 0, 0] = np.nan
    three = np.concatenate([garment, garment + [0.0, 0.0, 0.003], broken])  # raised 3 mm: covered; left to the guard
    body3, normals3 = np.repeat(body, 3, axis=0), np.repeat(normals, 3, axis=0)
    count, found = lift.bared(three, body3, normals3, cand, tolerance=0, rings=0)
    assert count.tolist() == [1, 0, -1]
    assert [np.flatnonzero(f).tolist() for f in found] == [sorted(faces[12]), [], []]
    ring = np.flatnonzero(lift.bared(garment, body, normals, cand, tolerance=0, rings=1)[1][0])
    assert set(faces[12]) < set(ring) == set(lift.faces[np.isin(lift.faces, faces[12]).any(axis=1)].ravel())
    count, found = lift.bared(garment, body, normals, cand, tolerance=1)  # one body vertex: within the tolerance
    assert count.tolist() == [1] and not found.any()
    count, found = lift.bared(garment, body, normals, cand, tolerance=0, depth=0.003)  # 2 mm in front, not 3
    assert count.tolist() == [0] and not found.any()
    flipped = TriangleLift(faces[:, ::-1], garment[0], body[0], normals[0])  # facing away from the body
    count, found = flipped.bared(garment, body, normals, cand, tolerance=0)
    assert count.tolist() == [0] and not found.any()


def test_the_skin_a_rest_garment_covers_is_what_lies_straight_under_it():
    from cloth_usd.core.postprocess import covered_at_rest

    xs = np.arange(5) * 0.02
    garment, faces, _ = _sheet(xs, xs, 0.01)  # 1 cm over the body
    body = np.array([[0.04, 0.04, 0.0],    # under the middle
                     [0.04, 0.04, 0.015],  # over it (through it at rest): covered too
                     [0.12, 0.04, 0.0],    # 4 cm past the sheet's inner triangles (1 cm past its rim)
                     [0.04, 0.04, -0.05],  # 6 cm under it: past the reach
                     [0.04, 0.04, 0.0]])
    normals = np.array([[0, 0, 1], [0, 0, 1], [0, 0, 1], [0, 0, 1], [1, 0, 0.0]])  # the last one's faces sideways
    assert covered_at_rest(garment, faces, body, normals).tolist() == [True, True, False, False, False]

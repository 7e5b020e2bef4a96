import numpy as np
from scipy.spatial.transform import Rotation

from cloth_usd.core.body import body_model_from_arrays, posed_vertices, shape_body
from cloth_usd.core.skinning import bind_garment, skin_garment
from tests.conftest import tiny_body_arrays


def _body(posedirs=False):
    return body_model_from_arrays(tiny_body_arrays(seed=4, posedirs=posedirs), source="tiny")


def test_zero_pose_keeps_the_rest_garment():
    body = _body(posedirs=True)
    betas = np.linspace(-1, 1, 10)
    rest = np.random.default_rng(0).normal(0, 0.3, size=(50, 3))
    binding = bind_garment(body, betas, rest)
    out = skin_garment(binding, np.zeros((3, 72)), np.zeros((3, 3)), body.parents)
    np.testing.assert_allclose(out, np.repeat(rest[None], 3, 0), atol=1e-12)
    np.testing.assert_allclose(binding.weights.sum(axis=1), 1.0)


def test_global_rotation_and_translation_move_the_garment_rigidly():
    body = _body()
    betas = np.zeros(10)
    _, joints = shape_body(body, betas)
    rest = np.random.default_rng(1).normal(0, 0.3, size=(40, 3))
    binding = bind_garment(body, betas, rest)
    aa = np.array([0.3, -1.2, 0.5])
    pose = np.zeros((1, 72))
    pose[0, :3] = aa
    transl = np.array([[0.1, 0.2, -0.3]])
    out = skin_garment(binding, pose, transl, body.parents)[0]
    expect = Rotation.from_rotvec(aa).apply(rest - joints[0]) + joints[0] + transl[0]
    np.testing.assert_allclose(out, expect, atol=1e-10)


def test_a_garment_vertex_on_a_body_vertex_follows_the_body():
    body = _body(posedirs=True)
    betas = np.random.default_rng(2).normal(size=10)
    v_shaped, _ = shape_body(body, betas)
    picks = np.unique(body.faces[:10].ravel())
    binding = bind_garment(body, betas, v_shaped[picks])
    poses = np.random.default_rng(3).normal(0, 0.5, size=(4, 72))
    transl = np.random.default_rng(4).normal(size=(4, 3))
    ours = skin_garment(binding, poses, transl, body.parents)
    np.testing.assert_allclose(ours, posed_vertices(body, betas, poses, transl)[:, picks], atol=1e-9)


def test_harmonic_weights_interpolate_free_vertices_along_the_mesh():
    from cloth_usd.core.skinning import harmonic_weights

    # a strip of 2 x 6 vertices; the two ends fixed at weights (1, 0) and (0, 1)
    n = 6
    faces = np.array([f for k in range(n - 1) for f in ((k, k + 1, n + k), (k + 1, n + k + 1, n + k))])
    values = np.zeros((2 * n, 2))
    values[[0, n], 0] = 1.0
    values[[n - 1, 2 * n - 1], 1] = 1.0
    values[1:n - 1, 0] = values[n + 1:2 * n - 1, 0] = 1.0  # the free ones start at the left end's
    free = np.ones(2 * n, bool)
    free[[0, n, n - 1, 2 * n - 1]] = False
    out = harmonic_weights(values, faces, free)
    np.testing.assert_allclose(out.sum(axis=1), 1.0, atol=1e-12)
    for r in (out[:n, 1], out[n:, 1]):  # from one end's weights to the other's, steadily
        assert r[0] == 0.0 and r[-1] == 1.0 and np.all(np.diff(r) > 0.1)
    # a free island touching no fixed vertex keeps its values
    faces2 = np.vstack([faces, [[2 * n, 2 * n + 1, 2 * n + 2]]])
    values2 = np.vstack([values, [[0.3, 0.7]] * 3])
    out2 = harmonic_weights(values2, faces2, np.concatenate([free, [True] * 3]))
    np.testing.assert_allclose(out2[2 * n:], values2[2 * n:])


def test_a_skirt_between_the_legs_follows_both_legs_with_free_beyond():
    """A strip hanging between the thighs: bound to the nearest body point, its middle
    switches from one leg's weights to the other's and the edge there tears when the legs
    part; with ``free_beyond`` the weights blend across and no edge stretches as much."""
    import pytest

    from cloth_usd.core.body import load_body_model

    body = load_body_model()
    betas = np.zeros(10)
    v, joints = shape_body(body, betas)
    y = 0.5 * (joints[1, 1] + joints[4, 1])  # mid-thigh
    band = np.abs(v[:, 1] - y) < 0.01
    left = np.flatnonzero(band & (v[:, 0] > 0))
    right = np.flatnonzero(band & (v[:, 0] < 0))
    p_l, p_r = v[left[np.argmin(v[left, 0])]], v[right[np.argmax(v[right, 0])]]
    n = 15
    row = np.linspace(p_l, p_r, n) + [0.0, 0.0, 0.03]  # a little in front of the inner thighs
    rest = np.vstack([row, row - [0.0, 0.03, 0.0]])
    faces = np.array([f for k in range(n - 1) for f in ((k, k + 1, n + k), (k + 1, n + k + 1, n + k))])
    pose = np.zeros((1, 72))
    pose[0, 3 * 1 + 2], pose[0, 3 * 2 + 2] = 0.5, -0.5  # both hips abducted: the legs part
    edges = np.array([[k, k + 1] for k in range(n - 1)])

    def worst_stretch(binding):
        out = skin_garment(binding, pose, np.zeros((1, 3)), body.parents)[0]
        return float((np.linalg.norm(out[edges[:, 0]] - out[edges[:, 1]], axis=1)
                      / np.linalg.norm(rest[edges[:, 0]] - rest[edges[:, 1]], axis=1)).max())

    nearest = bind_garment(body, betas, rest)
    blended = bind_garment(body, betas, rest, faces=faces, free_beyond=0.01)
    assert (blended.association.distance > 0.01).any()
    np.testing.assert_allclose(blended.weights.sum(axis=1), 1.0, atol=1e-9)
    assert worst_stretch(blended) < 0.7 * worst_stretch(nearest), (worst_stretch(blended), worst_stretch(nearest))
    with pytest.raises(Exception, match="free_beyond needs the garment's faces"):
        bind_garment(body, betas, rest, free_beyond=0.01)


def test_dresses_and_trousers_bind_with_blended_weights_everything_else_with_the_nearest():
    """bind_worn is the one place that decides, for the bake and for training alike."""
    from cloth_usd.core.scene import Category
    from cloth_usd.core.skinning import LOWER_FREE_BEYOND, bind_worn

    body = _body()
    betas = np.zeros(body.num_betas)
    v, _ = shape_body(body, betas)
    # a small sheet: two vertices on the body, two standing off it by 5 cm
    normal_off = np.array([0.0, 0.0, 0.05])
    rest = np.vstack([v[0], v[1], v[0] + normal_off, v[1] + normal_off])
    faces = np.array([[0, 1, 2], [1, 3, 2]])
    for category in Category:
        got = bind_worn(body, betas, rest, faces, category)
        free = LOWER_FREE_BEYOND if category in (Category.DRESS, Category.TROUSERS) else None
        want = bind_garment(body, betas, rest, faces=faces, free_beyond=free)
        np.testing.assert_allclose(got.weights, want.weights, atol=1e-12, err_msg=category.value)
    nearest = bind_garment(body, betas, rest)
    assert not np.allclose(bind_worn(body, betas, rest, faces, "trousers").weights, nearest.weights)
    np.testing.assert_allclose(bind_worn(body, betas, rest, faces, "tshirt").weights, nearest.weights, atol=1e-12)

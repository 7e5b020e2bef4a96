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

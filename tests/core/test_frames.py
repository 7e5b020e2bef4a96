import numpy as np
from scipy.spatial.transform import Rotation

from cloth_usd.core.body import shape_body
from cloth_usd.core.frames import body_frame, reorient_poses, rest_orientation
from cloth_usd.core.rotations import axis_angle_to_matrix, matrix_to_axis_angle


def _smpl_like_joints():
    j = np.zeros((24, 3))
    j[1], j[2] = (0.1, -0.1, 0), (-0.1, -0.1, 0)  # hips: left at +X
    j[12] = (0, 0.5, 0.02)  # neck above the pelvis
    j[16], j[17] = (0.18, 0.45, 0), (-0.18, 0.45, 0)
    return j


def test_canonical_body_has_identity_frame_and_turn():
    j = _smpl_like_joints()
    np.testing.assert_allclose(rest_orientation(j, j), np.eye(3), atol=1e-12)
    f = body_frame(j)
    np.testing.assert_allclose(f.T @ f, np.eye(3), atol=1e-12)


def test_turned_rest_is_recovered_and_poses_reexpressed():
    rng = np.random.default_rng(0)
    turn = Rotation.from_rotvec([0.2, 1.3, -0.1]).as_matrix()
    model = _smpl_like_joints()
    world = model @ turn.T + np.array([1.0, 0.2, -3.0])
    np.testing.assert_allclose(rest_orientation(world, model), turn, atol=1e-12)
    # Canonical poses -> what a reader sees for a turned character (zero at its rest).
    canonical = axis_angle_to_matrix(rng.normal(0, 0.7, size=(3, 24, 3)))
    seen = turn @ canonical @ turn.T
    seen_poses = matrix_to_axis_angle(seen).reshape(3, 72)
    back = axis_angle_to_matrix(reorient_poses(seen_poses, turn).reshape(3, 24, 3))
    np.testing.assert_allclose(back[:, 1:], canonical[:, 1:], atol=1e-9)
    np.testing.assert_allclose(back[:, 0], turn @ canonical[:, 0], atol=1e-9)


def test_identity_turn_is_a_no_op(tiny_body):
    _, joints = shape_body(tiny_body, np.zeros(10))
    poses = np.random.default_rng(1).normal(size=(2, 72))
    assert reorient_poses(poses, np.eye(3)) is poses

"""cloth_usd.core.rotations: axis-angle <-> matrix, including angles near 0 and pi."""

from __future__ import annotations

import numpy as np
import pytest

from cloth_usd.core.rotations import axis_angle_to_matrix, matrix_to_axis_angle
from cloth_usd.errors import ArgumentError


def _random_axis_angle(rng: np.random.Generator, n: int, lo: float, hi: float) -> np.ndarray:
    """(n, 3) random axes times angles uniform in [lo, hi]."""
    axis = rng.normal(size=(n, 3))
    axis /= np.linalg.norm(axis, axis=1, keepdims=True)
    return axis * rng.uniform(lo, hi, size=(n, 1))


def test_matrices_are_rotations():
    aa = _random_axis_angle(np.random.default_rng(0), 200, 0.0, np.pi)
    rot = axis_angle_to_matrix(aa)
    identity = np.broadcast_to(np.eye(3), rot.shape)
    np.testing.assert_allclose(rot @ np.swapaxes(rot, 1, 2), identity, atol=1e-12)
    np.testing.assert_allclose(np.linalg.det(rot), 1.0, atol=1e-12)


def test_random_round_trip_and_batch_shape():
    aa = _random_axis_angle(np.random.default_rng(1), 60, 0.0, np.pi - 1e-3).reshape(4, 15, 3)
    rot = axis_angle_to_matrix(aa)
    assert rot.shape == (4, 15, 3, 3)
    back = matrix_to_axis_angle(rot)
    assert back.shape == (4, 15, 3)
    np.testing.assert_allclose(back, aa, atol=1e-10)


def test_matches_scipy():
    transform = pytest.importorskip("scipy.spatial.transform")
    aa = _random_axis_angle(np.random.default_rng(2), 100, 0.0, np.pi)
    expected = transform.Rotation.from_rotvec(aa).as_matrix()
    np.testing.assert_allclose(axis_angle_to_matrix(aa), expected, atol=1e-12)


@pytest.mark.parametrize("angle", [0.0, 1e-14, 1e-9, 1e-6, 1e-4, 1e-2])
def test_near_zero(angle):
    aa = np.array([0.48, -0.6, 0.64]) * angle  # a unit axis
    rot = axis_angle_to_matrix(aa)
    k = np.array([[0, -aa[2], aa[1]], [aa[2], 0, -aa[0]], [-aa[1], aa[0], 0]])
    # Second-order Taylor expansion; the next term is O(angle^3).
    np.testing.assert_allclose(rot, np.eye(3) + k + 0.5 * k @ k, atol=1e-15 + angle**3)
    np.testing.assert_allclose(matrix_to_axis_angle(rot), aa, atol=1e-15, rtol=1e-8)


@pytest.mark.parametrize("delta", [0.0, 1e-12, 1e-8, 1e-5, 1e-3, 0.3])
def test_near_pi(delta):
    axis = np.array([[0.48, -0.6, 0.64], [0.0, 0.0, 1.0], [1.0, 0.0, 0.0], [0.6, 0.8, 0.0]])
    aa = axis * (np.pi - delta)
    back = matrix_to_axis_angle(axis_angle_to_matrix(aa))
    if delta == 0.0:  # aa and -aa are the same rotation; compare matrices and angles
        np.testing.assert_allclose(axis_angle_to_matrix(back), axis_angle_to_matrix(aa), atol=1e-12)
        np.testing.assert_allclose(np.linalg.norm(back, axis=1), np.pi, atol=1e-12)
    else:
        np.testing.assert_allclose(back, aa, atol=1e-10)


def test_tolerates_float32_round_off():
    aa = _random_axis_angle(np.random.default_rng(3), 50, 0.0, np.pi)
    rot = axis_angle_to_matrix(aa).astype(np.float32)
    back = matrix_to_axis_angle(rot)
    np.testing.assert_allclose(axis_angle_to_matrix(back), rot, atol=1e-6)


def test_bad_shapes_raise():
    with pytest.raises(ArgumentError, match=r"aa: .*\(\.\.\., 3\), got \(2, 4\)"):
        axis_angle_to_matrix(np.zeros((2, 4)))
    with pytest.raises(ArgumentError, match=r"rot: .*\(\.\.\., 3, 3\), got \(3, 4\)"):
        matrix_to_axis_angle(np.zeros((3, 4)))


def test_empty_batch():
    assert axis_angle_to_matrix(np.zeros((0, 3))).shape == (0, 3, 3)
    assert matrix_to_axis_angle(np.zeros((0, 3, 3))).shape == (0, 3)

"""Procedural motions: shapes, rest start, joint limits, determinism, smoothness, resampling."""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from scipy.spatial.transform import Rotation

from cloth_usd.datagen.motion import (
    EULER_ORDERS, JOINT_LIMITS, MotionKind, MotionSpec, blend_from_rest, euler_to_poses, generate,
    poses_to_euler, resample, walk_cycle,
)
from cloth_usd.errors import ArgumentError

KINDS = list(MotionKind)
#: Fastest plausible joint rotation [rad/s]; the procedural motions peak near 8.
MAX_ANGULAR_SPEED = 15.0


def _angular_speed(poses: np.ndarray, fps: float) -> np.ndarray:
    """(T-1, 24) rotation angle between consecutive frames per joint, times fps [rad/s]."""
    r = Rotation.from_rotvec(poses.reshape(-1, 3)).as_matrix().reshape(len(poses), 24, 3, 3)
    rel = np.swapaxes(r[:-1], -1, -2) @ r[1:]
    cos = np.clip((np.trace(rel, axis1=-2, axis2=-1) - 1) / 2, -1, 1)
    return np.arccos(cos) * fps


@pytest.mark.parametrize("kind", KINDS, ids=[k.value for k in KINDS])
def test_each_kind_starts_at_rest_and_stays_within_limits(kind):
    spec = MotionSpec(kind=kind, seconds=3.0, fps=24.0, seed=3)
    poses, root = generate(spec)
    assert poses.shape == (72, 72) and root.shape == (72, 3)
    assert np.all(np.isfinite(poses)) and np.all(np.isfinite(root))
    assert np.array_equal(poses[0], np.zeros(72)) and np.array_equal(root[0], np.zeros(3))
    euler = poses_to_euler(poses)
    tol = 1e-9
    assert np.all(euler >= JOINT_LIMITS[..., 0] - tol) and np.all(euler <= JOINT_LIMITS[..., 1] + tol)
    assert _angular_speed(poses, spec.fps).max() < MAX_ANGULAR_SPEED
    assert np.abs(poses[-1]).max() > 0.1  # it moves


@pytest.mark.parametrize("kind", KINDS, ids=[k.value for k in KINDS])
def test_deterministic_per_seed_and_different_across_seeds(kind):
    a = generate(MotionSpec(kind=kind, seconds=2.0, seed=1))
    b = generate(MotionSpec(kind=kind, seconds=2.0, seed=1))
    c = generate(MotionSpec(kind=kind, seconds=2.0, seed=2))
    assert np.array_equal(a[0], b[0]) and np.array_equal(a[1], b[1])
    assert np.abs(a[0] - c[0]).max() > 1e-3


def test_ease_in_is_smooth_from_rest():
    poses, _ = generate(MotionSpec(kind="arm_raise", seconds=2.0, fps=30.0, blend_seconds=0.5))
    step = np.abs(np.diff(poses, axis=0)).max(axis=1)
    assert step[0] < 0.02  # the ease starts with zero velocity
    assert np.abs(poses[15]).max() > 0.5  # and has arrived after 0.5 s


def test_arm_raise_goes_from_down_to_overhead():
    poses, _ = generate(MotionSpec(kind="arm_raise", seconds=4.0, fps=24.0, seed=0))
    z = Rotation.from_rotvec(poses[:, 16 * 3:17 * 3]).as_euler("XYZ")[:, 2]  # left shoulder
    assert z.min() < np.deg2rad(-60) and z.max() > np.deg2rad(60)


def test_walk_and_run_move_forward():
    for kind, least in (("walk", 2.0), ("run", 6.0)):
        _, root = generate(MotionSpec(kind=kind, seconds=3.0))
        assert root[-1, 2] > least and np.all(np.diff(root[:, 2]) >= 0)


def test_limits_table_is_consistent():
    assert JOINT_LIMITS.shape == (24, 3, 2)
    assert np.all(JOINT_LIMITS[..., 0] <= 0) and np.all(JOINT_LIMITS[..., 1] >= 0)
    middle = np.array(["XYZ".index(order[1]) for order in EULER_ORDERS])
    assert np.all(np.abs(JOINT_LIMITS[np.arange(24), middle]) < np.pi / 2)  # angles read back uniquely
    assert np.allclose(JOINT_LIMITS[17, 0], JOINT_LIMITS[16, 0])  # right shoulder mirrors left
    assert np.allclose(JOINT_LIMITS[17, 2], -JOINT_LIMITS[16, 2, ::-1])


def test_euler_round_trip_at_the_limits():
    rng = np.random.default_rng(0)
    lo, hi = JOINT_LIMITS[..., 0], JOINT_LIMITS[..., 1]
    euler = lo + (hi - lo) * rng.random((50, 24, 3))
    euler[0], euler[1] = lo, hi
    assert np.allclose(poses_to_euler(euler_to_poses(euler)), euler, atol=1e-9)


def test_spec_validation_names_the_field():
    with pytest.raises(ArgumentError, match="kind.*valid: walk"):
        MotionSpec(kind="moonwalk")
    with pytest.raises(ArgumentError, match="seconds"):
        MotionSpec(seconds=0)
    with pytest.raises(ArgumentError, match="intensity"):
        MotionSpec(intensity=3.0)
    assert MotionSpec(kind="dance").kind is MotionKind.DANCE


def test_walk_cycle_and_blend_from_rest_keep_working():
    poses, root = walk_cycle(20)
    assert poses.shape == (20, 72) and root.shape == (20, 3)
    assert np.allclose(poses[0], 0.0)
    blended = blend_from_rest(np.full((5, 72), 0.3), 3)
    assert np.allclose(blended[0], 0.0) and np.allclose(blended[3:], 0.3)


def test_resample_interpolates_rotations_and_translation():
    poses = np.zeros((3, 72))
    poses[1, 3:6] = [0.0, 0.0, 0.8]
    poses[2, 3:6] = [0.0, 0.0, 1.6]
    root = np.array([[0.0, 0, 0], [1, 0, 0], [2, 0, 0]])
    out, r = resample(poses, root, 10.0, 20.0)
    assert out.shape == (5, 72) and r.shape == (5, 3)
    assert np.allclose(out[1, 3:6], [0, 0, 0.4]) and np.allclose(out[3, 3:6], [0, 0, 1.2])
    assert np.allclose(r[:, 0], [0, 0.5, 1, 1.5, 2])


@settings(max_examples=25, deadline=None)
@given(n=st.integers(1, 40), src=st.floats(5.0, 120.0), dst=st.floats(5.0, 120.0))
def test_resample_keeps_duration_and_is_finite(n, src, dst):
    poses, root = walk_cycle(n, fps=src)
    out, r = resample(poses, root, src, dst)
    expected = 1 if n == 1 else int(np.floor((n - 1) * dst / src + 1e-9)) + 1
    assert out.shape == (expected, 72) and r.shape == (expected, 3)
    assert np.all(np.isfinite(out)) and np.all(np.isfinite(r))
    assert np.allclose(out[0], poses[0]) and np.allclose(r[0], root[0])

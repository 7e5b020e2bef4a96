"""The trained range of poses: the range poses span, as a bundle records it, and the check."""

from __future__ import annotations

import numpy as np
import pytest

from cloth_usd.core.limits import (JOINT_LIMITS, pose_outliers, pose_range, pose_range_from_record,
                                   pose_range_record)
from cloth_usd.core.smpl import JOINT_NAMES


def _poses(elbow_z_deg) -> np.ndarray:
    """(T, 72): the rest pose but the left elbow turned about z by each angle [deg] (with no
    turn about y or x its Euler angle about z is the angle itself)."""
    poses = np.zeros((len(elbow_z_deg), 24, 3))
    poses[:, JOINT_NAMES.index("left_elbow"), 2] = np.deg2rad(elbow_z_deg)
    return poses.reshape(-1, 72)


def test_the_range_is_each_angles_smallest_and_largest():
    lim = np.rad2deg(pose_range(_poses([-15.0, 5.0, 20.0])))
    elbow = JOINT_NAMES.index("left_elbow")
    np.testing.assert_allclose(lim[elbow, 2], [-15.0, 20.0], atol=1e-9)
    np.testing.assert_allclose(np.delete(lim, elbow, axis=0), 0.0, atol=1e-9)  # every other joint at rest
    with pytest.raises(ValueError, match=r"poses must be \(T, 72\) with T > 0"):
        pose_range(np.zeros((0, 72)))


def test_the_record_round_trips_to_a_hundredth_of_a_degree():
    poses = np.random.default_rng(0).normal(0.0, 0.4, (20, 72))
    record = pose_range_record(poses)
    assert record["frames"] == 20 and list(record["euler_deg"]) == list(JOINT_NAMES)
    np.testing.assert_allclose(pose_range_from_record(record), pose_range(poses), atol=np.deg2rad(0.005 + 1e-9))


@pytest.mark.parametrize("record, expect", [
    ([], "expected"),
    ({"euler_deg": {}}, "lacks the joints pelvis"),
    ({"euler_deg": {name: [[0, 1]] * 2 for name in JOINT_NAMES}}, "three finite"),
    ({"euler_deg": {name: [[0, "a"]] * 3 for name in JOINT_NAMES}}, "three finite"),
    ({"euler_deg": {name: [[0, float("nan")]] * 3 for name in JOINT_NAMES}}, "three finite"),
    ({"euler_deg": {name: [[1, 0]] * 3 for name in JOINT_NAMES}}, "low <= high"),
])
def test_a_broken_record_says_what_is_wrong(record, expect):
    with pytest.raises(ValueError, match=expect):
        pose_range_from_record(record)


def test_the_check_takes_the_range_it_is_given():
    """An elbow turned 30 deg about z is 25 past JOINT_LIMITS' 5, inside a range trained to 25."""
    shot, elbow = _poses([0.0, 30.0]), JOINT_NAMES.index("left_elbow")
    outlier = pose_outliers(shot)
    assert outlier is not None and outlier.frames.tolist() == [1]
    assert (outlier.joint, outlier.axis) == ("left_elbow", "z")
    assert (outlier.low_deg, outlier.high_deg) == pytest.approx(np.rad2deg(JOINT_LIMITS[elbow, 2]))
    assert pose_outliers(shot, limits=pose_range(_poses([-25.0, 25.0]))) is None  # within 10 deg of the range
    narrow = pose_outliers(shot, limits=pose_range(_poses([0.0, 10.0])))
    assert narrow is not None and (narrow.low_deg, narrow.high_deg) == pytest.approx((0.0, 10.0))


def test_the_bodies_record_round_trips_and_the_check_allows_the_margin():
    from cloth_usd.core.limits import BETA_MARGIN, betas_outside_range, betas_range_from_record, betas_range_record

    trained = np.array([[-2.0, 2.0, 0.0], [2.0, -2.0, 0.0], [1.0, 1.0, 0.0]])
    record = betas_range_record(trained)
    assert record == {"count": 3, "betas": [[-2.0, 2.0], [-2.0, 2.0], [0.0, 0.0]]}
    lim = betas_range_from_record(record)
    assert betas_outside_range(np.array([2.0 + BETA_MARGIN, -2.0, 0.4]), lim).size == 0  # at the margin: inside
    assert betas_outside_range(np.array([3.0, 3.0, 0.0, 0.0, 0.6]), lim).tolist() == [0, 1, 4]  # past the record: 0
    for bad in ([], {"betas": [[0.0]]}, {"betas": [[1.0, 0.0]]}, {"betas": [[0.0, float("inf")]]}):
        with pytest.raises(ValueError, match="expected"):
            betas_range_from_record(bad)

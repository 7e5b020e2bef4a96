"""The body measurements a sewing pattern is drafted from, taken on the T-posed body.

Girths are convex-hull perimeters of thin horizontal (or, for the arm, vertical) slices
of the shaped rest body, so they are what a tape measure round the body reads. Heights
are in the canonical body frame (metres, Y up, the pelvis joint at its ``J(betas)[0]``).
Shape letters: V body vertices.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy.spatial import ConvexHull

from ..core.body import BodyModel, shape_body

__all__ = ["BodyMeasurements", "measure_body"]

_PELVIS, _L_KNEE, _SPINE1, _L_ANKLE, _NECK, _L_SHOULDER, _L_ELBOW, _L_WRIST = 0, 4, 3, 7, 12, 16, 18, 20
#: Half thickness of a measuring slice [m].
_SLAB = 0.012


@dataclass(frozen=True)
class BodyMeasurements:
    """A T-posed body's measurements [m], canonical frame (Y up, facing +Z, left at +X)."""

    neck_y: float
    """Height of the neck joint (the base of the neck)."""
    neck_girth: float
    shoulder_y: float
    """Height of the top of the shoulder (trapezius), beside the neck."""
    shoulder_x: float
    """Half width from the centre to the shoulder point (the top of the arm's joint)."""
    armpit_y: float
    """Height of the underarm, where the arm leaves the torso."""
    chest_girth: float
    waist_y: float
    """Height of the spine1 joint (where a dress's bodice meets its skirt)."""
    waist_girth: float
    natural_waist_y: float
    """Height of the narrowest slice of the torso above the waist joint (where trousers sit)."""
    natural_waist_girth: float
    hip_y: float
    """Height of the widest part of the hips and seat."""
    hip_girth: float
    crotch_y: float
    """Height of the crotch (lowest point of the torso between the legs)."""
    thigh_girth: float
    """Girth of one thigh just below the crotch."""
    knee_y: float
    knee_girth: float
    ankle_y: float
    ankle_girth: float
    calf_y: float
    """Height of the widest slice of the leg between the knee and the ankle."""
    calf_girth: float
    arm_y: float
    """Height of the arm's axis in the T-pose (the shoulder joint)."""
    upper_arm_girth: float
    """Girth of the arm just outside the armpit."""
    elbow_x: float
    wrist_x: float
    wrist_girth: float
    front_z: float
    """Most forward point of the torso between waist and armpit."""
    back_z: float
    """Most backward point of the torso between waist and armpit."""
    seat_front_z: float
    seat_back_z: float
    """Front and back of the hips and seat."""

    def to_json(self) -> dict:
        return {k: round(float(v), 4) for k, v in self.__dict__.items()}


def _perimeter(points: np.ndarray) -> float:
    if points.shape[0] < 3:
        return 0.0
    hull = ConvexHull(points)
    ring = points[hull.vertices]
    return float(np.linalg.norm(ring - np.roll(ring, 1, axis=0), axis=1).sum())


def measure_body(body: BodyModel, betas: np.ndarray) -> BodyMeasurements:
    """Measure the body of ``betas`` in the T-pose.

    Args:
        betas: (B',) shape coefficients.
    """
    v, j = shape_body(body, np.asarray(betas, dtype=np.float64))
    v = np.asarray(v, dtype=np.float64)
    x, y = v[:, 0], v[:, 1]
    shoulder_jx = float(j[_L_SHOULDER, 0])
    arm_y = float(j[_L_SHOULDER, 1])

    def torso_slice(h: float, half_width: float) -> np.ndarray:
        sel = (np.abs(y - h) < _SLAB) & (np.abs(x) < half_width)
        return v[sel][:, [0, 2]]

    # The arm just outside the shoulder: its underside, and its girth.
    arm_x = shoulder_jx + 0.07
    arm = v[(np.abs(x - arm_x) < _SLAB) & (y > arm_y - 0.2)]
    armpit_y = float(arm[:, 1].min()) - 0.02
    upper_arm = _perimeter(arm[:, 1:])
    wrist_x = float(j[_L_WRIST, 0])
    wrist = v[(np.abs(x - (wrist_x - 0.02)) < _SLAB / 2) & (y > arm_y - 0.2)]
    top = (np.abs(x - (shoulder_jx - 0.03)) < _SLAB) & (y > arm_y - 0.2)
    shoulder_y = float(y[top].max())
    torso_half = shoulder_jx  # below the armpit the arms are out of the way
    chest_y = armpit_y - 0.04
    waist_y = float(j[_SPINE1, 1])
    torso = v[(y > waist_y) & (y < armpit_y) & (np.abs(x) < torso_half)]
    # Hips: the widest slice between the pelvis joint and the crotch.
    mid = np.abs(x) < 0.03
    crotch_y = float(y[mid & (y < j[_PELVIS, 1])].min()) if np.any(mid & (y < j[_PELVIS, 1])) else \
        float(j[_PELVIS, 1]) - 0.1
    candidates = np.linspace(crotch_y + 0.02, float(j[_PELVIS, 1]) + 0.02, 8)
    girths = [_perimeter(torso_slice(h, 0.4)) for h in candidates]
    hip_y = float(candidates[int(np.argmax(girths))])
    seat = v[(np.abs(y - hip_y) < 0.05) & (np.abs(x) < 0.3)]
    heights = np.linspace(waist_y, armpit_y - 0.12, 10)
    waists = [_perimeter(torso_slice(h, torso_half)) for h in heights]
    knee_y, ankle_y = float(j[_L_KNEE, 1]), float(j[_L_ANKLE, 1])

    def leg(h: float) -> float:
        sel = (np.abs(y - h) < _SLAB) & (x > 0)
        return _perimeter(v[sel][:, [0, 2]])

    lower = np.linspace(knee_y - 0.05, ankle_y + 0.08, 10)
    calves = [leg(h) for h in lower]
    neck = v[(np.abs(y - (float(j[_NECK, 1]) + 0.02)) < _SLAB)]
    return BodyMeasurements(
        neck_y=float(j[_NECK, 1]), neck_girth=_perimeter(neck[:, [0, 2]]),
        shoulder_y=shoulder_y, shoulder_x=shoulder_jx + 0.03, armpit_y=armpit_y,
        chest_girth=_perimeter(torso_slice(chest_y, torso_half)), waist_y=waist_y,
        waist_girth=_perimeter(torso_slice(waist_y, torso_half)),
        natural_waist_y=float(heights[int(np.argmin(waists))]), natural_waist_girth=min(waists), hip_y=hip_y, hip_girth=max(girths),
        crotch_y=crotch_y, thigh_girth=leg(crotch_y - 0.04), knee_y=knee_y, knee_girth=leg(knee_y),
        ankle_y=ankle_y, ankle_girth=leg(ankle_y + 0.04), calf_y=float(lower[int(np.argmax(calves))]),
        calf_girth=max(calves), arm_y=arm_y, upper_arm_girth=upper_arm,
        elbow_x=float(j[_L_ELBOW, 0]), wrist_x=wrist_x, wrist_girth=_perimeter(wrist[:, 1:]),
        front_z=float(torso[:, 2].max()), back_z=float(torso[:, 2].min()),
        seat_front_z=float(seat[:, 2].max()), seat_back_z=float(seat[:, 2].min()))

"""Is a garment plausibly worn by its body? Its size against the body's height and its
distance from the body's bones, from the rest skeleton alone (no body model needed).

A garment authored in the wrong units (a MakeHuman top left in decimetres is 10 times too
big) or placed away from its character reads without a contract violation; these numbers
let ``inspect`` warn about it and ``bake`` refuse it. Shape letters: N garment vertices,
J joints.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from .smpl import JOINT_NAMES, PARENTS

__all__ = ["HEIGHT_PER_HEAD_ANKLE", "SIZE_WARN", "SIZE_SMALL", "SIZE_REFUSE", "FAR_FROM_BONES",
           "GarmentScale", "garment_scale", "scale_notes"]

#: Body height [m] per head-joint-to-mid-ankle distance [m]: 1.69 m / 1.46 m for the
#: embedded SMPL-format body at zero betas (the head joint sits below the crown, the ankles
#: above the soles).
HEIGHT_PER_HEAD_ANKLE = 1.16
#: ``inspect`` warns above this ratio of the garment's bounding-box diagonal to the body's
#: height. A T-posed long-sleeved shirt is about 1.1, a floor-length dress about 1.0.
SIZE_WARN = 1.6
#: ... and below this one (a garment in metres read as centimetres is 0.01).
SIZE_SMALL = 0.1
#: ``bake`` refuses a garment larger than this many times the body's height unless told otherwise.
SIZE_REFUSE = 3.0
#: ``inspect`` warns when the garment's median vertex lies further than this from the body's
#: bones [m]: a worn garment is within a torso's half depth plus its ease (about 0.15 m).
FAR_FROM_BONES = 0.35

_HEAD = JOINT_NAMES.index("head")
_ANKLES = [JOINT_NAMES.index("left_ankle"), JOINT_NAMES.index("right_ankle")]
#: At most this many vertices are measured (evenly strided): the median needs no more.
_SAMPLE = 4096


@dataclass(frozen=True)
class GarmentScale:
    """How a garment's rest points sit on its body's rest skeleton."""

    diagonal: float
    """The diagonal of the garment's bounding box [m], taken over the 1st to 99th percentile
    of its vertices on each axis: a stray vertex or two (a garment of loose pieces) does not
    make it huge, a garment in the wrong units still is."""
    body_height: float
    """The body's height [m], estimated from its head and ankle joints."""
    distance: float
    """Median distance of the garment's vertices from the nearest bone segment [m]."""

    @property
    def ratio(self) -> float:
        """The garment's bounding-box diagonal over the body's height."""
        return self.diagonal / self.body_height


def _segment_distance(points: np.ndarray, a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """(N,) distance from each point to the nearest of the segments a[k]..b[k] (K, 3)."""
    ab = b - a  # (K, 3)
    ap = points[:, None, :] - a[None]  # (N, K, 3)
    t = np.clip(np.einsum("nkc,kc->nk", ap, ab) / np.maximum((ab * ab).sum(-1), 1e-12), 0.0, 1.0)
    closest = a[None] + t[..., None] * ab[None]
    return np.linalg.norm(points[:, None, :] - closest, axis=-1).min(axis=1)


def garment_scale(rest_points: np.ndarray, rest_joints: np.ndarray) -> GarmentScale:
    """Measure a garment against its body's rest skeleton.

    Args:
        rest_points: (N, 3) float garment rest points [m], the frame of ``rest_joints``.
        rest_joints: (24, 3) float SMPL joint positions of the body at rest [m].
    """
    points = np.asarray(rest_points, dtype=np.float64)
    joints = np.asarray(rest_joints, dtype=np.float64)
    if points.shape[0] == 0:
        return GarmentScale(0.0, 1.0, float("inf"))
    lo, hi = np.percentile(points, [1.0, 99.0], axis=0)
    diagonal = float(np.linalg.norm(hi - lo))
    height = HEIGHT_PER_HEAD_ANKLE * float(np.linalg.norm(joints[_HEAD] - joints[_ANKLES].mean(0)))
    sample = points[:: max(1, points.shape[0] // _SAMPLE)]
    child = np.arange(1, len(PARENTS))
    distance = float(np.median(_segment_distance(sample, joints[PARENTS[child]], joints[child])))
    return GarmentScale(diagonal=diagonal, body_height=max(height, 1e-9), distance=distance)


def scale_notes(scale: GarmentScale) -> list[str]:
    """One line for each implausibility of ``scale`` (empty when it looks worn)."""
    notes = []
    figure = (f"its bounding box ({scale.diagonal:.3g} m diagonal) is {scale.ratio:.2g} times the body's "
              f"height ({scale.body_height:.2f} m)")
    if scale.ratio > SIZE_WARN:
        notes.append(f"{figure}: check its units (metersPerUnit, or a scale on the prim)")
    elif scale.ratio < SIZE_SMALL:
        notes.append(f"{figure}: too small to be worn; check its units (metersPerUnit, or a scale on the prim)")
    if scale.distance > FAR_FROM_BONES:
        notes.append(f"its vertices lie {scale.distance:.2f} m from the body's bones (median; a worn garment is "
                     f"within {FAR_FROM_BONES:g} m): check its placement and cloth:body")
    return notes

"""The run-time guard: is a learned tier's frame a garment at all?

A learned model can leave its training range (a pose nobody simulated, a body far out in
shape space) and answer with something that is not a garment: NaN, a vertex thrown far
from the body, a mesh torn into long spikes. Such a frame is replaced, as a whole, by the
next safer tier (detail -> coarse -> skinning) for that frame alone, and counted; a
caller may also refuse it (``cloth-usd bake --strict``).

The checks are relative to the skinned garment of the same frame, since skinning itself
stretches edges at the joints (on the sample walk its longest edge reaches 5.6x its rest
length): an edge counts as stretched by its length over the longer of its rest and its
skinned length. One edge says little (the sample's shipped detail tier has a few edges
at 2-9x in almost every frame, around the post-process's pushes), so a frame fails on
the stretch of a whole percentile of its edges. Shape letters: T frames, N vertices,
E edges.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..errors import ArgumentError
from .mesh import vector_lengths
from .scene import Category

__all__ = ["GuardLimits", "FrameFaults", "check_frames", "guard_limits", "DRESS_LIMITS"]


@dataclass(frozen=True)
class GuardLimits:
    """When a learned frame is not a garment."""

    max_offset: float = 0.5
    """Largest distance [m] of any vertex from its skinned position: a vertex thrown off the
    garment. Not a tight bound: where the hips bend, a hem that hangs as cloth does is far from
    skinning's, which follows the thighs. Newton's own shirt goes up to 387 mm from skinning in
    the 52 simulated training sequences of the sample shirt (213 mm in its test set, and past
    150 mm in 11% of the test frames)."""
    median_offset: float = 0.1
    """Largest distance [m] of the frame's median vertex from its skinned position: a garment
    moved as a whole (crumpled, thrown). Newton's shirt's median vertex stays within 59 mm of
    skinning in those sequences (37 mm in the test set)."""
    stretch: float = 2.0
    """Largest allowed :attr:`stretch_quantile` of the frame's edge stretch (edge length over
    the longer of its rest and skinned lengths). On the sample walk the shipped tiers' 99th
    percentile stays at or below 1.42 (coarse) and 1.54 (detail) in every frame."""
    stretch_quantile: float = 0.99
    """Which quantile of a frame's edge stretch is held to :attr:`stretch`."""
    min_edge: float = 0.005
    """Edges are measured against at least this length [m]: a model's millimetre-scale
    displacement is no tear on a garment whose edges are millimetres long."""

    def __post_init__(self) -> None:
        if not (self.max_offset > 0 and self.median_offset > 0 and self.stretch > 1
                and 0 < self.stretch_quantile <= 1 and self.min_edge > 0):
            raise ArgumentError(f"GuardLimits: need max_offset > 0, median_offset > 0, stretch > 1, "
                                f"0 < stretch_quantile <= 1 and min_edge > 0, got {self.max_offset}, "
                                f"{self.median_offset}, {self.stretch}, {self.stretch_quantile}, {self.min_edge}")


#: A dress's limits (:func:`guard_limits`): its skirt swings away from the legs that skinning binds
#: it to. Newton's sample dress, over its ten simulated training sequences
#: (``bench/bench_newton_offsets.py``), puts its farthest vertex up to 698 mm from skinning and its
#: median vertex up to 162 mm (2.3% and 3.1% of its frames past the shirt's 0.5 and 0.1 m; its
#: test set 481 and 107 mm). The margins over Newton are the shirt's: 1.3 x its farthest vertex,
#: 1.5 x its median.
DRESS_LIMITS = GuardLimits(max_offset=0.9, median_offset=0.25)


def guard_limits(category: Category | str) -> GuardLimits:
    """The limits a bake holds a garment of ``category`` to: :data:`DRESS_LIMITS` for a dress,
    :class:`GuardLimits`' defaults (set on the shirt's Newton frames; Newton's sample trousers stay
    within 139 mm and 62 mm of them) for the others."""
    return DRESS_LIMITS if Category(category) is Category.DRESS else GuardLimits()


@dataclass(frozen=True)
class FrameFaults:
    """What :func:`check_frames` found, per frame."""

    ok: np.ndarray
    """(T,) bool: the frame is a garment."""
    reasons: tuple[str, ...]
    """Per frame, why it is not ('' when it is)."""


def check_frames(points: np.ndarray, skinned: np.ndarray, rest: np.ndarray, edges: np.ndarray,
                 limits: GuardLimits = GuardLimits()) -> FrameFaults:
    """Which frames of a learned tier are garments.

    Args:
        points: (T, N, 3) float the learned tier's garment [m].
        skinned: (T, N, 3) float the skinned garment of the same frames [m].
        rest: (N, 3) float the rest garment [m].
        edges: (E, 2) int garment edges, each once.
        limits: the thresholds.
    """
    points = np.asarray(points, dtype=np.float64)
    skinned = np.asarray(skinned, dtype=np.float64)
    if points.shape != skinned.shape or points.ndim != 3 or points.shape[1:] != np.shape(rest):
        raise ArgumentError(f"check_frames: points {points.shape}, skinned {skinned.shape} and rest "
                            f"{np.shape(rest)} must be (T, N, 3), (T, N, 3) and (N, 3)")
    num_t = points.shape[0]
    finite = np.isfinite(points).all(axis=(1, 2))
    safe = np.where(finite[:, None, None], points, skinned)
    distance = vector_lengths(safe - skinned)
    offset = distance.max(axis=1, initial=0.0)
    median = np.median(distance, axis=1) if distance.shape[1] else np.zeros(num_t)
    stretch = np.ones(num_t)
    if len(edges):
        a, b = edges[:, 0], edges[:, 1]
        rest_len = vector_lengths(rest[a] - rest[b])
        ref = np.maximum(vector_lengths(skinned[:, a] - skinned[:, b]), np.maximum(rest_len, limits.min_edge))
        ratio = vector_lengths(safe[:, a] - safe[:, b]) / ref
        stretch = np.quantile(ratio, limits.stretch_quantile, axis=1)
    reasons = []
    for t in range(num_t):
        if not finite[t]:
            reasons.append("not finite")
        elif offset[t] > limits.max_offset:
            reasons.append(f"a vertex {1e3 * offset[t]:.1f} mm from its skinned position "
                           f"(limit {1e3 * limits.max_offset:g} mm)")
        elif median[t] > limits.median_offset:
            reasons.append(f"half its vertices over {1e3 * median[t]:.1f} mm from their skinned positions "
                           f"(limit {1e3 * limits.median_offset:g} mm)")
        elif stretch[t] > limits.stretch:
            reasons.append(f"edges stretched {stretch[t]:.2f}x at the {limits.stretch_quantile * 100:g}th "
                           f"percentile (limit {limits.stretch:g}x)")
        else:
            reasons.append("")
    return FrameFaults(ok=np.array([not r for r in reasons], dtype=bool), reasons=tuple(reasons))

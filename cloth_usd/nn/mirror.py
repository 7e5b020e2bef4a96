"""A simulated sequence mirrored left for right: twice the training frames from one simulation.

A body and its garment mirrored through the body's midplane (x -> -x in the frame the models
see, the body facing +Z) are another valid sequence: SMPL's left and right joints swap and each
rotation is mirrored (axis-angle ``(a_x, a_y, a_z) -> (a_x, -a_y, -a_z)``), the root's path is
mirrored, and a garment that is itself symmetric takes, at each vertex, Newton's garment at that
vertex's mirror image on its rest surface (barycentric on the nearest triangle). On the sample
shirt, fitted to Newton's 52 simulated sequences alone, their mirror images took 0.75 mm off the
error on its Newton test set on each of two seeds (``bench/bench_sim_scaling.py --mirror``), about
what a second 52 simulated sequences would give; in the hybrid training of the shipped bundle they
took 0.93 mm off the unseen body and put 0.22 mm on the unseen motions (docs/models.md, "Fifty-two simulated
sequences and their mirror images"). A garment that is not symmetric (its
mirror image more than :data:`SYMMETRY_TOLERANCE` from its surface) is refused: mirroring would
teach it another garment.
"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass

import numpy as np

from ..core.association import associate
from ..core.smpl import MIRROR_JOINTS
from ..errors import ArgumentError

__all__ = ["MIRROR_JOINTS", "SYMMETRY_TOLERANCE", "MirrorMap", "mirror_map", "mirror_poses", "mirrored_clip"]

#: Largest distance [m] of a vertex's mirror image from the rest garment's surface for a garment
#: to count as symmetric (the sample shirt: 0.002 mm at the median vertex, 1.8 mm at the 99th
#: percentile, 7.9 mm at the worst).
SYMMETRY_TOLERANCE = 0.02

#: Mirrors a point through the body's midplane (x = 0).
_FLIP = np.array([-1.0, 1.0, 1.0])

#: Triangles searched per vertex: those around its nearest rest vertices.
_NEAREST = 8


@dataclass(frozen=True)
class MirrorMap:
    """Where each vertex's mirror image lies on the rest garment. Shape letters: N vertices."""

    corners: np.ndarray
    """(N, 3) int64 the vertices of the triangle it lies on."""
    weights: np.ndarray
    """(N, 3) float64 its barycentric weights there."""
    distance: np.ndarray
    """(N,) float64 its distance from the surface [m] (0 for an exactly symmetric garment)."""

    def apply(self, points: np.ndarray) -> np.ndarray:
        """(..., N, 3) the mirror image of garments ``points`` (..., N, 3), vertex for vertex."""
        points = np.asarray(points, dtype=np.float64)
        return np.einsum("nk,...nkd->...nd", self.weights, points[..., self.corners, :]) * _FLIP


def mirror_map(rest_points: np.ndarray, faces: np.ndarray, *, tolerance: float = SYMMETRY_TOLERANCE,
               name: str = "the garment") -> MirrorMap:
    """Each vertex's mirror image on the rest garment ``rest_points`` (N, 3) [m] of triangles ``faces``.

    Raises:
        ArgumentError: a vertex's mirror image is more than ``tolerance`` from the surface (one line
            naming ``name`` and the distance).
    """
    rest = np.asarray(rest_points, dtype=np.float64)
    faces = np.asarray(faces, dtype=np.int64)
    # each mirror image's nearest point on the rest garment, as a garment is associated with its body
    found = associate(rest * _FLIP, rest, faces, candidates=_NEAREST)
    worst = int(np.argmax(found.distance))
    if not found.distance[worst] <= tolerance:
        raise ArgumentError(f"{name} is not symmetric left for right: vertex {worst}'s mirror image is "
                            f"{1e3 * found.distance[worst]:.1f} mm from it (limit {1e3 * tolerance:g} mm); train "
                            f"without mirroring")
    return MirrorMap(corners=faces[found.triangle], weights=found.barycentric, distance=found.distance)


def mirror_poses(poses: np.ndarray) -> np.ndarray:
    """(T, 72) SMPL axis-angle poses [rad] mirrored left for right."""
    p = np.asarray(poses, dtype=np.float64).reshape(-1, len(MIRROR_JOINTS), 3)
    return (p[:, list(MIRROR_JOINTS)] * -_FLIP).reshape(-1, 3 * len(MIRROR_JOINTS))


def mirrored_clip(clip, mirror: MirrorMap):
    """A :class:`~cloth_usd.nn.physics_train.PhysicsClip` mirrored left for right: its poses and
    root path, and its simulated target (if any) through ``mirror`` (the map of its rest garment)."""
    target = None
    if clip.target is not None:
        target = mirror.apply(clip.target).astype(np.float32)
    return dataclasses.replace(clip, name=f"{clip.name}-mirrored", poses=mirror_poses(clip.poses),
                               transl=np.asarray(clip.transl, dtype=np.float64) * _FLIP, target=target)

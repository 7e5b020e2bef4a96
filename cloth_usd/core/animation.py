"""Baked animation as plain arrays, for the game-engine exports (``cloth_usd.export``).

The USD layer reads these from a shot or cache (:mod:`cloth_usd.usd.animation`); the
exporters write them as glTF, vertex-animation textures or a browser preview. Everything
is in cloth_usd's internal frame, which is also glTF's: metres, Y-up.

Shape letters: T frames, N garment vertices, M triangles, V body vertices, J joints.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

__all__ = ["MeshAnimation", "SkinnedAnimation", "axis_angle_to_quaternion"]


@dataclass(frozen=True)
class MeshAnimation:
    """A mesh whose points move each frame (a garment's point cache)."""

    name: str
    """The prim path it was read from (``/Character/Tshirt``)."""
    points: np.ndarray
    """(T, N, 3) float64 positions [m], internal frame (Y-up), one row per frame."""
    triangles: np.ndarray
    """(M, 3) int64 vertex indices, counter-clockwise seen from the front."""
    times: np.ndarray
    """(T,) float64 seconds from the first frame (time code / timeCodesPerSecond)."""
    time_codes: np.ndarray
    """(T,) float64 the USD time codes the frames were read at."""
    fps: float
    """Frames per second of the source stage (``timeCodesPerSecond``)."""
    uvs: np.ndarray | None = None
    """(N, 2) float64 texture coordinates (USD's ``primvars:st``, v up), or None."""
    vertex_map: np.ndarray | None = None
    """(N,) int64: the source mesh point of each vertex, when face-varying UVs split
    points into several vertices; None when vertices are the mesh's points."""
    body_path: str | None = None
    """The Skeleton prim the garment is worn by (its ``cloth:body``), when known."""


@dataclass(frozen=True)
class SkinnedAnimation:
    """An SMPL body as a skinned mesh: rest shape, skin weights and joint motion.

    Posing it is linear blend skinning without SMPL's pose correctives: joint ``j``'s
    world transform is the chain of its ancestors' ``(rotation, rest offset)``, the root
    translated by ``root_translation``; a vertex is ``sum_j w_j G_j (v - rest_joints[j])``.
    """

    name: str
    """The Skeleton prim path of the character."""
    rest_vertices: np.ndarray
    """(V, 3) float64 shaped body in SMPL's zero pose [m]."""
    triangles: np.ndarray
    """(M, 3) int64 body faces."""
    weights: np.ndarray
    """(V, J) float64 skin weights, rows summing to 1."""
    rest_joints: np.ndarray
    """(J, 3) float64 joint positions of the shaped rest body [m]."""
    parents: np.ndarray
    """(J,) int64 parent joint index, -1 for the root."""
    joint_names: tuple[str, ...]
    """The J joint names (SMPL's)."""
    rotations: np.ndarray
    """(T, J, 4) float64 local joint rotations as unit quaternions (x, y, z, w)."""
    root_translation: np.ndarray
    """(T, 3) float64 world position of the root joint [m]."""
    times: np.ndarray
    """(T,) float64 seconds from the first frame."""


def axis_angle_to_quaternion(aa: np.ndarray) -> np.ndarray:
    """(..., 3) axis-angle vectors [rad] -> (..., 4) unit quaternions (x, y, z, w)."""
    aa = np.asarray(aa, dtype=np.float64)
    theta = np.linalg.norm(aa, axis=-1, keepdims=True)
    xyz = 0.5 * np.sinc(theta / (2.0 * np.pi)) * aa  # sin(theta / 2) / theta * aa
    q = np.concatenate([xyz, np.cos(theta / 2.0)], axis=-1)
    return q / np.linalg.norm(q, axis=-1, keepdims=True)

"""Rotation conversions between axis-angle vectors and 3x3 matrices (numpy only).

Axis-angle vectors are SMPL's pose parameterisation: the unit rotation axis times
the angle [rad]. Matrices act on column vectors (``p' = R @ p``). Every function
takes any number of leading batch dimensions (written ``...``).
"""

from __future__ import annotations

import numpy as np

from ..errors import ArgumentError

__all__ = ["axis_angle_to_matrix", "matrix_to_axis_angle"]

# Above this cosine, the angle is below 90 degrees and the axis is read from the
# skew-symmetric part of R; at and below it, from the symmetric part (stable near pi).
_COS_SPLIT = 0.0


def axis_angle_to_matrix(aa: np.ndarray) -> np.ndarray:
    """Rotation matrices from axis-angle vectors (Rodrigues' formula).

    Stable for every angle, including exactly zero: the coefficients are written
    with ``np.sinc`` so there is no division by the angle.

    Args:
        aa: (..., 3) float axis-angle vectors [rad].

    Returns:
        (..., 3, 3) float64 rotation matrices.
    """
    aa = np.asarray(aa, dtype=np.float64)
    if aa.shape[-1:] != (3,):
        raise ArgumentError(f"aa: axis-angle vectors must have shape (..., 3), got {aa.shape}")
    theta = np.sqrt(np.sum(aa * aa, axis=-1))[..., None, None]
    a = np.sinc(theta / np.pi)  # sin(t) / t
    b = 0.5 * np.sinc(theta / (2.0 * np.pi)) ** 2  # (1 - cos(t)) / t^2
    k = _skew(aa)
    return np.eye(3) + a * k + b * (k @ k)


def matrix_to_axis_angle(rot: np.ndarray) -> np.ndarray:
    """Axis-angle vectors from rotation matrices; the angle lies in [0, pi].

    Robust near 0 (no division by sin of the angle) and near pi (the axis is
    then read from the symmetric part of the matrix). Inputs should be rotations;
    small deviations from orthonormality (float32 round-off) are tolerated.

    Args:
        rot: (..., 3, 3) float rotation matrices.

    Returns:
        (..., 3) float64 axis-angle vectors [rad]. At exactly pi, either of the two
        equivalent opposite vectors may be returned.
    """
    rot = np.asarray(rot, dtype=np.float64)
    if rot.shape[-2:] != (3, 3):
        raise ArgumentError(f"rot: rotation matrices must have shape (..., 3, 3), got {rot.shape}")
    batch = rot.shape[:-2]
    r = rot.reshape(-1, 3, 3)
    # v = sin(theta) * axis; c = cos(theta).
    v = 0.5 * np.stack(
        [r[:, 2, 1] - r[:, 1, 2], r[:, 0, 2] - r[:, 2, 0], r[:, 1, 0] - r[:, 0, 1]], axis=-1
    )
    c = np.clip(0.5 * (np.trace(r, axis1=-2, axis2=-1) - 1.0), -1.0, 1.0)
    s = np.linalg.norm(v, axis=-1)
    theta = np.arctan2(s, c)
    out = v * (theta / np.where(s > 0.0, s, 1.0))[:, None]
    out[s == 0.0] = 0.0  # identity (angle exactly zero); pi handled below
    large = c <= _COS_SPLIT
    if np.any(large):
        out[large] = _axis_angle_near_pi(r[large], v[large], c[large], theta[large])
    return out.reshape(*batch, 3)


def _axis_angle_near_pi(r: np.ndarray, v: np.ndarray, c: np.ndarray, theta: np.ndarray) -> np.ndarray:
    """Axis-angle for angles of 90 degrees or more, shapes (K,3,3), (K,3), (K,), (K,).

    The symmetric part of R is ``cos(t) I + (1 - cos(t)) a a^T``; with
    ``1 - cos(t) >= 1`` its column of largest diagonal gives the axis to full
    precision, and the sign comes from ``v = sin(t) a``.
    """
    outer = 0.5 * (r + np.swapaxes(r, -1, -2)) - c[:, None, None] * np.eye(3)
    outer = outer / (1.0 - c)[:, None, None]  # = a a^T
    k = np.argmax(np.diagonal(outer, axis1=-2, axis2=-1), axis=-1)
    rows = np.arange(len(k))
    axis = outer[rows, :, k]  # a * a_k
    axis = axis / np.linalg.norm(axis, axis=-1, keepdims=True)
    flip = np.sum(axis * v, axis=-1) < 0.0
    axis[flip] = -axis[flip]
    return axis * theta[:, None]


def _skew(v: np.ndarray) -> np.ndarray:
    """(..., 3) vectors -> (..., 3, 3) cross-product matrices ``[v]_x``."""
    zero = np.zeros(v.shape[:-1])
    x, y, z = v[..., 0], v[..., 1], v[..., 2]
    return np.stack(
        [
            np.stack([zero, -z, y], axis=-1),
            np.stack([z, zero, -x], axis=-1),
            np.stack([-y, x, zero], axis=-1),
        ],
        axis=-2,
    )

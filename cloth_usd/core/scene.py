"""What the USD layer hands to the rest of cloth_usd: frozen dataclasses of numpy arrays.

All positions here are in cloth_usd's internal frame: SMPL's, metres, Y-up, the body
facing +Z. The USD layer converts a stage's ``upAxis`` and ``metersPerUnit`` into this
frame once, on read, and back once, on write (see ``stage_to_internal``).

Shape letters: T frames, N garment vertices, M triangles, J joints.
"""

from __future__ import annotations

import enum
from dataclasses import dataclass, field

import numpy as np

__all__ = [
    "Tier",
    "Category",
    "StageInfo",
    "Character",
    "Motion",
    "Garment",
    "Scene",
]


class Tier(str, enum.Enum):
    """Quality tiers, fastest first."""

    SKINNING = "skinning"
    COARSE = "coarse"
    DETAIL = "detail"


class Category(str, enum.Enum):
    """Garment categories; one model pair per category."""

    TSHIRT = "tshirt"
    DRESS = "dress"
    TROUSERS = "trousers"


@dataclass(frozen=True)
class StageInfo:
    """Stage-level metadata, as authored on the root layer."""

    identifier: str
    """The root layer's identifier (usually its file path)."""
    up_axis: str
    """``"Y"`` or ``"Z"``."""
    meters_per_unit: float
    """Metres per stage unit (0.01 when unauthored, as USD says)."""
    meters_per_unit_authored: bool
    """False when the stage did not author ``metersPerUnit``."""
    time_codes_per_second: float
    frames_per_second: float
    start_time_code: float | None
    """None when the stage authors no start time code."""
    end_time_code: float | None
    """None when the stage authors no end time code."""
    stage_to_internal: np.ndarray = field(repr=False)
    """(4, 4) float64: maps stage world points to internal metres Y-up, column
    convention: ``internal = M @ [p, 1]``. A uniform scale and a rotation."""


@dataclass(frozen=True)
class Character:
    """A UsdSkel Skeleton that carries the 24 SMPL joints."""

    prim_path: str
    """Path of the Skeleton prim."""
    betas: np.ndarray
    """(10,) float64 SMPL shape coefficients (zero-padded when fewer are authored)."""
    betas_authored: bool
    """False when ``smpl:betas`` is missing (betas are then zeros)."""
    gender: str
    """``neutral``, ``female`` or ``male``."""
    joint_indices: np.ndarray
    """(24,) int64: for each SMPL joint, its index in the Skeleton's ``joints`` array."""
    rest_root_position: np.ndarray
    """(3,) float64 pelvis joint position [m] in the rest pose, internal world frame."""
    rest_joints: np.ndarray
    """(24, 3) float64 SMPL joint positions [m] in the rest pose, internal world frame:
    how the T-posed body stands in the world (its place and its turn)."""


@dataclass(frozen=True)
class Motion:
    """A character's pose at each requested time code, in SMPL's parameterisation."""

    times: np.ndarray
    """(T,) float64 time codes."""
    poses: np.ndarray
    """(T, 72) float64 axis-angle [rad], 24 joints x 3, joint 0 the global orientation,
    relative to the rest pose (the rest pose is SMPL's zero pose)."""
    root_position: np.ndarray
    """(T, 3) float64 posed pelvis joint position [m], internal world frame. SMPL's
    ``transl`` is ``root_position - J(betas)[0]``."""


@dataclass(frozen=True)
class Garment:
    """A garment Mesh prim as the scene contract describes it."""

    prim_path: str
    category: Category
    body_path: str
    """Path of the Skeleton prim that ``cloth:body`` targets."""
    enabled: bool
    tier: Tier | None
    """Per-garment ``cloth:tier`` override, None when unauthored."""
    rest_points: np.ndarray
    """(N, 3) float64 rest-pose garment points [m], internal world frame (the body
    stands with its pelvis at its Character's ``rest_root_position``)."""
    triangles: np.ndarray
    """(M, 3) int64 vertex indices, the polygons fan-triangulated."""
    face_map: np.ndarray
    """(M,) int64: the source polygon index of each triangle."""


@dataclass(frozen=True)
class Scene:
    """Everything cloth_usd reads from a stage before any frame is evaluated."""

    stage: StageInfo
    characters: tuple[Character, ...]
    garments: tuple[Garment, ...]

"""The one error hierarchy of cloth_usd.

Every error a user can cause is a :class:`ClothUsdError`; its message names the file,
prim, frame or argument at fault and says what to do. The CLI prints it as one line.
"""

from __future__ import annotations

__all__ = [
    "ClothUsdError",
    "BodyModelError",
    "SceneError",
    "GarmentError",
    "OutputExistsError",
    "OutputWriteError",
    "ArgumentError",
    "MotionFileError",
    "BundleError",
]


class ClothUsdError(Exception):
    """Base of every error cloth_usd raises on purpose."""


class BodyModelError(ClothUsdError):
    """A body model file is missing, unreadable or not in SMPL layout."""


class SceneError(ClothUsdError):
    """A stage breaks the scene contract (see docs/scene_contract.md in the repository)."""


class GarmentError(SceneError):
    """A garment prim breaks the scene contract."""


class OutputExistsError(ClothUsdError):
    """An output file exists and ``--force`` was not given."""


class OutputWriteError(ClothUsdError):
    """USD could not create or save an output layer (no write permission, a full disk,
    a network share gone); the target is left as it was. Another attempt may succeed."""


class ArgumentError(ClothUsdError):
    """A command-line or API argument is out of range or malformed."""


class MotionFileError(ClothUsdError):
    """A motion file (BVH, AMASS ``.npz``) is missing, malformed or lacks a joint or key."""


class BundleError(ClothUsdError):
    """A model bundle is missing a file, fails its sha256 check or has a bad manifest."""

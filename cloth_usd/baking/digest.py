"""The digest of everything a cache depends on (:attr:`cloth_usd.baking.BakePlan.inputs_sha256`)."""

from __future__ import annotations

import hashlib
import json
import os
from typing import Sequence

from .._version import __version__
from ..core.body import BodyModel
from ..core.files import file_sha256
from ..core.frame_range import FrameRange
from ..core.scene import Character, Garment, Tier
from ..runtime.bundle import ModelBundle

__all__ = ["inputs_digest"]


def inputs_digest(layer_files: Sequence[str], frames: FrameRange, chosen: Sequence[Garment],
                  tiers: dict[str, tuple[Tier, ModelBundle | None]], characters: dict[str, Character],
                  bodies: dict[str, BodyModel], joint_map: dict[str, int]) -> str:
    """sha256 over the stage's layer files (root first, the others sorted), the frame range,
    each garment's tier, bundle and body model, the joint map and the tool version.

    Args:
        tiers: by garment prim path, its tier and bundle (None for skinning).
        bodies: by gender.
    """
    files = [p for p in layer_files if p and os.path.isfile(p)]
    layers = [file_sha256(files[0])] + sorted(file_sha256(p) for p in files[1:]) if files else []
    payload = {
        "tool_version": __version__,
        **({"joint_map": joint_map} if joint_map else {}),  # absent without a map: older digests hold
        "layers": layers,
        "frames": [repr(float(frames.start)), repr(float(frames.end)), repr(float(frames.step))],
        "garments": {g.prim_path: {"tier": tiers[g.prim_path][0].value,
                                   "bundle": tiers[g.prim_path][1].sha256 if tiers[g.prim_path][1] else "",
                                   "body": bodies[characters[g.body_path].gender].sha256}
                     for g in chosen},
    }
    return hashlib.sha256(json.dumps(payload, sort_keys=True).encode()).hexdigest()

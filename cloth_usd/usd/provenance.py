"""A cache's provenance on disk: :class:`~cloth_usd.core.provenance.Provenance` as the
layer's ``customLayerData["cloth_usd"]`` and back.

The on-disk form (docs/scene_contract.md) is a dictionary of strings and numbers:
VtDictionary keeps no plain list of floats, so the fit is a string of numbers, and a
skinning-tier garment records ``fit = "not computed (skinning tier)"`` and none of the
learned tiers' counts.
"""

from __future__ import annotations

from typing import Any, Mapping

from ..core.frame_range import parse_frames
from ..core.provenance import FileRecord, GarmentReport, Provenance
from ..core.scene import Tier
from ..errors import ClothUsdError
from .write import CacheInfo

__all__ = ["KEY", "to_custom_data", "from_custom_data", "cache_provenance"]

#: The ``customLayerData`` key that holds cloth_usd's provenance.
KEY = "cloth_usd"

_NO_FIT = "not computed (skinning tier)"


def _garment_data(r: GarmentReport) -> dict:
    out: dict[str, Any] = {"tier": r.tier.value, "vertices": r.vertices, "frames": r.frames,
                           "mean_body_distance_mm": round(r.mean_body_distance_mm, 3),
                           "max_displacement_mm": round(r.max_displacement_mm, 3)}
    if r.fit is None:
        out["fit"] = _NO_FIT
    else:  # a string of numbers: VtDictionary keeps no plain list of floats
        out.update(fit=" ".join(f"{a:.6g}" for a in r.fit), model_bundle=r.bundle,
                   postprocess_moved=r.postprocess_moved, max_offset_mm=round(r.max_offset_mm, 3),
                   fallback_coarse=r.fallback_coarse, fallback_skinning=r.fallback_skinning)
    return out


def to_custom_data(p: Provenance) -> dict:
    """``{"cloth_usd": {...}}``, the cache layer's ``customLayerData``."""
    return {KEY: {
        "tool_version": p.tool_version,
        "source_layer": p.source_layer,
        "frame_range": str(p.frames),
        "body_models": {g: {"file": b.name, "sha256": b.sha256} for g, b in p.body_models.items()},
        "model_bundle": {"name": p.model_bundle.name, "sha256": p.model_bundle.sha256},
        "garments": {r.prim_path: _garment_data(r) for r in p.garments},
        "inputs_sha256": p.inputs_sha256,
    }}


def _fit(text: Any) -> tuple[float, ...] | None:
    try:
        return tuple(float(a) for a in str(text).split())
    except ValueError:
        return None


def _garment(prim: str, g: Mapping[str, Any]) -> GarmentReport:
    fit = _fit(g.get("fit", _NO_FIT))
    return GarmentReport(
        prim_path=prim, tier=Tier(g["tier"]), vertices=int(g["vertices"]), frames=int(g["frames"]),
        mean_body_distance_mm=float(g.get("mean_body_distance_mm", 0.0)),
        max_displacement_mm=float(g.get("max_displacement_mm", 0.0)),
        bundle=g.get("model_bundle") if fit is not None else None, fit=fit,
        postprocess_moved=int(g.get("postprocess_moved", 0)), max_offset_mm=float(g.get("max_offset_mm", 0.0)),
        fallback_coarse=int(g.get("fallback_coarse", 0)), fallback_skinning=int(g.get("fallback_skinning", 0)))


def from_custom_data(data: Mapping[str, Any]) -> Provenance | None:
    """The provenance a layer's ``customLayerData`` records; None when it holds none (not a
    cloth_usd cache, or one whose provenance is malformed)."""
    raw = data.get(KEY)
    if not isinstance(raw, Mapping):
        return None
    try:
        return Provenance(
            tool_version=str(raw.get("tool_version", "")), source_layer=str(raw.get("source_layer", "")),
            frames=parse_frames(str(raw["frame_range"])),
            body_models={g: FileRecord(name=str(b["file"]), sha256=str(b["sha256"]))
                         for g, b in dict(raw.get("body_models", {})).items()},
            model_bundle=FileRecord(name=str(raw["model_bundle"]["name"]), sha256=str(raw["model_bundle"]["sha256"])),
            garments=tuple(_garment(prim, g) for prim, g in dict(raw.get("garments", {})).items()),
            inputs_sha256=str(raw.get("inputs_sha256", "")))
    except (KeyError, TypeError, ValueError, ClothUsdError):
        return None


def cache_provenance(info: CacheInfo | None) -> Provenance | None:
    """The provenance of a cache layer read by :func:`~cloth_usd.usd.write.cache_layer_info`."""
    return None if info is None else from_custom_data(info.provenance)

"""cloth_usd: learned garment animation that reads a USD scene and writes a USD point cache.

Importing this package is cheap; heavy modules (pxr, onnxruntime) load on first use::

    import cloth_usd
    result = cloth_usd.bake("shot.usda", "cache.usdc", shot="shot_cloth.usda")
"""

from __future__ import annotations

from typing import Any

from ._version import __version__

__all__ = ["__version__", "bake", "inspect_stage", "ClothUsdError"]

from .errors import ClothUsdError


def __getattr__(name: str) -> Any:
    if name == "bake":
        from .baking import bake

        return bake
    if name == "inspect_stage":
        from .inspection import inspect_stage

        return inspect_stage
    raise AttributeError(f"module 'cloth_usd' has no attribute {name!r}")

"""Torch networks of the learned tiers (training and export only; inference runs the
exported ONNX models through :mod:`cloth_usd.runtime`, without torch)."""

from .layers import GATBlock, gather_nodes, masked_softmax, pool_mean, unpool
from .models import (
    AttributeParser,
    CoarseConfig,
    CoarseGenerator,
    DetailConfig,
    DetailGenerator,
    DisplacementHead,
    ParserConfig,
)

__all__ = [
    "GATBlock", "gather_nodes", "masked_softmax", "pool_mean", "unpool",
    "AttributeParser", "CoarseConfig", "CoarseGenerator", "DetailConfig", "DetailGenerator",
    "DisplacementHead", "ParserConfig", "export_coarse", "export_detail",
]


def __getattr__(name: str):
    if name in ("export_coarse", "export_detail"):
        from . import export

        return getattr(export, name)
    raise AttributeError(f"module 'cloth_usd.nn' has no attribute {name!r}")

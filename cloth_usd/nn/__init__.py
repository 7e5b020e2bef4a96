"""Torch networks of the learned tiers (training and export only; inference runs the
exported ONNX models through :mod:`cloth_usd.runtime`, without torch).

Training: :func:`cloth_usd.nn.train.train` (``cloth-usd train``) on data from
:mod:`cloth_usd.nn.data`; bundles: :func:`cloth_usd.nn.export.export_bundle`
(``cloth-usd export``)."""

from .layers import GATBlock, gather_nodes, pad_table, pool_mean, slot_softmax, unpool
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
    "GATBlock", "gather_nodes", "pad_table", "pool_mean", "slot_softmax", "unpool",
    "AttributeParser", "CoarseConfig", "CoarseGenerator", "DetailConfig", "DetailGenerator",
    "DisplacementHead", "ParserConfig", "export_coarse", "export_detail", "export_bundle",
    "TrainConfig", "load_run",
]

_LAZY = {"export_coarse": "export", "export_detail": "export", "export_bundle": "export",
         "TrainConfig": "config", "load_run": "runs"}


def __getattr__(name: str):
    if name in _LAZY:
        import importlib

        return getattr(importlib.import_module(f".{_LAZY[name]}", __name__), name)
    raise AttributeError(f"module 'cloth_usd.nn' has no attribute {name!r}")

"""ONNX export of the generators (torch.onnx, dynamo exporter, opset 18).

Input and output names and shapes: :mod:`cloth_usd.runtime.io`. Every dimension is
dynamic: batch B, vertices N, neighbours K, pooled clusters N2, members P, pooled
neighbours K2, so one exported file serves every garment topology. Example inputs are
built on a small synthetic grid whose dimensions are all distinct and > 1 (the exporter
specialises dimensions that equal 0, 1 or each other in the example).
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import torch

from ..core.graph import build_graph
from ..runtime.io import COARSE_INPUTS, DETAIL_INPUTS, OUTPUT, detail_inputs
from .models import ATTRIBUTE_FEATURES, CoarseGenerator, DetailGenerator

__all__ = ["OPSET", "export_coarse", "export_detail"]

OPSET = 18


def _example(model: CoarseGenerator | DetailGenerator) -> tuple[dict[str, torch.Tensor], int]:
    """Example inputs on a 9 x 7 grid with a fan vertex, batch 2."""
    nx, ny = 9, 7
    xs, ys = np.meshgrid(np.arange(nx, dtype=float), np.arange(ny, dtype=float) * 1.1)
    pos = np.stack([xs.ravel(), ys.ravel(), np.zeros(nx * ny)], 1)
    idx = np.arange(nx * ny).reshape(ny, nx)
    a, b, c, d = idx[:-1, :-1].ravel(), idx[:-1, 1:].ravel(), idx[1:, :-1].ravel(), idx[1:, 1:].ravel()
    faces = np.concatenate([np.stack([a, b, d], 1), np.stack([a, d, c], 1)])
    graph = build_graph(faces, pos)
    rng = np.random.default_rng(0)
    batch = 2
    feats = rng.normal(size=(batch, nx * ny, model.config.in_features))
    inputs = detail_inputs(feats, rng.normal(size=(batch, ATTRIBUTE_FEATURES)), graph)
    return {k: torch.from_numpy(v) for k, v in inputs.items()}, batch


def _dynamic_axes(name: str, ndim: int) -> range:
    """Dynamic axes of an input: all but the feature axis of ``features`` / ``attributes``."""
    return range(ndim - 1) if name in ("features", "attributes") else range(ndim)


def _export(model: torch.nn.Module, names: tuple[str, ...], path: Path,
            example: dict[str, torch.Tensor]) -> Path:
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    args = tuple(example[n] for n in names)
    dynamic = tuple({a: torch.export.Dim.DYNAMIC for a in _dynamic_axes(n, example[n].ndim)} for n in names)
    model = model.eval()
    with torch.no_grad():
        program = torch.onnx.export(model, args, input_names=list(names), output_names=[OUTPUT],
                                    dynamic_shapes=dynamic, opset_version=OPSET, dynamo=True,
                                    optimize=True, verbose=False)
    program.save(str(path))
    return path


def export_coarse(model: CoarseGenerator, path: str | Path) -> Path:
    """Write ``model`` to ``path`` as ONNX (inputs :data:`~cloth_usd.runtime.io.COARSE_INPUTS`).

    Returns:
        The path written.
    """
    example, _ = _example(model)
    return _export(model, COARSE_INPUTS, Path(path), example)


def export_detail(model: DetailGenerator, path: str | Path) -> Path:
    """Write ``model`` to ``path`` as ONNX (inputs :data:`~cloth_usd.runtime.io.DETAIL_INPUTS`).

    Returns:
        The path written.
    """
    example, _ = _example(model)
    return _export(model, DETAIL_INPUTS, Path(path), example)

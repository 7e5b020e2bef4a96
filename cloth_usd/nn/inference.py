"""Torch models run as the core pipeline's model functions (evaluation, export checks,
training): named inputs moved to the device once per graph, no gradient."""

from __future__ import annotations

from typing import Callable, Mapping, Sequence

import numpy as np
import torch

from ..core.graph import MeshGraph
from ..errors import ArgumentError
from ..runtime.io import COARSE_INPUTS, DETAIL_INPUTS, coarse_inputs, detail_inputs
from .models import CoarseGenerator, DetailGenerator

__all__ = ["pick_device", "Tensors", "coarse_forward", "detail_forward", "torch_coarse_fn", "torch_detail_fn"]


def pick_device(name: str | None) -> torch.device:
    """``cpu``, ``cuda`` (an error when unavailable) or ``auto``/None (cuda when available)."""
    if name in (None, "auto"):
        return torch.device("cuda" if torch.cuda.is_available() else "cpu")
    if name not in ("cpu", "cuda") and not str(name).startswith("cuda:"):
        raise ArgumentError(f"--device {name}: unknown (valid: auto, cpu, cuda)")
    if str(name).startswith("cuda") and not torch.cuda.is_available():
        raise ArgumentError(f"--device {name}: torch sees no CUDA device (torch {torch.__version__}); use cpu")
    return torch.device(name)


class Tensors:
    """Named model inputs as tensors on one device; graph tensors are moved once per graph.

    The cache holds each graph it keys by ``id``, so a freed graph's id can never be
    reused by another garment's graph while its tensors are cached.
    """

    def __init__(self, device: torch.device) -> None:
        self.device = device
        self._graphs: dict[int, tuple[MeshGraph, dict[str, torch.Tensor]]] = {}

    def __call__(self, inputs: Mapping[str, np.ndarray], graph: MeshGraph, names: Sequence[str]) -> list:
        held, cached = self._graphs.setdefault(id(graph), (graph, {}))
        assert held is graph
        out = []
        for name in names:
            if name in ("features", "attributes"):
                out.append(torch.from_numpy(inputs[name]).to(self.device))
                continue
            if name not in cached:
                cached[name] = torch.from_numpy(inputs[name]).to(self.device)
            out.append(cached[name])
        return out


def coarse_forward(model: CoarseGenerator, features: np.ndarray, graph: MeshGraph, tensors: Tensors) -> torch.Tensor:
    return model(*tensors(coarse_inputs(features, graph.table), graph, COARSE_INPUTS))


def detail_forward(model: DetailGenerator, features: np.ndarray, attributes: np.ndarray, graph: MeshGraph,
                    tensors: Tensors) -> torch.Tensor:
    return model(*tensors(detail_inputs(features, attributes, graph), graph, DETAIL_INPUTS))


def torch_coarse_fn(model: CoarseGenerator, device: torch.device | str = "cpu") -> Callable:
    """A :data:`cloth_usd.core.pipeline.CoarseFn` running a torch coarse model (no grad)."""
    tensors = Tensors(torch.device(device))

    def run(features: np.ndarray, graph: MeshGraph) -> np.ndarray:
        with torch.no_grad():
            return coarse_forward(model, features, graph, tensors).cpu().numpy()

    return run


def torch_detail_fn(model: DetailGenerator, device: torch.device | str = "cpu") -> Callable:
    """A :data:`cloth_usd.core.pipeline.DetailFn` running a torch detail model (no grad)."""
    tensors = Tensors(torch.device(device))

    def run(features: np.ndarray, attributes: np.ndarray, graph: MeshGraph) -> np.ndarray:
        with torch.no_grad():
            return detail_forward(model, features, attributes, graph, tensors).cpu().numpy()

    return run

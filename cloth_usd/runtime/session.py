"""Run an exported model with onnxruntime (never torch).

CUDAExecutionProvider is used when onnxruntime offers it, else the CPU provider.
"""

from __future__ import annotations

import logging
from pathlib import Path
from typing import Any

import numpy as np

from ..errors import ClothUsdError

__all__ = ["ModelSession", "pick_providers"]

log = logging.getLogger(__name__)


def _ort() -> Any:
    try:
        import onnxruntime
    except ImportError as exc:  # pragma: no cover - depends on the environment
        raise ClothUsdError(
            "the learned tiers need onnxruntime: pip install 'cloth-usd[runtime]'") from exc
    return onnxruntime


def pick_providers(*, prefer_gpu: bool = True) -> list[str]:
    """Execution providers in preference order: CUDA (if available and wanted), then CPU."""
    available = _ort().get_available_providers()
    if prefer_gpu and "CUDAExecutionProvider" in available:
        return ["CUDAExecutionProvider", "CPUExecutionProvider"]
    return ["CPUExecutionProvider"]


class ModelSession:
    """One loaded ONNX model.

    Args:
        path: the ``.onnx`` file.
        intra_op_threads: onnxruntime's intra-op thread count (0: its default).
        prefer_gpu: use CUDA when onnxruntime offers it.
        spin: onnxruntime's threads spin, waiting for more work, after a run (its default);
            False: they sleep at once and leave the CPU to what follows the run
            (:data:`~cloth_usd.runtime.bundle.SPINNING_TIERS`).
    """

    def __init__(self, path: str | Path, *, intra_op_threads: int = 0, prefer_gpu: bool = True,
                 spin: bool = True) -> None:
        ort = _ort()
        path = Path(path)
        if not path.is_file():
            raise ClothUsdError(f"model file not found: {path}")
        options = ort.SessionOptions()
        options.intra_op_num_threads = int(intra_op_threads)
        options.add_session_config_entry("session.intra_op.allow_spinning", "1" if spin else "0")
        self.path = path
        self.providers = pick_providers(prefer_gpu=prefer_gpu)
        self._session = ort.InferenceSession(str(path), sess_options=options, providers=self.providers)
        self.input_names = tuple(i.name for i in self._session.get_inputs())
        self.output_names = tuple(o.name for o in self._session.get_outputs())
        log.debug("loaded %s on %s", path, self._session.get_providers())

    def run(self, inputs: dict[str, np.ndarray]) -> dict[str, np.ndarray]:
        """Run one batch; ``inputs`` maps every input name to its array (extra names ignored)."""
        missing = [n for n in self.input_names if n not in inputs]
        if missing:
            raise ClothUsdError(f"{self.path}: missing inputs {missing}; the model takes {list(self.input_names)}")
        out = self._session.run(list(self.output_names), {n: inputs[n] for n in self.input_names})
        return dict(zip(self.output_names, out))

"""Inference with exported ONNX models (onnxruntime only; torch is never imported here).

onnxruntime itself is imported lazily, when a :class:`ModelSession` is made.
"""

from .io import COARSE_INPUTS, DETAIL_INPUTS, OUTPUT, coarse_inputs, detail_inputs
from .session import ModelSession, pick_providers

__all__ = ["COARSE_INPUTS", "DETAIL_INPUTS", "OUTPUT", "coarse_inputs", "detail_inputs",
           "ModelSession", "pick_providers"]

"""Inference with exported ONNX models (onnxruntime only; torch is never imported here).

onnxruntime itself is imported lazily, when a :class:`ModelSession` is made.
"""

from .bundle import ModelBundle, default_bundle_dir, find_bundle, load_bundle, write_bundle
from .garment import LearnedFrames, LearnedGarment
from .io import COARSE_INPUTS, DETAIL_INPUTS, OUTPUT, coarse_inputs, detail_inputs
from .session import ModelSession, pick_providers

__all__ = ["COARSE_INPUTS", "DETAIL_INPUTS", "OUTPUT", "coarse_inputs", "detail_inputs",
           "ModelSession", "pick_providers", "ModelBundle", "load_bundle", "find_bundle",
           "write_bundle", "default_bundle_dir", "LearnedGarment", "LearnedFrames"]

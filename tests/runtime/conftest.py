"""A tiny exported model bundle, built once per test session (needs torch and onnx)."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from bundle_helpers import WIDTH, prepare_model, write_tiny_bundle


@pytest.fixture(scope="session")
def exported_models(tmp_path_factory):
    """``(coarse.onnx, detail.onnx, fit.npz, configs)`` of tiny random models."""
    torch = pytest.importorskip("torch", reason="exporting models needs torch (pip install 'cloth-usd[train]')")
    pytest.importorskip("onnxruntime", reason="the learned tiers need onnxruntime")
    pytest.importorskip("onnx", reason="the torch.onnx exporter needs onnx and onnxscript")
    pytest.importorskip("onnxscript", reason="the torch.onnx exporter needs onnx and onnxscript")
    from dataclasses import asdict

    from cloth_usd.core.fit import FitModel
    from cloth_usd.nn.export import export_coarse, export_detail
    from cloth_usd.nn.models import CoarseConfig, CoarseGenerator, DetailConfig, DetailGenerator

    out = tmp_path_factory.mktemp("exported")
    torch.manual_seed(0)
    cc, dc = CoarseConfig(width=WIDTH), DetailConfig(width=WIDTH)
    coarse, detail = CoarseGenerator(cc).eval(), DetailGenerator(dc).eval()
    prepare_model(coarse, 7, torch)
    prepare_model(detail, 30, torch)
    export_coarse(coarse, out / "coarse.onnx")
    export_detail(detail, out / "detail.onnx")
    rng = np.random.default_rng(0)
    anchors = np.array([412, 1290, 3021, 3500, 4200, 6540], dtype=np.int64)
    FitModel(anchors=anchors, mean=np.full(6, 0.02), loadings=rng.normal(0, 0.01, (6, 3)),
             noise_variance=np.ones(6)).save(out / "fit.npz")
    return out / "coarse.onnx", out / "detail.onnx", out / "fit.npz", {"coarse": asdict(cc), "detail": asdict(dc)}


@pytest.fixture(scope="session")
def tiny_bundle(exported_models, tmp_path_factory) -> Path:
    """A verified-good bundle folder inside a folder of bundles: ``<models>/tiny-tshirt``."""
    return write_tiny_bundle(tmp_path_factory.mktemp("models") / "tiny-tshirt", exported_models)

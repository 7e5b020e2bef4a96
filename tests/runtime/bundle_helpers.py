"""Helpers of the runtime tests: the make_bundle script as a module, tiny bundles."""

from __future__ import annotations

from pathlib import Path

from script_module import ROOT, load_script

WIDTH = 0.125
OUTPUT_SCALE = 0.005  # [m]: random weights give displacements of a few mm


def load_make_bundle():
    """``scripts/make_bundle.py`` as a module (scripts/ is not a package)."""
    return load_script("make_bundle", ROOT / "scripts" / "make_bundle.py")


def prepare_model(model, in_features: int, torch) -> None:
    model.set_statistics(torch.zeros(in_features), torch.ones(in_features), torch.full((3,), OUTPUT_SCALE))
    with torch.no_grad():
        model.head.magnitude[-1].bias.fill_(1.0)  # ReLU would zero a fresh model's magnitude


def write_tiny_bundle(folder: Path, exported, *, name: str = "tiny-tshirt", detail: bool = True) -> Path:
    coarse, det, fit, configs = exported
    return load_make_bundle().make_bundle(
        folder, name=name, category="tshirt", coarse_onnx=coarse, detail_onnx=det if detail else None,
        fit_npz=fit, configs=configs,
        training_data={"manifest_sha256": "0" * 64, "description": "random weights, tests only"},
        metrics={"note": "untrained"}, opset=18)

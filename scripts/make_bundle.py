"""Build a model bundle folder from exported ONNX files, a fit model and metrics.

Usage::

    python scripts/make_bundle.py OUT_DIR --name tshirt-v1 --category tshirt \\
        --coarse coarse.onnx [--detail detail.onnx] --fit fit.npz \\
        [--configs configs.json] [--metrics metrics.json] \\
        [--training-manifest data/manifest.json] [--description TEXT] [--opset 18] [--force]

The work is :func:`cloth_usd.runtime.bundle.write_bundle` (hashes every file, writes
``manifest.json``); this script is its command line. :func:`make_bundle` is the same
function under the name tests and release scripts import.
"""

from __future__ import annotations

import argparse
import hashlib
import json
import sys
from pathlib import Path
from typing import Any, Mapping, Sequence

from cloth_usd.errors import ClothUsdError
from cloth_usd.runtime.bundle import write_bundle

OPSET = 18


def make_bundle(out_dir: str | Path, *, name: str, category: str, coarse_onnx: str | Path,
                detail_onnx: str | Path | None, fit_npz: str | Path, configs: Mapping[str, Any],
                training_data: Mapping[str, Any], metrics: Mapping[str, Any], opset: int = OPSET,
                force: bool = False) -> Path:
    """Write a bundle folder; see :func:`cloth_usd.runtime.bundle.write_bundle`."""
    return write_bundle(out_dir, name=name, category=category, coarse_onnx=coarse_onnx,
                        detail_onnx=detail_onnx, fit_npz=fit_npz, configs=configs,
                        training_data=training_data, metrics=metrics, opset=opset, force=force)


def _json(path: str | None) -> dict:
    return json.loads(Path(path).read_text()) if path else {}


def main(argv: Sequence[str] | None = None) -> int:
    p = argparse.ArgumentParser(prog="make_bundle", description=__doc__.split("\n\n")[0])
    p.add_argument("out_dir", help="bundle folder to create")
    p.add_argument("--name", required=True, help="bundle name, recorded in every cache it bakes")
    p.add_argument("--category", required=True, help="tshirt, dress or trousers")
    p.add_argument("--coarse", required=True, help="exported coarse generator (.onnx)")
    p.add_argument("--detail", help="exported detail generator (.onnx), optional")
    p.add_argument("--fit", required=True, help="fit model (FitModel.save .npz)")
    p.add_argument("--configs", help='JSON file {"coarse": {...}, "detail": {...}} of model configs')
    p.add_argument("--metrics", help="JSON file of validation metrics")
    p.add_argument("--training-manifest", help="the training data set's manifest (its sha256 is recorded)")
    p.add_argument("--description", default="", help="one line about the training data")
    p.add_argument("--opset", type=int, default=OPSET, help=f"ONNX opset of the files (default {OPSET})")
    p.add_argument("--force", action="store_true", help="write into a non-empty folder")
    args = p.parse_args(argv)
    training = {"description": args.description, "manifest_sha256": ""}
    try:
        if args.training_manifest:
            training["manifest_sha256"] = hashlib.sha256(Path(args.training_manifest).read_bytes()).hexdigest()
        out = make_bundle(args.out_dir, name=args.name, category=args.category, coarse_onnx=args.coarse,
                          detail_onnx=args.detail, fit_npz=args.fit, configs=_json(args.configs),
                          training_data=training, metrics=_json(args.metrics), opset=args.opset,
                          force=args.force)
    except (ClothUsdError, OSError, ValueError) as exc:
        sys.stderr.write(f"make_bundle: error: {exc}\n")
        return 2
    sys.stdout.write(f"wrote {out}\n")
    return 0


if __name__ == "__main__":
    sys.exit(main())

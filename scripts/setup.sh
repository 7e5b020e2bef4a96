#!/usr/bin/env bash
# Set up a virtual environment with what baking needs (cloth-usd and onnxruntime for the
# learned tiers, matplotlib for `cloth-usd render`; no torch, no simulator), then bake the
# bundled sample with the detail tier.
# Usage: bash scripts/setup.sh [--no-sample]   (idempotent; VENV=path to choose where the
#        environment lives). scripts/test.sh adds the training and simulation extras.
set -euo pipefail
cd "$(dirname "$0")/.."
VENV=${VENV:-.venv}
PY=${PYTHON:-python3}
if [ ! -x "$VENV/bin/python" ]; then
    "$PY" -m venv "$VENV"
fi
"$VENV/bin/python" -m pip install -q --upgrade pip
"$VENV/bin/python" -m pip install -q -e ".[runtime,preview]"
if [ "${1:-}" != "--no-sample" ]; then
    mkdir -p out
    "$VENV/bin/cloth-usd" bake samples/walk_tshirt/scene.usda -o out/walk_tshirt_cache.usdc \
        --shot out/walk_tshirt_shot.usda --tier detail --force
fi

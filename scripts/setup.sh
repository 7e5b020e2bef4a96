#!/usr/bin/env bash
# Set up a virtual environment with cloth-usd and its dev extras, then bake the bundled sample.
# Usage: bash scripts/setup.sh   (idempotent; VENV=path to choose where the environment lives)
set -euo pipefail
cd "$(dirname "$0")/.."
VENV=${VENV:-.venv}
PY=${PYTHON:-python3}
if [ ! -x "$VENV/bin/python" ]; then
    "$PY" -m venv "$VENV"
fi
"$VENV/bin/python" -m pip install -q --upgrade pip
# torch first, pinned: this machine type carries the 2.13.0 CPU build; any other version
# would download gigabytes of CUDA packages. smplx then finds it satisfied.
"$VENV/bin/python" -m pip install -q "torch==2.13.0"
"$VENV/bin/python" -m pip install -q -e ".[dev]"
if [ "${1:-}" != "--no-sample" ]; then
    mkdir -p out
    "$VENV/bin/cloth-usd" bake samples/walk_tshirt/scene.usda -o out/walk_tshirt_cache.usdc \
        --shot out/walk_tshirt_shot.usda --force
fi

#!/usr/bin/env bash
# Install what the tests need and run them all: the main suite in .venv, then the Blender
# add-on tests in real Blender (bpy) in .venv-blender (bpy pins numpy 1.26 and ships its
# own USD, so it cannot share .venv). This is what CI runs.
# Usage: bash scripts/test.sh [pytest args]
#        CLOTH_USD_SKIP_BLENDER=1 bash scripts/test.sh   # skip the add-on tests locally
set -euo pipefail
cd "$(dirname "$0")/.."
VENV=${VENV:-.venv}
bash scripts/setup.sh --no-sample
# The tests also train, export and simulate: add the dev extras (torch, newton, ray).
# torch first, pinned: this machine type carries the 2.13.0 CPU build; any other version
# would download gigabytes of CUDA packages. smplx then finds it satisfied.
"$VENV/bin/python" -m pip install -q "torch==2.13.0"
"$VENV/bin/python" -m pip install -q -e ".[dev]"
# The game-export tests: the glTF validator, three.js and esbuild (npm), headless chromium.
bash scripts/setup_web.sh
"$VENV/bin/python" -m pytest "$@"
if [ "${CLOTH_USD_SKIP_BLENDER:-0}" != "1" ]; then
    bash scripts/test_addon.sh
fi

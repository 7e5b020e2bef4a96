#!/usr/bin/env bash
# Test the Blender add-on in real Blender: bpy (Blender as a Python module) in its own
# environment, because bpy pins numpy<2 and ships its own USD (pxr), so it cannot share
# .venv (numpy 2, usd-core). Creates the environment when missing, then runs the tests.
# Usage: bash scripts/test_addon.sh [pytest args]   (VENV=path to choose where it lives)
set -euo pipefail
cd "$(dirname "$0")/.."
VENV=${VENV:-.venv-blender}
PY=${PYTHON:-$(command -v python3.11 || command -v python3)}
BPY=5.0.1  # Blender 5.0 as a module: CPython 3.11 only
if [ ! -x "$VENV/bin/python" ]; then
    "$PY" -c 'import sys; sys.exit(sys.version_info[:2] != (3, 11) and "bpy needs Python 3.11; set PYTHON=python3.11")'
    "$PY" -m venv "$VENV"
fi
"$VENV/bin/python" -m pip install -q --upgrade pip
# One resolve, so that bpy's numpy pin holds: bpy, plus what cloth_usd needs that bpy
# lacks (scipy, tqdm, threadpoolctl), plus pytest.
"$VENV/bin/python" -m pip install -q "bpy==$BPY" "scipy>=1.11" "tqdm>=4.60" "threadpoolctl>=3.1" "pytest>=8"
# cloth_usd without its dependencies: usd-core would bring a second pxr; the tests use
# Blender's own, as the add-on does inside Blender.
"$VENV/bin/python" -m pip install -q --no-deps -e .
exec "$VENV/bin/python" -m pytest tests/addon -m blender "$@"

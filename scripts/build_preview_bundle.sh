#!/usr/bin/env bash
# Rebuild cloth_usd/export/assets/preview.bundle.js, the player of `cloth-usd preview`:
# web/preview.js and the parts of three.js it uses (npm, pinned in web/package-lock.json),
# bundled and minified by esbuild. The bundle is committed so that `cloth-usd preview`
# needs only the Python package; this script makes it reproducible (same versions, same
# bytes: tests/export/test_preview.py checks that).
# Usage: bash scripts/build_preview_bundle.sh [OUT.js]
set -euo pipefail
cd "$(dirname "$0")/.."
bash scripts/setup_web.sh --no-browser
OUT=${1:-cloth_usd/export/assets/preview.bundle.js}
THREE_VERSION=$(node -p "require('./web/node_modules/three/package.json').version")
BANNER="/*! cloth-usd preview player (Apache-2.0), built by scripts/build_preview_bundle.sh from web/preview.js.
 * Bundles three.js ${THREE_VERSION} (https://threejs.org), Copyright 2010-2026 Three.js Authors,
 * SPDX-License-Identifier: MIT; its licence text is in cloth_usd/export/assets/LICENSE-three.txt. */"
web/node_modules/.bin/esbuild web/preview.js --bundle --minify --format=iife --target=es2020 \
    --legal-comments=none --log-level=warning "--banner:js=${BANNER}" --outfile="$OUT"

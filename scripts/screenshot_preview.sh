#!/usr/bin/env bash
# A screenshot of `cloth-usd preview`'s page in headless chromium (docs/preview.png:
# bash scripts/screenshot_preview.sh out/walk_tshirt_shot.usda docs/preview.png 40).
# Usage: bash scripts/screenshot_preview.sh SHOT.usda OUT.png [FRAME] [WIDTH,HEIGHT]
set -euo pipefail
SHOT=$1; OUT=$2; FRAME=${3:-1}; SIZE=${4:-960,640}
WORK=$(mktemp -d)
trap 'rm -rf "$WORK"' EXIT
"$(dirname "$0")/../.venv/bin/cloth-usd" preview "$SHOT" -o "$WORK/preview.html"
chromium --headless --no-sandbox --disable-gpu --enable-unsafe-swiftshader --disable-quic --no-first-run \
    --disable-background-networking --disable-component-update --disable-sync --user-data-dir="$WORK/profile" \
    --window-size="$SIZE" --virtual-time-budget=1500 --screenshot="$OUT" "file://$WORK/preview.html#frame=$FRAME" \
    2>/dev/null

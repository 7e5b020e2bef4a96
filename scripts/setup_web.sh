#!/usr/bin/env bash
# What the game-export tests need besides Python, installed only when missing (quick when
# all is there): the npm packages of web/ (gltf-validator, three, esbuild; versions locked
# in web/package-lock.json) and Debian's chromium for the preview page's headless test.
# Usage: bash scripts/setup_web.sh [--no-browser]
set -euo pipefail
cd "$(dirname "$0")/.."
if [ ! -f web/node_modules/.package-lock.json ] || ! cmp -s web/package-lock.json web/node_modules/.lock-installed; then
    (cd web && npm ci --no-audit --no-fund --loglevel=error)
    cp web/package-lock.json web/node_modules/.lock-installed
fi
if [ "${1:-}" != "--no-browser" ] && ! command -v chromium >/dev/null 2>&1; then
    if [ "$(id -u)" = "0" ]; then
        apt-get update -qq && DEBIAN_FRONTEND=noninteractive apt-get install -y -qq chromium >/dev/null
    else
        echo "setup_web.sh: chromium is missing; install Debian's package (apt-get install chromium)" >&2
    fi
fi

#!/usr/bin/env bash
# Install what the tests need (same environment as scripts/setup.sh) and run them.
# Usage: bash scripts/test.sh [pytest args]
set -euo pipefail
cd "$(dirname "$0")/.."
VENV=${VENV:-.venv}
bash scripts/setup.sh --no-sample
exec "$VENV/bin/python" -m pytest "$@"

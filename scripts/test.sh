#!/usr/bin/env bash
# Quick start, second command: installs what is missing, builds, and runs the whole test suite.
# Heavy [slow] cases run in reduced form when CI=true (or GEODRIFT_REDUCED=1).
set -euo pipefail
cd "$(dirname "$0")/.."
scripts/setup.sh "$@"
build=${GEODRIFT_BUILD_DIR:-build}
echo "== running tests"
cd "$build"
ctest --output-on-failure -j "$(nproc)" --timeout 1200

#!/usr/bin/env bash
# Quick start, first command: installs what is missing, builds, and runs the main job on the
# data shipped in data/kitti: a reduced run of the paper's KITTI experiment (sequence 02,
# geo-tag intervals 100 and 300, one simulator seed), writing out/demo/RESULTS.md and plots.
# The full experiment: build/frontends/cli/geodrift experiment --out docs (see docs/RESULTS.md).
set -euo pipefail
cd "$(dirname "$0")/.."
scripts/setup.sh "$@"
build=${GEODRIFT_BUILD_DIR:-build}
out=out/demo
mkdir -p "$(dirname "$out")"
echo "== running: geodrift experiment (reduced) -> $out"
"$build/frontends/cli/geodrift" experiment --sequences 02 --intervals 100,300 --seeds 1 \
  --out "$out" --force
echo "== outputs in $out: $(ls "$out" | tr '\n' ' ')"

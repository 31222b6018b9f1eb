#!/usr/bin/env bash
# Installs the Debian 12 packages geodrift needs (only the missing ones), then configures and
# builds into build/ (or $GEODRIFT_BUILD_DIR).
#   scripts/setup.sh            library, frontends, geodrift command, tests
#   scripts/setup.sh --bench    also Google Benchmark + Ceres (benchmark peer) and bench/
set -euo pipefail
cd "$(dirname "$0")/.."

bench=OFF
for a in "$@"; do
  case "$a" in
    --bench) bench=ON ;;
    *) echo "setup.sh: unknown option '$a' (known: --bench)" >&2; exit 2 ;;
  esac
done

pkgs=(g++ cmake make ccache libeigen3-dev libsuitesparse-dev libopenblas0 libgeographiclib-dev
      libopencv-dev catch2)
[ "$bench" = ON ] && pkgs+=(libbenchmark-dev libceres-dev)

missing=()
for p in "${pkgs[@]}"; do
  dpkg-query -W -f='${Status}' "$p" 2>/dev/null | grep -q "install ok installed" || missing+=("$p")
done
if [ ${#missing[@]} -gt 0 ]; then
  echo "== installing Debian packages: ${missing[*]}"
  if [ "$(id -u)" = 0 ]; then sudo=""
  elif command -v sudo >/dev/null; then sudo="sudo"
  else
    echo "setup.sh: missing packages ${missing[*]} and not root (no sudo): install them first" >&2
    exit 1
  fi
  $sudo apt-get update -qq
  DEBIAN_FRONTEND=noninteractive $sudo apt-get install -y -qq --no-install-recommends \
    "${missing[@]}" >/dev/null
fi

build=${GEODRIFT_BUILD_DIR:-build}
echo "== configuring $build (Release -O2, asserts on, bench=$bench)"
cmake -S . -B "$build" -DCMAKE_BUILD_TYPE=Release -DGEODRIFT_ENABLE_ASSERTS=ON \
  -DGEODRIFT_BUILD_BENCH=$bench ${GEODRIFT_CMAKE_ARGS:-} >"$build.configure.log" 2>&1 || {
  cat "$build.configure.log" >&2; exit 1; }
echo "== building $build"
cmake --build "$build" -j "$(nproc)" || { echo "setup.sh: build failed" >&2; exit 1; }

#!/usr/bin/env bash
# AddressSanitizer + UndefinedBehaviorSanitizer build of everything geodrift compiles (core
# headers through the tests, the frontends, the geodrift command), then:
#   ctest -L fast, ctest -L data, and geodrift simulate -> correct -> eval and
#   geodrift experiment --seeds 1 on the data shipped in data/kitti.
# Any sanitizer finding aborts the process that hit it (-fno-sanitize-recover=all), so the step
# fails and this script exits non-zero. Leaks are reported by LeakSanitizer at exit.
#   scripts/sanitize.sh            build into build-asan/ and run everything
#   GEODRIFT_SANITIZE_JOBS=1 ...   ctest parallelism (default: nproc)
# On 2 cores: about 2 h to build from a cold ccache, then 29 min of tests and commands
# (docs/building.md has the measured figures).
set -euo pipefail
cd "$(dirname "$0")/.."

build=${GEODRIFT_BUILD_DIR:-build-asan}
san="-fsanitize=address,undefined -fno-sanitize-recover=all -fno-omit-frame-pointer"
# CMake takes CXXFLAGS/LDFLAGS as the initial flags of a new build folder; RelWithDebInfo is
# -O2 -g -DNDEBUG (the tests' GEODRIFT_ASSERTs stay on through GEODRIFT_ENABLE_ASSERTS).
CXXFLAGS="$san" LDFLAGS="-fsanitize=address,undefined" GEODRIFT_BUILD_DIR=$build \
  GEODRIFT_CMAKE_ARGS="-DCMAKE_BUILD_TYPE=RelWithDebInfo -DGEODRIFT_SANITIZE=ON" scripts/setup.sh

export ASAN_OPTIONS=${ASAN_OPTIONS:-detect_leaks=1:abort_on_error=1:strict_string_checks=1:detect_stack_use_after_return=1}
export UBSAN_OPTIONS=${UBSAN_OPTIONS:-print_stacktrace=1:halt_on_error=1}
export LSAN_OPTIONS=${LSAN_OPTIONS:-suppressions=$PWD/scripts/lsan.supp:print_suppressions=0}
jobs=${GEODRIFT_SANITIZE_JOBS:-$(nproc)}

start=$(date +%s)
echo "== ctest -L fast (sanitized)"
(cd "$build" && ctest -L fast --output-on-failure -j "$jobs" --timeout 3600)
echo "== ctest -L data (sanitized)"
(cd "$build" && ctest -L data --output-on-failure -j "$jobs" --timeout 3600)

gd="$build/frontends/cli/geodrift"
work=$(mktemp -d "${TMPDIR:-/tmp}/geodrift-sanitize.XXXXXX")
trap 'rm -rf "$work"' EXIT
echo "== geodrift simulate -> correct -> eval (sanitized)"
"$gd" simulate --sequence 02 --frames 0:1500 --interval 100 --seed 1 --out "$work/sim"
"$gd" correct --trajectory "$work/sim/trajectory_kitti.txt" --map "$work/sim/colmap" \
  --anchors "$work/sim/anchors.csv" --out "$work/corrected"
"$gd" correct --trajectory "$work/sim/trajectory_kitti.txt" \
  --anchors "$work/sim/anchors.csv" --out "$work/corrected_traj_only"
"$gd" eval --result "$work/corrected" --ground-truth "$work/sim/ground_truth_kitti.txt" \
  --kitti-to-w
echo "== geodrift experiment --seeds 1 (sanitized)"
"$gd" experiment --sequences 02,08 --intervals 100,300 --seeds 1 --out "$work/experiment"
echo "== sanitize.sh: clean ($(($(date +%s) - start)) s of tests and commands after the build)"

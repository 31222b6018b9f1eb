#!/usr/bin/env bash
# Fuzz every geodrift parser with libFuzzer (docs/fuzzing.md).
#
#   scripts/fuzz.sh [SECONDS] [TARGET ...]
#
# Configures build-fuzz with clang (-DGEODRIFT_FUZZ=ON), builds the fuzzers, runs each for
# SECONDS (default 600) over its corpus tests/fuzz/<target>/ (plus fuzz/<target>.dict when
# present), under `nice -n 10`, at most FUZZ_JOBS (default 2) at a time, then merges the new
# finds back into the minimized corpus (-merge=1). Prints a summary (target, seconds, execs,
# crashes) and exits non-zero on any crash, leak, timeout, out-of-memory or UBSan report; the
# reproducers are left in build-fuzz/artifacts/<target>/.
# Environment: FUZZ_JOBS (parallel fuzzers), FUZZ_BUILD_DIR (default build-fuzz),
# FUZZ_NO_MERGE=1 (leave tests/fuzz/ untouched), FUZZ_NO_BUILD=1 (run the fuzzers already built).
set -euo pipefail

cd "$(dirname "$0")/.."
root=$(pwd)
seconds=${1:-600}
shift || true
jobs=${FUZZ_JOBS:-2}
build=${FUZZ_BUILD_DIR:-build-fuzz}

all_targets=(trajectory_kitti trajectory_tum colmap_cameras colmap_images colmap_points3d anchors
             g2o bal vo_stereo geotag_csv exif calib_text calib_yaml)
targets=("$@")
[ ${#targets[@]} -eq 0 ] && targets=("${all_targets[@]}")

if ! command -v clang++ >/dev/null; then
  echo "fuzz.sh: clang++ not found (apt-get install clang)" >&2
  exit 2
fi
mkdir -p "$build"
if [ "${FUZZ_NO_BUILD:-0}" != 1 ]; then
  cmake -S . -B "$build" -DCMAKE_BUILD_TYPE=RelWithDebInfo -DCMAKE_CXX_COMPILER=clang++ \
    -DCMAKE_C_COMPILER=clang -DGEODRIFT_FUZZ=ON -DGEODRIFT_BUILD_TESTS=OFF -DGEODRIFT_INSTALL=OFF \
    >"$build/configure.log" 2>&1 || { cat "$build/configure.log"; exit 2; }
  build_targets=()
  for t in "${targets[@]}"; do build_targets+=(--target "fuzz_$t"); done
  nice -n 10 cmake --build "$build" -j"$jobs" "${build_targets[@]}"
fi

# Runs one fuzzer; its log goes to $build/logs/<target>.log.
run_one() {
  local t=$1 exe="$build/fuzz/fuzz_$1"
  local work="$build/corpus/$t" art="$build/artifacts/$t/" log="$build/logs/$t.log"
  mkdir -p "$work" "$art" "$root/tests/fuzz/$t" "$build/logs"
  local dict=()
  [ -f "fuzz/$t.dict" ] && dict=(-dict="fuzz/$t.dict")
  # Leak detection stays on (ASan's default); -timeout flags a hang of one input.
  nice -n 10 "$exe" -max_total_time="$seconds" -timeout=10 -rss_limit_mb=2048 \
    -max_len=8192 -print_final_stats=1 -artifact_prefix="$art" "${dict[@]}" \
    "$work" "tests/fuzz/$t" >"$log" 2>&1
}

start=$(date +%s)
declare -A pid_of
for t in "${targets[@]}"; do
  while [ "$(jobs -rp | wc -l)" -ge "$jobs" ]; do sleep 1; done
  echo "fuzz.sh: $t for ${seconds}s ($(date -u +%H:%M:%S) UTC)"
  run_one "$t" &
  pid_of[$t]=$!
done
declare -A rc_of
for t in "${targets[@]}"; do
  set +e
  wait "${pid_of[$t]}"
  rc_of[$t]=$?
  set -e
done

# Merge: the minimized union of the committed corpus and the new finds replaces the corpus
# (only when the fuzzer ended cleanly; a crashing input must not enter it unfixed).
status=0
printf '\n%-18s %8s %12s %8s %8s %s\n' target seconds execs crashes corpus result
for t in "${targets[@]}"; do
  log="$build/logs/$t.log"
  execs=$(sed -n 's/^stat::number_of_executed_units: *//p' "$log" | tail -1)
  secs=$(sed -n 's/^Done [0-9]* runs in \([0-9]*\) second.*/\1/p' "$log" | tail -1)
  crashes=$(find "$build/artifacts/$t" -type f \( -name 'crash-*' -o -name 'leak-*' \
    -o -name 'timeout-*' -o -name 'oom-*' -o -name 'slow-unit-*' \) -newermt "@$start" | wc -l)
  result=ok
  if [ "${rc_of[$t]}" -ne 0 ] || [ "$crashes" -gt 0 ]; then
    result="FAIL (exit ${rc_of[$t]}, log $log)"
    status=1
  elif [ "${FUZZ_NO_MERGE:-0}" != 1 ]; then
    merged="$build/merged/$t"
    rm -rf "$merged" && mkdir -p "$merged"
    nice -n 10 "$build/fuzz/fuzz_$t" -merge=1 -timeout=10 -max_len=8192 "$merged" \
      "tests/fuzz/$t" "$build/corpus/$t" >"$build/logs/$t.merge.log" 2>&1
    # Keep the human-named seeds and reproducers (seed_*, repro_*); replace the hash-named
    # units by the merged set, minus the copies of a named file (libFuzzer names units by SHA-1).
    named=$(find "tests/fuzz/$t" -type f \( -name 'seed_*' -o -name 'repro_*' \) \
      -exec sha1sum {} + | cut -d' ' -f1)
    find "tests/fuzz/$t" -type f ! -name 'seed_*' ! -name 'repro_*' -delete
    for f in "$merged"/*; do
      [ -e "$f" ] || continue
      grep -qx "$(basename "$f")" <<<"$named" || cp "$f" "tests/fuzz/$t/"
    done
  fi
  n=$(find "tests/fuzz/$t" -type f | wc -l)
  printf '%-18s %8s %12s %8s %8s %s\n' "$t" "${secs:-?}" "${execs:-?}" "$crashes" "$n" "$result"
done
exit $status

#!/usr/bin/env bash
# Rebuilds the committed Ceres reference summaries bench/reference/ceres_<graph>.txt: the four
# SE(3) g2o graphs solved by Ceres 2.1 (libceres-dev) from the files' initial values with the
# same residual as geodrift (see ceres_reference.cpp). tests/solver_data compares our solver's
# final cost with the `final_cost` lines.
#   usage: bench/reference/regenerate.sh [data_dir]   (default: <repo>/../shared/data)
set -euo pipefail
here="$(cd "$(dirname "$0")" && pwd)"
repo="$(cd "$here/../.." && pwd)"
data="${1:-$repo/../shared/data}"
build="$repo/build-ceres-reference"
cmake -S "$here" -B "$build" -DCMAKE_BUILD_TYPE=Release > /dev/null
cmake --build "$build" -j2 > /dev/null
for g in sphere2500 parking-garage torus3D cubicle; do
  echo "solving $g"
  "$build/ceres_reference" "$data/pose_graphs_g2o/$g.g2o" 1 > "$here/ceres_$g.txt"
  grep -E '^(final_cost|iterations|termination|total_time_s) ' "$here/ceres_$g.txt"
done

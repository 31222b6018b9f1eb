#!/bin/bash
# Drift correction on the output of a REAL monocular VO (geodrift's own, `geodrift run` without
# --geotags) on rendered street worlds along KITTI ground truth, with anchors taken from the
# renderer's ground truth by the paper's KITTI protocol (DESIGN.md "Evaluation").
#
# Data layout (docs/vo_drift.md says how it was made): DATA/<stretch>/world (`geodrift render`)
# and DATA/<stretch>/vo (`geodrift run --images DATA/<stretch>/world --out DATA/<stretch>/vo`).
# Prints markdown tables on stdout; a progress line on stderr when it is a terminal.
set -euo pipefail

usage() {
  cat <<'EOF'
usage: scripts/vo_drift_experiment.sh [options]

For each stretch and anchor interval N: anchors at frames 50, 100, 150, 200, then every N frames
from 200 + N (positions in W from the rendered ground truth poses.txt, frames as the rendered
dataset numbers them), `geodrift correct` in each mode on the VO keyframes, without and with the
VO's COLMAP map, `geodrift eval --json` against the ground truth. Prints the mean 2D error [m]
(rows = method, columns = interval) plus the global Sim(3) alignment of the uncorrected VO
keyframes, and the unit-invariance check: the same runs with the VO trajectory and map scaled by
each --scales factor, as (scaled - original) mean 2D error.

options
  --data DIR          data folder (default /work/vo_data)
  --stretches LIST    development stretches, comma-separated folder names under DATA
                      (default 02_0000_0899,08_0100_0699)
  --holdout           also run the held-out stretch(es) (--holdout-stretches)
  --holdout-stretches LIST   default 08_2000_2599
  --intervals LIST    anchor intervals N in frames (default 100,200,300)
  --modes LIST        correct modes (default: every mode `geodrift correct --help` lists)
  --sigma M           sigma_m of the anchors (default 0.05)
  --scales LIST       input scale factors for the unit-invariance check (default 0.05,20;
                      "none" skips it)
  --no-map            trajectory-only runs only
  --wrong-anchors F,MIN,MAX
                      also run every cell with wrong geo-tags: a fraction F of the anchors after
                      INIT's four (at least one) shifted by MIN..MAX metres in a random
                      horizontal direction, once per --seeds entry; adds a table of the mean 2D
                      error over the seeds, its ratio to the clean run and to the run over the
                      correct anchors alone (the floor of any screening), and the anchors after
                      INIT the correction left out (wrong / correct)
  --seeds LIST        seeds of the wrong anchors (default 1,2,3,4,5)
  --work DIR          where runs are written (default: a temporary folder, removed at exit)
  --keep              keep the temporary work folder (its path is printed on stderr)
  -h, --help          this text

environment
  GEODRIFT            the geodrift binary (default build/frontends/cli/geodrift of this tree)
EOF
}

die() {
  echo "vo_drift_experiment.sh: error: $*" >&2
  exit 1
}

here=$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)
G=${GEODRIFT:-$here/build/frontends/cli/geodrift}
DATA=/work/vo_data
STRETCHES=02_0000_0899,08_0100_0699
HOLDOUT=0
HOLDOUT_STRETCHES=08_2000_2599
INTERVALS=100,200,300
MODES=
SIGMA=0.05
SCALES=0.05,20
WITH_MAP=1
WRONG=
SEEDS=1,2,3,4,5
WORK=
KEEP=0
# The ASSUMED KITTI geo origin (DESIGN.md): W of `eval --kitti-to-w` and of our anchors.
ORIGIN=49.0110,8.4170,160

need_arg() { if [ $# -lt 2 ] || [ -z "$2" ]; then die "$1 needs a value (see --help)"; fi; }
while [ $# -gt 0 ]; do
  case "$1" in
    --data) need_arg "$@"; DATA=$2; shift 2 ;;
    --stretches) need_arg "$@"; STRETCHES=$2; shift 2 ;;
    --holdout) HOLDOUT=1; shift ;;
    --holdout-stretches) need_arg "$@"; HOLDOUT_STRETCHES=$2; shift 2 ;;
    --intervals) need_arg "$@"; INTERVALS=$2; shift 2 ;;
    --modes) need_arg "$@"; MODES=$2; shift 2 ;;
    --sigma) need_arg "$@"; SIGMA=$2; shift 2 ;;
    --scales) need_arg "$@"; SCALES=$2; shift 2 ;;
    --no-map) WITH_MAP=0; shift ;;
    --wrong-anchors) need_arg "$@"; WRONG=$2; shift 2 ;;
    --seeds) need_arg "$@"; SEEDS=$2; shift 2 ;;
    --work) need_arg "$@"; WORK=$2; shift 2 ;;
    --keep) KEEP=1; shift ;;
    -h | --help) usage; exit 0 ;;
    *) die "unknown argument '$1' (see --help)" ;;
  esac
done

[ -x "$G" ] || die "geodrift binary '$G' not found or not executable (set GEODRIFT=...)"
[ -d "$DATA" ] || die "data folder '$DATA' does not exist (--data)"
command -v python3 > /dev/null || die "python3 is needed (JSON parsing, input scaling)"
[[ $INTERVALS =~ ^[1-9][0-9]*(,[1-9][0-9]*)*$ ]] || die "--intervals '$INTERVALS': positive integers, comma-separated"
[[ $SIGMA =~ ^[0-9]*\.?[0-9]+([eE][-+]?[0-9]+)?$ ]] || die "--sigma '$SIGMA' is not a positive number"
if [ "$SCALES" = none ]; then SCALES=; fi
num='[0-9]*\.?[0-9]+([eE][-+]?[0-9]+)?'
if [ -n "$WRONG" ]; then
  [[ $WRONG =~ ^$num,$num,$num$ ]] || die "--wrong-anchors '$WRONG': F,MIN,MAX (three non-negative numbers)"
  python3 -c 'import sys; f, a, b = map(float, sys.argv[1].split(",")); sys.exit(0 if 0 < f <= 1 and 0 <= a <= b else 1)' "$WRONG" ||
    die "--wrong-anchors '$WRONG': need 0 < F <= 1 and 0 <= MIN <= MAX"
  [[ $SEEDS =~ ^[0-9]+(,[0-9]+)*$ ]] || die "--seeds '$SEEDS': non-negative integers, comma-separated"
fi
for s in ${SCALES//,/ }; do
  [[ $s =~ ^[0-9]*\.?[0-9]+([eE][-+]?[0-9]+)?$ ]] || die "--scales: '$s' is not a positive number"
done

# Modes: --modes, else parsed from `geodrift correct --help` (the --mode entry: "a (..) | b | c",
# possibly continued on the next lines), so modes added later are picked up.
if [ -z "$MODES" ]; then
  MODES=$("$G" correct --help | python3 -c '
import re, sys
lines = sys.stdin.read().splitlines()
text, on = [], False
for l in lines:
    if re.match(r"\s*--mode\s", l):
        on = True
        text.append(re.sub(r"^\s*--mode\s+\S+\s*", "", l))
        continue
    if on:
        if re.match(r"\s*--", l) or not l.strip() or not l.startswith(" "):
            break
        text.append(l.strip())
s = re.sub(r"\([^)]*\)", "", " ".join(text))
modes = [c.split()[0] for c in s.split("|") if c.split()]
modes = [m for m in modes if re.fullmatch(r"[a-z0-9+_-]+", m)]
print(",".join(modes))')
  [ -n "$MODES" ] || die "could not parse the modes from 'geodrift correct --help'; give --modes"
fi

list=$STRETCHES
if [ $HOLDOUT = 1 ]; then list="$list,$HOLDOUT_STRETCHES"; fi
for st in ${list//,/ }; do
  [ -f "$DATA/$st/world/poses.txt" ] || die "$DATA/$st/world/poses.txt missing (render the stretch first)"
  [ -f "$DATA/$st/vo/keyframes_kitti.txt" ] || die "$DATA/$st/vo/keyframes_kitti.txt missing (run the VO first)"
done

if [ -z "$WORK" ]; then
  WORK=$(mktemp -d "${TMPDIR:-/tmp}/vo_drift.XXXXXX")
  if [ $KEEP = 1 ]; then
    echo "vo_drift_experiment.sh: work folder $WORK (kept)" >&2
  else
    trap 'rm -rf "$WORK"' EXIT
  fi
else
  mkdir -p "$WORK"
fi

tty=0
[ -t 2 ] && tty=1
progress() { if [ $tty = 1 ]; then printf '\r\033[K%s' "$*" >&2; fi; }
progress_done() { if [ $tty = 1 ]; then printf '\r\033[K' >&2; fi; }

# Ground truth (rendered poses.txt: KITTI world of the sequence, one row per dataset frame, '#'
# header) -> W (E = x, N = z, U = -y; DESIGN.md), written as KITTI rows after a frame index.
gt_to_w() {
  awk '/^#/ || NF == 0 { next }
       { o = (NF == 13) ? 1 : 0; if (NF != 12 && NF != 13) { print "bad line " NR > "/dev/stderr"; exit 1 }
         for (i = 1; i <= 12; ++i) v[i] = $(i + o)
         printf "%d", n++
         for (i = 1; i <= 4; ++i) printf " %.9g", v[i]
         for (i = 9; i <= 12; ++i) printf " %.9g", v[i]
         for (i = 5; i <= 8; ++i) printf " %.9g", -v[i]
         printf "\n" }' "$1"
}

# Anchors CSV for interval N: protocol frames inside the keyframes' frame range, position = the
# ground-truth camera centre in W (x,y,z; read with --origin = the assumed KITTI origin).
make_anchors() { # gt_w.txt first_kf last_kf N sigma
  awk -v lo="$2" -v hi="$3" -v N="$4" -v sg="$5" '
    BEGIN { n = split("50,100,150,200", init, ","); for (i = 1; i <= n; ++i) want[init[i]] = 1
            print "# geodrift vo_drift_experiment anchors: ground truth of the rendered stretch, W = UTM 32N shifted to the ASSUMED KITTI origin 49.0110N 8.4170E 160 m (metres); protocol interval " N
            print "frame,x,y,z,sigma_m" }
    { f = $1; if (f >= 200 + N && (f - 200) % N == 0) want[f] = 1
      if ((f in want) && f >= lo && f <= hi) printf "%d,%.4f,%.4f,%.4f,%s\n", f, $5, $9, $13, sg }' "$1"
}

# Share of keyframes whose true position lies inside their 95 % ellipse (trajectory.csv's
# sd_east, sd_north, cov_en against the ground truth in W), or "-" without ellipses.
coverage() { # run_dir gt_w.txt
  python3 - "$1" "$2" << 'PY'
import csv, sys
gt = {}
for line in open(sys.argv[2]):
    v = line.split()
    if len(v) == 13 and not line.startswith("#"):
        gt[int(v[0])] = (float(v[4]), float(v[8]))
rows = csv.DictReader(l for l in open(sys.argv[1] + "/trajectory.csv") if not l.startswith("#"))
inside = n = 0
for r in rows:
    f = int(r["frame"])
    if f not in gt or not r.get("sd_east"):
        continue
    dx, dy = float(r["x"]) - gt[f][0], float(r["y"]) - gt[f][1]
    a, b, c = float(r["sd_east"]) ** 2, float(r["sd_north"]) ** 2, float(r["cov_en"])
    q = (b * dx * dx - 2 * c * dx * dy + a * dy * dy) / (a * b - c * c)
    n += 1
    inside += q <= 5.991464547107979  # chi2_2(0.95)
print("%.1f" % (100.0 * inside / n) if n else "-")
PY
}

# Wrong geo-tags: of the anchors after INIT's four, round(F * n) (at least one) chosen at random
# and shifted by MIN..MAX metres in a random horizontal direction (Python's Mersenne Twister,
# seeded by seed and N). Writes the corrupted CSV, the wrong anchors' CSV line numbers and the
# CSV without them.
corrupt_anchors() { # anchors.csv F,MIN,MAX seed N out.csv out.lines (also out_oracle.csv)
  python3 - "$@" << 'PY'
import math, random, sys
src, spec, seed, n_int, out, out_lines = sys.argv[1:7]
f, lo, hi = map(float, spec.split(","))
lines = open(src).read().splitlines()
rows = [i for i, l in enumerate(lines) if l[:1].isdigit()]
after = rows[4:]
rng = random.Random(int(seed) * 100003 + int(n_int))
k = max(1, round(f * len(after))) if after else 0
wrong = sorted(rng.sample(after, k))
for i in wrong:
    fr, x, y, z, sg = lines[i].split(",")
    d, a = rng.uniform(lo, hi), rng.uniform(0, 2 * math.pi)
    lines[i] = "%s,%.4f,%.4f,%s,%s" % (fr, float(x) + d * math.cos(a), float(y) + d * math.sin(a), z, sg)
open(out, "w").write("\n".join(lines) + "\n")
open(out_lines, "w").write(" ".join(str(i + 1) for i in wrong) + "\n")
# The same anchors without the wrong ones: what knowing exactly which are wrong would give.
keep = [l for i, l in enumerate(lines) if i not in set(wrong)]
open(out[:-4] + "_oracle.csv", "w").write("\n".join(keep) + "\n")
PY
}

# Anchors after INIT left out by a run: "<wrong left out> <wrong> <correct left out> <correct>".
left_out() { # report.json wrong.lines
  python3 - "$1" "$2" << 'PY'
import json, sys
anchors = json.load(open(sys.argv[1]))["anchors"]
wrong = set(int(t) for t in open(sys.argv[2]).read().split())
c = [0, 0, 0, 0]
for a in sorted(anchors, key=lambda a: a["line"])[4:]:
    w = a["line"] in wrong
    c[0 if w else 2] += not a["used"]
    c[1 if w else 3] += 1
print(*c)
PY
}

# Scales a KITTI trajectory with a leading frame index (translations: fields 5, 9, 13) and a
# COLMAP text model (images.txt: TX TY TZ of every image line; points3D.txt: X Y Z) by $1.
scale_inputs() { # s traj model_dir_or_empty out_dir
  local s=$1 traj=$2 model=$3 out=$4
  mkdir -p "$out"
  awk -v s="$s" '/^#/ || NF == 0 { print; next }
    { if (NF != 13) { print "scale_inputs: expected 13 fields (frame + 12) at line " NR > "/dev/stderr"; exit 1 }
      $5 *= s; $9 *= s; $13 *= s; print }' OFMT='%.12g' CONVFMT='%.12g' "$traj" > "$out/trajectory.txt"
  if [ -n "$model" ]; then
    mkdir -p "$out/model"
    cp "$model/cameras.txt" "$out/model/cameras.txt"
    # images.txt: after the comments, lines alternate image line / its 2D points (maybe empty).
    awk -v s="$s" 'BEGIN { OFMT = CONVFMT = "%.12g" }
      /^#/ && !started { print; next }
      { started = 1; if (k++ % 2 == 0) { $6 *= s; $7 *= s; $8 *= s } print }' \
      "$model/images.txt" > "$out/model/images.txt"
    awk -v s="$s" 'BEGIN { OFMT = CONVFMT = "%.12g" }
      /^#/ || NF == 0 { print; next } { $2 *= s; $3 *= s; $4 *= s; print }' \
      "$model/points3D.txt" > "$out/model/points3D.txt"
  fi
}

json_get() { # file key -> .key.mean
  python3 -c '
import json, sys
d = json.load(open(sys.argv[1]))
v = d.get(sys.argv[2])
print("nan" if v is None or v.get("mean") is None else "%.6f" % v["mean"])' "$1" "$2"
}

# One correct + eval; prints the mean 2D error or "fail".
run_one() { # dir traj model anchors mode gt_w [extra correct options...]
  local dir=$1 traj=$2 model=$3 anchors=$4 mode=$5 gtw=$6
  shift 6
  rm -f "$dir.eval.log" "$dir.eval.json"
  local args=(correct --trajectory "$traj" --anchors "$anchors" --origin "$ORIGIN" --mode "$mode"
    --out "$dir" --force "$@")
  [ -n "$model" ] && args+=(--map "$model")
  if ! "$G" "${args[@]}" > "$dir.correct.log" 2>&1; then
    # A usage error (e.g. init+ba without a map) means "not applicable", not a failure.
    if grep -q 'usage error' "$dir.correct.log"; then echo n/a; else echo fail; fi
    return
  fi
  if ! "$G" eval --result "$dir" --ground-truth "$gtw" --json > "$dir.eval.json" 2> "$dir.eval.log"; then
    echo fail
    return
  fi
  json_get "$dir.eval.json" error_2d
}

row_label() { if [ "$2" = map ]; then echo "$1 + map"; else echo "$1 (trajectory only)"; fi; }
fmt() { case "$1" in fail | nan | n/a) echo "$1" ;; *) printf '%.2f' "$1" ;; esac; }
diff_cell() { # scaled orig
  case "$1$2" in *fail* | *nan* | *n/a*) echo "–" ;; *) python3 -c 'import sys; print("%+.3f" % (float(sys.argv[1]) - float(sys.argv[2])))' "$1" "$2" ;; esac
}

IFS=, read -r -a intervals <<< "$INTERVALS"
IFS=, read -r -a modes <<< "$MODES"
IFS=, read -r -a scales <<< "$SCALES"
seeds=()
[ -n "$WRONG" ] && IFS=, read -r -a seeds <<< "$SEEDS"
echo "# Drift correction on geodrift's own monocular VO (rendered KITTI stretches)"
echo
echo "geodrift: \`$("$G" --version 2>/dev/null | head -1)\` ($G); anchors: protocol frames 50,100,150,200 then every N from 200+N, ground-truth positions, sigma_m $SIGMA; mean 2D error [m] over the VO keyframes with ground truth; modes: $MODES."
declare -A failures=()
for st in ${list//,/ }; do
  w=$WORK/$st
  mkdir -p "$w"
  gt_to_w "$DATA/$st/world/poses.txt" > "$w/gt_w.txt"
  traj=$DATA/$st/vo/keyframes_kitti.txt
  model=
  if [ $WITH_MAP = 1 ] && [ -f "$DATA/$st/vo/model/images.txt" ]; then model=$DATA/$st/vo/model; fi
  read -r lo hi nkf < <(awk '/^#/ || NF == 0 { next } { if (n == 0) lo = $1; hi = $1; ++n } END { print lo, hi, n }' "$traj")
  "$G" eval --result "$traj" --ground-truth "$w/gt_w.txt" --json > "$w/vo_global.json" 2> "$w/vo_global.log" ||
    die "geodrift eval of the uncorrected VO failed: $(cat "$w/vo_global.log")"
  global=$(json_get "$w/vo_global.json" global_sim3_error_2d)
  for s in "${scales[@]}"; do
    scale_inputs "$s" "$traj" "$model" "$w/scaled_$s"
  done
  declare -A res=()
  variants=(nomap)
  [ -n "$model" ] && variants+=(map)
  total=$(( ${#intervals[@]} * ${#modes[@]} * ${#variants[@]} * (1 + ${#scales[@]} + 2 * ${#seeds[@]}) ))
  done_runs=0
  for N in "${intervals[@]}"; do
    make_anchors "$w/gt_w.txt" "$lo" "$hi" "$N" "$SIGMA" > "$w/anchors_$N.csv"
    for mode in "${modes[@]}"; do
      for v in "${variants[@]}"; do
        for s in 1 "${scales[@]}"; do
          progress "$st: interval $N, $mode, $v, scale $s ($done_runs/$total runs)"
          if [ "$s" = 1 ]; then t=$traj m=$model; else t=$w/scaled_$s/trajectory.txt m=$w/scaled_$s/model; fi
          [ "$v" = nomap ] && m=
          d=$w/run_${N}_${mode}_${v}_$s
          r=$(run_one "$d" "$t" "$m" "$w/anchors_$N.csv" "$mode" "$w/gt_w.txt")
          res[$N,$mode,$v,$s]=$r
          if [ "$s" = 1 ] && [ -f "$d/trajectory.csv" ] && [ "$r" != fail ] && [ "$r" != n/a ]; then
            res[$N,$mode,$v,cov]=$(coverage "$d" "$w/gt_w.txt")
          fi
          if [ "$r" = fail ] || [ "$r" = n/a ]; then
            why=$(cat "$d.correct.log" "$d.eval.log" 2> /dev/null | grep . | tail -n 1 || true)
            why="$st, $mode, ${v/nomap/trajectory only}: ${why:-no message}"
            failures[$why]="${failures[$why]:+${failures[$why]}, }N=$N x$s"
          fi
          done_runs=$((done_runs + 1))
        done
        for seed in "${seeds[@]}"; do
          progress "$st: interval $N, $mode, $v, wrong anchors seed $seed ($done_runs/$total runs)"
          a=$w/anchors_${N}_wrong_$seed
          [ -f "$a.csv" ] || corrupt_anchors "$w/anchors_$N.csv" "$WRONG" "$seed" "$N" "$a.csv" "$a.lines"
          m=$model
          [ "$v" = nomap ] && m=
          d=$w/run_${N}_${mode}_${v}_wrong_$seed
          r=$(run_one "$d" "$traj" "$m" "$a.csv" "$mode" "$w/gt_w.txt")
          res[$N,$mode,$v,wrong,$seed]=$r
          res[$N,$mode,$v,oracle,$seed]=$(run_one "${d}_oracle" "$traj" "$m" "${a}_oracle.csv" "$mode" "$w/gt_w.txt" --no-screen-anchors)
          if [ -f "$d/report.json" ] && [ "$r" != fail ] && [ "$r" != n/a ]; then
            res[$N,$mode,$v,out,$seed]=$(left_out "$d/report.json" "$a.lines")
          elif [ "$r" = fail ]; then
            why=$(cat "$d.correct.log" "$d.eval.log" 2> /dev/null | grep . | tail -n 1 || true)
            why="$st, $mode, ${v/nomap/trajectory only}, wrong anchors: ${why:-no message}"
            failures[$why]="${failures[$why]:+${failures[$why]}, }N=$N seed $seed"
          fi
          done_runs=$((done_runs + 1))
        done
      done
    done
  done
  progress_done
  nanch=$(grep -c '^[0-9]' "$w/anchors_${intervals[0]}.csv")
  echo
  echo "## $st"
  echo
  echo "VO: $nkf keyframes (frames $lo..$hi); map: $([ -n "$model" ] && echo "$model" || echo none); anchors at N=${intervals[0]}: $nanch."
  echo
  head="| method |"; sep="|---|"
  for N in "${intervals[@]}"; do head="$head N=$N |"; sep="$sep---:|"; done
  echo "$head"; echo "$sep"
  for v in "${variants[@]}"; do
    for mode in "${modes[@]}"; do
      row="| $(row_label "$mode" "$v") |"
      for N in "${intervals[@]}"; do row="$row $(fmt "${res[$N,$mode,$v,1]}") |"; done
      echo "$row"
    done
  done
  row="| uncorrected VO, global Sim3 (oracle) |"
  for N in "${intervals[@]}"; do row="$row $(fmt "$global") |"; done
  echo "$row"
  echo
  echo "Uncertainty: keyframes whose true position lies inside their 95 % ellipse [%] (modes that report ellipses):"
  echo
  echo "$head"; echo "$sep"
  for v in "${variants[@]}"; do
    for mode in "${modes[@]}"; do
      row="| $(row_label "$mode" "$v") |" any=0
      for N in "${intervals[@]}"; do
        c=${res[$N,$mode,$v,cov]:--}
        [ "$c" != - ] && any=1
        row="$row $c |"
      done
      [ $any = 1 ] && echo "$row"
    done
  done
  for s in "${scales[@]}"; do
    echo
    echo "Unit invariance: input (trajectory$([ -n "$model" ] && echo " and map")) x $s, (scaled - original) mean 2D error [m]:"
    echo
    echo "$head"; echo "$sep"
    for v in "${variants[@]}"; do
      for mode in "${modes[@]}"; do
        row="| $(row_label "$mode" "$v") |"
        for N in "${intervals[@]}"; do row="$row $(diff_cell "${res[$N,$mode,$v,$s]}" "${res[$N,$mode,$v,1]}") |"; done
        echo "$row"
      done
    done
  done
  if [ ${#seeds[@]} -gt 0 ]; then
    echo
    echo "Wrong anchors ($WRONG: fraction, min, max metres; seeds $SEEDS): mean 2D error [m] over the seeds, (ratio to the clean run / the ratio of the same mode over the correct anchors alone, unscreened: the floor of any screening), and the anchors after INIT left out over all seeds, wrong / correct:"
    echo
    echo "$head"; echo "$sep"
    for v in "${variants[@]}"; do
      for mode in "${modes[@]}"; do
        row="| $(row_label "$mode" "$v") |"
        for N in "${intervals[@]}"; do
          vals=() oracle=() outs=()
          for seed in "${seeds[@]}"; do
            vals+=("${res[$N,$mode,$v,wrong,$seed]}")
            oracle+=("${res[$N,$mode,$v,oracle,$seed]}")
            outs+=("${res[$N,$mode,$v,out,$seed]:-}")
          done
          row="$row $(python3 - "${res[$N,$mode,$v,1]}" "${#seeds[@]}" "${vals[@]}" "${oracle[@]}" "${outs[@]}" << 'PY'
import sys
clean, n = sys.argv[1], int(sys.argv[2])
vals, oracle, outs = sys.argv[3:3 + n], sys.argv[3 + n:3 + 2 * n], sys.argv[3 + 2 * n:3 + 3 * n]
bad = [v for v in vals + oracle if v in ("fail", "nan", "n/a")]
if bad:
    print("n/a" if all(v == "n/a" for v in bad) else "%d runs %s" % (len(bad), bad[0]))
    sys.exit()
mean = sum(map(float, vals)) / n
floor = sum(map(float, oracle)) / n
ok = clean not in ("fail", "nan", "n/a") and float(clean) > 0
ratio = " (%.2fx / %.2fx)" % (mean / float(clean), floor / float(clean)) if ok else ""
c = [0, 0, 0, 0]
for o in outs:
    for i, t in enumerate(o.split()):
        c[i] += int(t)
print("%.2f%s, %d/%d / %d/%d" % (mean, ratio, c[0], c[1], c[2], c[3]))
PY
) |"
        done
        echo "$row"
      done
    done
  fi
  unset res
done
if [ ${#failures[@]} -gt 0 ]; then
  echo
  echo "Runs without a number (cell 'fail', or 'n/a' for a usage error: the mode does not apply):"
  echo
  for f in "${!failures[@]}"; do echo "- $f (${failures[$f]})"; done | sort
fi

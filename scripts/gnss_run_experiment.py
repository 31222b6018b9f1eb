#!/usr/bin/env python3
"""A run of GNSS fixes off together (multipath along a street canyon) on our own VO.

For each stretch (docs/vo_drift.md says how /work/vo_data was made): the VO's keyframes, fixes
every 10 frames from the ground truth with 2 m of horizontal and 3 m of vertical noise
(sigma_m 2), then the same fixes with a run of consecutive ones shifted together (8 fixes by
(25, 15) m, 15 fixes by (-20, 30) m, from the 41st fix on; 6 fixes by (30, -10) m from the
first, a receiver's cold start; the last 10 by (-15, -25) m), and each run's fixes dropped (what
knowing them would give). `geodrift correct` (default screening) and `geodrift eval` against
the ground truth; prints the mean and largest 2D error and the fixes left out.

  GEODRIFT=build/frontends/cli/geodrift scripts/gnss_run_experiment.py \\
      [--data /work/vo_data] [--stretches 02_0000_0899] [--map] [--cases clean] \\
      [--correct-args "--fixed-windows"]

--map corrects with the VO's COLMAP map (<stretch>/vo/model) too; --cases runs only the named
cases (comma-separated: clean, "8 in a row off", ...); --correct-args passes further options to
`geodrift correct`.
"""
import argparse
import json
import os
import random
import subprocess
import sys
import tempfile

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
K = os.path.join(ROOT, "data", "kitti")
# (name, run length, shift, dropped instead, first fix of the run; negative: from the end)
CASES = [("clean", 0, None, False, 0), ("8 in a row off", 8, (25, 15), False, 40),
         ("8 in a row dropped", 8, (25, 15), True, 40),
         ("15 in a row off", 15, (-20, 30), False, 40),
         ("15 in a row dropped", 15, (-20, 30), True, 40),
         ("first 6 off", 6, (30, -10), False, 0), ("first 6 dropped", 6, (30, -10), True, 0),
         ("last 10 off", 10, (-15, -25), False, -10),
         ("last 10 dropped", 10, (-15, -25), True, -10)]


def main():
    ap = argparse.ArgumentParser(description=__doc__,
                                 formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--data", default="/work/vo_data")
    ap.add_argument("--stretches", default="02_0000_0899")
    ap.add_argument("--map", action="store_true")
    ap.add_argument("--cases", default="")
    ap.add_argument("--correct-args", default="")
    a = ap.parse_args()
    g = os.environ.get("GEODRIFT", os.path.join(ROOT, "build", "frontends", "cli", "geodrift"))
    work = tempfile.mkdtemp(prefix="gnss_run_")
    for st in a.stretches.split(","):
        seq, first, last = st[:2], int(st.split("_")[1]), int(st.split("_")[2])
        w = []
        for line in open(f"{K}/poses/{seq}.txt"):
            v = [float(x) for x in line.split()]
            w.append((v[3], v[11], -v[7]))  # W = (x, z, -y) of KITTI's camera frame
        traj = f"{a.data}/{st}/vo/keyframes_kitti.txt"
        if not os.path.exists(traj):
            sys.exit(f"gnss_run_experiment.py: error: {traj} does not exist")
        n = last - first
        gt = f"{work}/{st}_gt.txt"
        open(gt, "w").write("".join(f"{f} 1 0 0 {w[first + f][0]} 0 1 0 {w[first + f][1]} "
                                    f"0 0 1 {w[first + f][2]}\n" for f in range(n)))
        fixes = range(0, n, 10)
        cases = [c for c in CASES if not a.cases or c[0] in a.cases.split(",")]
        for name, length, shift, drop, start in cases:
            start = start if start >= 0 else len(fixes) + start
            rng = random.Random(5)
            rows = ["frame,x,y,z,sigma_m"]
            for i, f in enumerate(fixes):
                x, y, z = w[first + f]
                x, y, z = x + rng.gauss(0, 2), y + rng.gauss(0, 2), z + rng.gauss(0, 3)
                if start <= i < start + length:
                    if drop:
                        continue
                    x, y = x + shift[0], y + shift[1]
                rows.append(f"{f},{x:.3f},{y:.3f},{z:.3f},2")
            an, out = f"{work}/anchors.csv", f"{work}/out"
            open(an, "w").write("\n".join(rows) + "\n")
            r = subprocess.run([g, "correct", "--trajectory", traj, "--anchors", an, "--origin",
                                "49.0110,8.4170,160", "--no-uncertainty", "--out", out, "--force"] +
                               (["--map", f"{a.data}/{st}/vo/model"] if a.map else []) +
                               a.correct_args.split(),
                               capture_output=True, text=True)
            if r.returncode != 0:
                print(f"{st} | {name} | refused: {r.stderr.strip().splitlines()[-1][:100]}")
                continue
            left_out = sum(1 for x in json.load(open(f"{out}/report.json"))["anchors"]
                           if not x["used"])
            e = json.loads(subprocess.run([g, "eval", "--result", out, "--ground-truth", gt,
                                           "--json"], capture_output=True, text=True).stdout)
            print(f"{st} | {name} | mean 2D error {e['error_2d']['mean']:.3f} m, "
                  f"max {e['error_2d']['max']:.2f} m | {left_out} of {len(rows) - 1} fixes left "
                  f"out", flush=True)


if __name__ == "__main__":
    main()

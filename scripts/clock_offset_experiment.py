#!/usr/bin/env python3
"""The anchors' clock check (`geodrift correct`, correction/time_offset.hpp) on our own VO.

For each stretch (docs/vo_drift.md says how /work/vo_data was made): the VO's every-frame
trajectory with KITTI's times, anchors every 25 frames interpolated from the ground truth at
timestamp + offset (0.05 m noise, sigma_m 0.05), `geodrift correct` without and with
`--anchor-time-offset auto`, `geodrift eval` against the ground truth; then the same with 30 % of
the anchors after the first four shifted 20-60 m (seeds 1-3). Prints one line per run.

  GEODRIFT=build/frontends/cli/geodrift scripts/clock_offset_experiment.py \\
      [--data /work/vo_data] [--stretches 08_0100_0699,02_0000_0899,08_2000_2599]
"""
import argparse
import bisect
import json
import math
import os
import random
import subprocess
import sys
import tempfile

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
K = os.path.join(ROOT, "data", "kitti")


def load_gt(seq):
    times = [float(x) for x in open(f"{K}/times/{seq}.txt")]
    w = []
    for line in open(f"{K}/poses/{seq}.txt"):
        v = [float(x) for x in line.split()]
        w.append((v[3], v[11], -v[7]))  # W = (x, z, -y) of KITTI's camera frame
    return times, w


def interp(times, w, t):
    j = min(max(bisect.bisect_right(times, t), 1), len(times) - 1)
    f = (t - times[j - 1]) / (times[j] - times[j - 1])
    return [(1 - f) * w[j - 1][a] + f * w[j][a] for a in range(3)]


def main():
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--data", default="/work/vo_data")
    ap.add_argument("--stretches", default="08_0100_0699,02_0000_0899,08_2000_2599")
    a = ap.parse_args()
    g = os.environ.get("GEODRIFT", os.path.join(ROOT, "build", "frontends", "cli", "geodrift"))
    work = tempfile.mkdtemp(prefix="clock_")
    for st in a.stretches.split(","):
        seq, first = st[:2], int(st.split("_")[1])
        times, w = load_gt(seq)
        src = f"{a.data}/{st}/vo/trajectory_kitti.txt"
        if not os.path.exists(src):
            sys.exit(f"clock_offset_experiment.py: error: {src} does not exist")
        n = sum(1 for line in open(src) if not line.startswith("#"))
        tf = f"{work}/{st}_times.txt"
        open(tf, "w").write("".join(f"{times[first + f]:.6f}\n" for f in range(n)))
        gt = f"{work}/{st}_gt.txt"
        open(gt, "w").write("".join(f"{times[first + f]:.6f} {w[first + f][0]} {w[first + f][1]} "
                                    f"{w[first + f][2]} 0 0 0 1\n" for f in range(n)))
        for wrong_seed in [None, 1, 2, 3]:
            for off in ([0.0, 0.3, -0.5] if wrong_seed is None else [0.0, 0.3]):
                rng, wrng = random.Random(1), random.Random(wrong_seed)
                rows = ["timestamp,x,y,z,sigma_m"]
                for i, f in enumerate(range(10, n - 10, 25)):
                    t = times[first + f]
                    p = [c + 0.05 * rng.gauss(0, 1) for c in interp(times, w, t + off)]
                    if wrong_seed is not None and i >= 4 and wrng.random() < 0.3:
                        d, ang = wrng.uniform(20, 60), wrng.uniform(0, 2 * math.pi)
                        p[0] += d * math.cos(ang)
                        p[1] += d * math.sin(ang)
                    rows.append(f"{t:.6f}," + ",".join(f"{c:.4f}" for c in p) + ",0.05")
                an = f"{work}/anchors.csv"
                open(an, "w").write("\n".join(rows) + "\n")
                line = [st, f"offset {off:+.1f} s", "clean" if wrong_seed is None else f"30 % wrong, seed {wrong_seed}"]
                for extra in ([], ["--anchor-time-offset", "auto"]):
                    out = f"{work}/out"
                    r = subprocess.run([g, "correct", "--trajectory", src, "--times", tf, "--anchors", an,
                                        "--origin", "49,8.4,100", "--no-uncertainty", "--out", out,
                                        "--force"] + extra, capture_output=True, text=True)
                    if r.returncode != 0:
                        line.append("refused: " + r.stderr.strip().splitlines()[-1][:80])
                        break
                    c = json.load(open(f"{out}/report.json"))["anchor_time_offset"]
                    e = subprocess.run([g, "eval", "--result", f"{out}/trajectory_tum.txt",
                                        "--ground-truth", gt, "--json"], capture_output=True, text=True)
                    err = json.loads(e.stdout)["error_2d"]["mean"]
                    if not extra:
                        line.append(f"estimate {c.get('estimate', float('nan')):+.3f} ± {c.get('sd', float('nan')):.3f} s, "
                                    f"statistic {c.get('statistic', 0):.1f}, significant {c.get('significant')}")
                        line.append(f"error {err:.3f} m")
                    else:
                        line.append(f"with auto {err:.3f} m")
                print(" | ".join(line), flush=True)


if __name__ == "__main__":
    main()

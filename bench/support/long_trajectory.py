#!/usr/bin/env python3
"""Writes a long drifting monocular trajectory and its anchors, for the size limits of
`geodrift correct` (issue 25 item 5; BENCHMARKS.md "Limits"). Standard library only.

The true path laps a 2.5 km closed road (four straights, each ending in a 90-degree bend) at a
constant step; the "VO" trajectory is that path with its log-scale drifting as a random walk
(0.2 % per sqrt(m)), in KITTI's camera convention (x right, y down, z forward; camera-to-map,
12 fields per line; map frame = east, -up, north). Anchors: x,y,z in W (east/north/up metres),
sigma_m 0.5 with that much Gaussian noise on each coordinate, every --anchor-every poses from
pose 50.

  long_trajectory.py --poses 10000000 --step 0.1 --anchor-every 2000 --out DIR
"""
import argparse
import math
import os
import random
import sys


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--poses", type=int, required=True)
    ap.add_argument("--step", type=float, default=0.1, help="metres between poses")
    ap.add_argument("--anchor-every", type=int, default=2000)
    ap.add_argument("--seed", type=int, default=1)
    ap.add_argument("--out", required=True)
    a = ap.parse_args()
    if a.poses < 300:
        sys.exit("long_trajectory.py: --poses must be >= 300")
    os.makedirs(a.out, exist_ok=True)
    rnd = random.Random(a.seed)
    lap = 2500.0
    e = n = u = 0.0          # true position (W)
    pe = pn = pu = 0.0       # drifted position
    log_scale = 0.0
    sd = 0.002 * math.sqrt(a.step)
    anchors = []
    path = os.path.join(a.out, "trajectory_kitti.txt")
    with open(path, "w") as f:
        buf = []
        for i in range(a.poses):
            s = i * a.step
            q = (s % lap) / lap * 4.0
            side = math.floor(q)
            bend = min(max((q - side - 0.9) / 0.1, 0.0), 1.0)
            h = (side + bend) * math.pi / 2
            ch, sh = math.cos(h), math.sin(h)
            if i > 0:
                up_new = 2.0 * math.sin(s / 300.0)
                de, dn, du = ch * a.step, sh * a.step, up_new - u
                e, n, u = e + de, n + dn, up_new
                log_scale += rnd.gauss(0.0, sd)
                k = math.exp(log_scale)
                pe, pn, pu = pe + k * de, pn + k * dn, pu + k * du
            else:
                u = 0.0
            if i >= 50 and (i - 50) % a.anchor_every == 0:
                anchors.append((i, e + rnd.gauss(0.0, 0.5), n + rnd.gauss(0.0, 0.5),
                                u + rnd.gauss(0.0, 0.5)))
            # columns of R_mc: right = (sh, 0, -ch), down = (0, 1, 0), forward = (ch, 0, sh)
            buf.append(f"{sh:.6f} 0 {ch:.6f} {pe:.4f} 0 1 0 {-pu:.4f} "
                       f"{-ch:.6f} 0 {sh:.6f} {pn:.4f}\n")
            if len(buf) == 100000:
                f.write("".join(buf))
                buf.clear()
        f.write("".join(buf))
    with open(os.path.join(a.out, "anchors.csv"), "w") as f:
        f.write("frame,x,y,z,sigma_m\n")
        for i, ae, an, au in anchors:
            f.write(f"{i},{ae:.3f},{an:.3f},{au:.3f},0.5\n")
    print(f"{path}: {a.poses} poses, {a.poses * a.step / 1000:.1f} km, {len(anchors)} anchors")


if __name__ == "__main__":
    main()

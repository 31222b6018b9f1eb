#!/usr/bin/env python3
"""Writes a COLMAP text model with one 3D point seen by every image, for the size limits of
`geodrift correct --map` (issue 25 item 5; BENCHMARKS.md "Limits"). Standard library only.

N images drive ahead 1 m apart, weaving 5 m sideways (x = 5 sin(i/200); KITTI camera
convention: x right, y down, z forward; identity rotation), 500 px focal length, 1000x500 images. Each image adds 4 points 15-25 m
ahead, each seen by the next 4 images; one far landmark (1 km beyond the last image) is seen by
all N images, so its track has N entries (a points3D.txt line of about 12*N bytes). Also writes
the KITTI trajectory of the images (frame = line = image name number) and anchors.csv (x,y,z in
W = east/north/up with east = x, north = z, up = -y; sigma_m 0.5, no noise) every
--anchor-every images.

  colmap_long_track.py --images 100000 --out DIR
  geodrift correct --trajectory DIR/trajectory_kitti.txt --map DIR/model \\
      --anchors DIR/anchors.csv --origin 55,13,0 --out DIR/corrected
"""
import argparse
import math
import os
import random
import sys


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--images", type=int, required=True)
    ap.add_argument("--anchor-every", type=int, default=500)
    ap.add_argument("--seed", type=int, default=1)
    ap.add_argument("--out", required=True)
    a = ap.parse_args()
    if a.images < 20:
        sys.exit("colmap_long_track.py: --images must be >= 20")
    n = a.images
    cam_x = [5.0 * math.sin(i / 200.0) for i in range(n)]
    rnd = random.Random(a.seed)
    f, cx, cy = 500.0, 500.0, 250.0
    model = os.path.join(a.out, "model")
    os.makedirs(model, exist_ok=True)

    # Points: id 1 = the far landmark; then 4 per image, seen by images i .. i+3.
    far = (0.0, -20.0, n + 1000.0)
    points = [(1, far, list(range(n)))]
    obs = [[] for _ in range(n)]  # per image: (u, v, point id)
    next_id = 2
    for i in range(n):
        for _ in range(4):
            p = (cam_x[i] + rnd.uniform(-10, 10), rnd.uniform(-3, 1), i + rnd.uniform(15, 25))
            points.append((next_id, p, [j for j in range(i, min(i + 4, n))]))
            next_id += 1
    track_idx = {}  # (point id, image) -> POINT2D_IDX
    for pid, p, seen in points:
        for j in seen:
            d = p[2] - j
            track_idx[(pid, j)] = len(obs[j])
            obs[j].append((cx + f * (p[0] - cam_x[j]) / d, cy + f * p[1] / d, pid))

    with open(os.path.join(model, "cameras.txt"), "w") as out:
        out.write("# CAMERA_ID, MODEL, WIDTH, HEIGHT, PARAMS[]\n")
        out.write(f"1 PINHOLE 1000 500 {f} {f} {cx} {cy}\n")
    with open(os.path.join(model, "images.txt"), "w") as out:
        out.write("# IMAGE_ID, QW, QX, QY, QZ, TX, TY, TZ, CAMERA_ID, NAME\n")
        for i in range(n):
            out.write(f"{i + 1} 1 0 0 0 {-cam_x[i]:.6f} 0 {-float(i)} 1 {i:06d}.png\n")
            out.write(" ".join(f"{u:.3f} {v:.3f} {pid}" for u, v, pid in obs[i]) + "\n")
    with open(os.path.join(model, "points3D.txt"), "w") as out:
        out.write("# POINT3D_ID, X, Y, Z, R, G, B, ERROR, TRACK[] as (IMAGE_ID, POINT2D_IDX)\n")
        for pid, p, seen in points:
            track = " ".join(f"{j + 1} {track_idx[(pid, j)]}" for j in seen)
            out.write(f"{pid} {p[0]:.4f} {p[1]:.4f} {p[2]:.4f} 128 128 128 0.5 {track}\n")
    with open(os.path.join(a.out, "trajectory_kitti.txt"), "w") as out:
        for i in range(n):
            out.write(f"1 0 0 {cam_x[i]:.6f} 0 1 0 0 0 0 1 {float(i)}\n")
    with open(os.path.join(a.out, "anchors.csv"), "w") as out:
        out.write("frame,x,y,z,sigma_m\n")
        for i in range(0, n, a.anchor_every):
            out.write(f"{i},{cam_x[i]:.6f},{float(i)},0,0.5\n")
    print(f"{n} images, {len(points)} points, far landmark seen by {n} images -> {a.out}")


if __name__ == "__main__":
    main()

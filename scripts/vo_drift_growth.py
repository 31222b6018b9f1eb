#!/usr/bin/env python3
"""How a VO's error between two anchors grows with their distance (docs/vo_drift.md).

For every stretch of the path of about L metres (L = 25, 50, ... 800, half-overlapping), a 2D
similarity is put through the VO keyframes at its two ends onto the ground truth (what two
exact anchors do), and the RMS horizontal distance of the keyframes in between from the ground
truth is taken; per L, the RMS over the stretches. The exponent between two lengths says which
error dominates there: about 0.5 for a random walk of the position, 1.5 for a random walk of
heading or log-scale (the drift model's shape), 2 for a drift at a steady rate.

The VO path (KITTI, camera-to-world, leading frame number) is first brought to the ground
truth's frame by the best 3D similarity over all keyframes, so that "horizontal" is the
ground truth's. Standard library only.

usage: scripts/vo_drift_growth.py VO_KITTI GT_W [VO_KITTI GT_W ...]
  VO_KITTI  keyframes_kitti.txt of `geodrift run` (frame r00 r01 r02 tx r10 ... tz)
  GT_W      the ground truth in W as scripts/vo_drift_experiment.sh writes it (gt_w.txt:
            frame r00 r01 r02 x r10 r11 r12 y r20 r21 r22 z, x east, y north)
"""
import math
import sys

LENGTHS = [25, 50, 100, 200, 400, 800]


def die(msg):
    sys.exit(f"vo_drift_growth.py: error: {msg}")


def read_positions(path):
    """frame -> (x, y, z) from a KITTI file with a leading frame number."""
    out = {}
    try:
        with open(path) as f:
            for n, line in enumerate(f, 1):
                if line.startswith("#") or not line.strip():
                    continue
                v = line.split()
                if len(v) != 13:
                    die(f"{path}:{n}: {len(v)} fields, expected 13 (frame + 3x4 pose)")
                try:
                    x = [float(a) for a in v]
                except ValueError:
                    die(f"{path}:{n}: not a number")
                if not all(math.isfinite(a) for a in x):
                    die(f"{path}:{n}: not finite")
                out[int(x[0])] = (x[4], x[8], x[12])
    except OSError as e:
        die(f"cannot read {path}: {e.strerror}")
    return out


def horn_similarity(A, B):
    """s, R, t minimising sum |s R a + t - b|^2 (Horn's quaternion method)."""
    n = len(A)
    ma = [sum(a[k] for a in A) / n for k in range(3)]
    mb = [sum(b[k] for b in B) / n for k in range(3)]
    M = [[0.0] * 3 for _ in range(3)]  # sum (a - ma)(b - mb)^T
    va = 0.0
    for a, b in zip(A, B):
        da = [a[k] - ma[k] for k in range(3)]
        db = [b[k] - mb[k] for k in range(3)]
        va += sum(x * x for x in da)
        for r in range(3):
            for c in range(3):
                M[r][c] += da[r] * db[c]
    (sxx, sxy, sxz), (syx, syy, syz), (szx, szy, szz) = M
    N = [[sxx + syy + szz, syz - szy, szx - sxz, sxy - syx],
         [syz - szy, sxx - syy - szz, sxy + syx, szx + sxz],
         [szx - sxz, sxy + syx, -sxx + syy - szz, syz + szy],
         [sxy - syx, szx + sxz, syz + szy, -sxx - syy + szz]]
    shift = sum(abs(x) for row in N for x in row)  # power iteration on N + shift·I
    q = [1.0, 0.0, 0.0, 0.0]
    for _ in range(500):
        q = [sum((N[r][c] + (shift if r == c else 0.0)) * q[c] for c in range(4)) for r in range(4)]
        norm = math.sqrt(sum(x * x for x in q))
        q = [x / norm for x in q]
    w, x, y, z = q
    R = [[1 - 2 * (y * y + z * z), 2 * (x * y - z * w), 2 * (x * z + y * w)],
         [2 * (x * y + z * w), 1 - 2 * (x * x + z * z), 2 * (y * z - x * w)],
         [2 * (x * z - y * w), 2 * (y * z + x * w), 1 - 2 * (x * x + y * y)]]
    s = sum(R[r][c] * M[c][r] for r in range(3) for c in range(3)) / va
    t = [mb[r] - s * sum(R[r][c] * ma[c] for c in range(3)) for r in range(3)]
    return lambda a: [s * sum(R[r][c] * a[c] for c in range(3)) + t[r] for r in range(3)]


def growth(vo_path, gt_path):
    vo, gt = read_positions(vo_path), read_positions(gt_path)
    frames = sorted(f for f in vo if f in gt)
    if len(frames) < 10:
        die(f"{vo_path} and {gt_path} share {len(frames)} frames (need 10)")
    level = horn_similarity([vo[f] for f in frames], [gt[f] for f in frames])
    V = [complex(*level(vo[f])[:2]) for f in frames]
    G = [complex(*gt[f][:2]) for f in frames]
    s = [0.0]
    for a, b in zip(G, G[1:]):
        s.append(s[-1] + abs(b - a))
    rows = []
    for L in LENGTHS:
        devs, i = [], 0
        while True:
            j = i
            while j < len(frames) and s[j] - s[i] < L:
                j += 1
            if j >= len(frames):
                break
            if j - i >= 2 and abs(V[j] - V[i]) > 0:
                z = (G[j] - G[i]) / (V[j] - V[i])  # the 2D similarity through both ends
                d = [abs(G[i] + z * (V[k] - V[i]) - G[k]) for k in range(i + 1, j)]
                devs.append(math.sqrt(sum(x * x for x in d) / len(d)))
            i += max(1, (j - i) // 2)
        if devs:
            rows.append((L, len(devs), math.sqrt(sum(x * x for x in devs) / len(devs))))
    return s[-1], rows


def main(argv):
    if len(argv) < 2 or len(argv) % 2 or argv[0] in ("-h", "--help"):
        print(__doc__.strip().split("\n\n")[-1])
        return 0 if argv[:1] in (["-h"], ["--help"]) else 2
    results = [(vo_path, *growth(vo_path, gt_path)) for vo_path, gt_path in zip(argv[::2], argv[1::2])]
    print("| path | length | " + " | ".join(f"L={L} m" for L in LENGTHS) + " | exponents |")
    print("|---|---:|" + "---:|" * len(LENGTHS) + "---|")
    for vo_path, total, rows in results:
        by_l = {L: (n, r) for L, n, r in rows}
        cells = [f"{by_l[L][1]:.3f} ({by_l[L][0]})" if L in by_l else "–" for L in LENGTHS]
        exps = [f"{a}→{b}: {math.log(rb / ra) / math.log(b / a):.2f}"
                for (a, _, ra), (b, _, rb) in zip(rows, rows[1:]) if ra > 0 and rb > 0]
        print(f"| {vo_path} | {total:.0f} m | " + " | ".join(cells) + " | " + ", ".join(exps) + " |")
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))

#!/usr/bin/env python3
"""Regenerates the tables of BENCHMARKS.md from the benches' Google Benchmark JSON output.

usage:
  scripts/bench_tables.py                      # print every table (markdown) to stdout
  scripts/bench_tables.py --write BENCHMARKS.md  # replace the generated blocks in place
  scripts/bench_tables.py --check BENCHMARKS.md  # exit 1 if a generated block is out of date
  options: --results DIR (default bench/results, relative to the repository root)

Each table lives in BENCHMARKS.md between `<!-- bench_tables:NAME -->` and
`<!-- /bench_tables:NAME -->`; the text between the markers is this script's output, everything
else in the file is written by hand. Inputs (bench/results/, one file per bench invocation, made
with `--benchmark_out=<file> --benchmark_out_format=json`; the command for each is in its
BENCHMARKS.md section):

  solver_sim3_paired*.json  bench_solver --benchmark_filter=Sim3Drift_Paired (one file per seed)
  solver_cholmod_ba.json    bench_solver, the CHOLMOD-per-step and BA rows with their floors
  solver_se3.json           bench_solver, the SE(3) g2o rows with their floors
  correction.json           bench_correction --benchmark_filter=Correct
  screening.json            bench_correction --benchmark_filter=Screen
  vo.json                   bench_vo
  kvld.json                 bench_kvld
  geotag.json               bench_geotag
  render.json               bench_render

A missing file leaves its block as it is (with --write) and is reported on stderr. Where a case
was repeated, the median aggregate is used; otherwise the single run. Each table ends with a
"Run:" line from the JSON's context (date, load average at the start of the run as Google
Benchmark recorded it, CPUs, and the `commit` / `load` keys passed with --benchmark_context).
Python 3 standard library only.
"""
import argparse
import glob
import json
import os
import re
import sys

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))


# ---- reading ---------------------------------------------------------------------------------

def load(path):
    with open(path) as f:
        data = json.load(f)
    rows = {}
    for b in data["benchmarks"]:
        name = b.get("run_name", b["name"])
        name = re.sub(r"/iterations:\d+|/repeats:\d+|/manual_time|/real_time", "", name)
        if b.get("run_type") == "aggregate":
            if b.get("aggregate_name") != "median":
                continue
            rows[name] = b  # the median wins over single repetitions
        elif name not in rows:
            rows[name] = b
    return data["context"], rows


def run_line(ctx, path, seed=False):
    load_avg = ctx.get("load_avg") or []
    parts = [ctx.get("date", "?")]
    parts.append(f"commit {ctx['commit']}" if "commit" in ctx else "commit not recorded")
    parts.append(f"{ctx.get('num_cpus', '?')} CPUs at {ctx.get('mhz_per_cpu', '?')} MHz")
    if load_avg:
        parts.append("load average at start " + " / ".join(f"{x:.2f}" for x in load_avg))
    if "load" in ctx:
        parts.append(f"load during the run {ctx['load']}")
    if seed and "drift_seed" in ctx:
        parts.append(f"drift seed {ctx['drift_seed']}")
    if "note" in ctx:
        parts.append(ctx["note"])
    return f"Run: {'; '.join(parts)} (`{os.path.relpath(path, ROOT)}`)."


def c(b, key, default=None):
    """Counter or field of a benchmark row."""
    return b.get(key, default)


# ---- formatting ------------------------------------------------------------------------------

def ms(v):
    if v is None:
        return "–"
    return f"{v:,.0f}" if v >= 100 else (f"{v:.1f}" if v >= 10 else f"{v:.2f}")


def ratio(v, digits=2):
    return "–" if v is None else f"{v:.{digits}f}×"


def table(header, rows):
    out = ["| " + " | ".join(header) + " |", "|" + "---|" * len(header)]
    out += ["| " + " | ".join(str(x) for x in r) + " |" for r in rows]
    return out


# ---- the tables ------------------------------------------------------------------------------

def t_sim3_paired(results):
    files = sorted(glob.glob(os.path.join(results, "solver_sim3_paired*.json")))
    if not files:
        return None
    out, notes = [], []
    rows = []
    for path in files:
        ctx, bench = load(path)
        seed = ctx.get("drift_seed", "?")
        for name, b in bench.items():
            m = re.match(r"BM_Sim3Drift_Paired/keyframes:(\d+)/fresh_memory:(\d)", name)
            if not m:
                continue
            kf, fresh = int(m.group(1)), m.group(2) == "1"
            ratios = c(b, "label", "").replace("ratios ", "").replace(" ", " · ")
            ok = c(b, "reached_all") == 1 and c(b, "ceres_converged_all") == 1
            med = c(b, "ratio_median")
            rows.append((int(seed), kf, not fresh, [
                seed, f"{kf // 1000}k", "fresh" if fresh else "reused",
                ms(c(b, "ceres_cpu_ms_median")),
                f"{ms(c(b, 'reach_cpu_ms_median'))} ({c(b, 'reach_iterations_median'):.0f})",
                ratios, f"**{med:.1f}×**", f"{c(b, 'ratio_min'):.1f}×",
                f"{med / 20:.2f}" + ("" if ok else " (a round did not converge/reach)")]))
        notes += ["", run_line(ctx, path, seed=True)]
    rows.sort(key=lambda r: (r[0] != 7, r[:3]))  # seed 7 (the benchmark's default) first
    out += table(["seed", "keyframes", "memory", "Ceres to convergence [ms CPU, median]",
                  "ours to Ceres' cost [ms CPU, median] (iterations)", "per-round ratios",
                  "median", "lowest", "median / 20× target"], [r[3] for r in rows])
    return out + notes


def t_sim3_cholmod(results):
    path = os.path.join(results, "solver_cholmod_ba.json")
    if not os.path.exists(path):
        return None
    ctx, bench = load(path)
    floors = {int(m.group(1)): b for n, b in bench.items()
              if (m := re.match(r"BM_Floor_Sim3Drift/keyframes:(\d+)", n))}
    rows = []
    for name, b in bench.items():
        m = re.match(r"BM_Sim3Drift_(Ours\w*Cholmod)/keyframes:(\d+)/threads:1", name)
        if not m or int(m.group(2)) not in floors:
            continue
        who, kf = m.group(1), int(m.group(2))
        f = floors[kf]
        step, floor = c(b, "cpu_per_step_ms"), c(f, "factor_cpu_ms")
        rows.append((who, kf, [who, f"{kf // 1000}k", f"{c(b, 'lm_iterations'):.0f}",
                               ms(step), ms(floor), f"**{step / floor:.2f}×**", "≤ 1.5×"]))
    rows.sort(key=lambda r: (r[0] != "OursCholmod", r[1]))  # plain LM first
    return table(["row", "keyframes", "LM iterations", "CPU per step [ms]",
                  "one bare CHOLMOD factorisation [ms CPU]", "step / factorisation", "target"],
                 [r[2] for r in rows]) + ["", run_line(ctx, path, seed=True)]


def t_ba(results):
    path = os.path.join(results, "solver_cholmod_ba.json")
    if not os.path.exists(path):
        return None
    ctx, bench = load(path)
    rows = []
    for which, label in ((0, "synthetic 500 × 50k"), (1, "KITTI 00 (77 × 8,069)")):
        ce = bench.get(f"BM_Ba_Ceres/synthetic0_kitti1:{which}/threads:1")
        ou = bench.get(f"BM_Ba_Ours/synthetic0_kitti1:{which}/threads:1")
        fl = bench.get(f"BM_Floor_Ba/synthetic0_kitti1:{which}")
        if not (ce and ou):
            continue
        # CPU per iteration on both sides (Ceres' own per-iteration counter is wall time).
        ce_it = c(ce, "total_cpu_ms") / c(ce, "lm_iterations")
        ou_it = c(ou, "total_cpu_ms") / c(ou, "lm_iterations")
        rows.append([label, f"{ms(c(ce, 'total_cpu_ms'))} ({c(ce, 'lm_iterations'):.0f})",
                     f"{ms(c(ou, 'total_cpu_ms'))} ({c(ou, 'lm_iterations'):.0f})",
                     f"**{c(ce, 'total_cpu_ms') / c(ou, 'total_cpu_ms'):.2f}×**",
                     f"{ms(ce_it)} / {ms(ou_it)}", f"**{ce_it / ou_it:.2f}×**",
                     f"{c(ou, 'cost_vs_ceres'):+.1e}",
                     ms(c(fl, "factor_cpu_ms")) if fl else "–"])
    return table(["problem", "Ceres SPARSE_SCHUR [ms CPU] (iterations)", "ours [ms CPU] (iterations)",
                  "to convergence", "CPU per iteration Ceres / ours [ms]", "per iteration",
                  "our cost / Ceres' − 1", "floor: one CHOLMOD factorisation of the reduced system [ms CPU]"],
                 rows) + ["", run_line(ctx, path)]


GRAPHS = ["sphere2500", "parking-garage", "torus3D", "cubicle"]


def t_se3(results):
    path = os.path.join(results, "solver_se3.json")
    if not os.path.exists(path):
        return None
    ctx, bench = load(path)
    rows = []
    for g, gname in enumerate(GRAPHS):
        ce = bench.get(f"BM_Se3Graph_Ceres/graph:{g}/threads:1")
        ou = bench.get(f"BM_Se3Graph_Ours/graph:{g}/threads:1")
        fl = bench.get(f"BM_Floor_Se3Graph/graph:{g}")
        if not (ce and ou):
            continue
        reach = c(ou, "reach_ratio_cpu")
        rows.append([gname, f"{ms(c(ce, 'total_cpu_ms'))} ({c(ce, 'lm_iterations'):.0f})",
                     f"{ms(c(ou, 'total_cpu_ms'))} ({c(ou, 'lm_iterations'):.0f})",
                     f"**{c(ou, 'ceres_ratio_cpu'):.2f}×**",
                     f"{ratio(reach)} ({c(ou, 'reach_iterations', 0):.0f})" if reach else "–",
                     f"{c(ou, 'cost_vs_ceres'):+.1e}",
                     f"{ms(c(ou, 'cpu_per_iteration_ms'))} / {ms(c(fl, 'block_factor_ms'))} / "
                     f"{ms(c(fl, 'factor_cpu_ms'))}" if fl else "–"])
    return table(["graph", "Ceres [ms CPU] (iterations)", "ours [ms CPU] (iterations)",
                  "to convergence", "to Ceres' cost ×1.001 (iterations)", "our cost / Ceres' − 1",
                  "ours per iteration / floors: block Cholesky, CHOLMOD factorisation [ms]"],
                 rows) + ["", run_line(ctx, path)]


def t_correction(results):
    path = os.path.join(results, "correction.json")
    if not os.path.exists(path):
        return None
    ctx, bench = load(path)
    # Rows by their label (correction::to_string(mode) + the peer's suffix), not by the enum's
    # numeric arguments.
    order = [("init+pgo", "init+pgo"), ("ours", "ours (defaults: two-pass BA)"),
             ("ours (one-pass BA)", "peer: ours, one-pass BA (round-3 defaults)"),
             ("ours (local scale 0.08)", "ours, local scale offsets SD 0.08"),
             ("ours (before)", "peer: ours, round-1 options"), ("batch", "full batch")]
    by_label = {c(b, "label"): b for n, b in bench.items()
                if n.startswith("BM_Correct_Kitti02_Interval100/")}
    ours = by_label.get("ours")
    rows = []
    for key, label in order:
        b = by_label.get(key)
        if not b:
            continue
        rel = c(b, "cpu_time") / c(ours, "cpu_time") if ours else None
        ba = (f"{c(b, 'ba_s'):.2f} s ({c(b, 'ba_eval_s'):.2f} / {c(b, 'ba_factor_s'):.2f} / "
              f"{c(b, 'ba_setup_s'):.2f})") if c(b, "ba_iterations") else "–"
        rows.append([label, ms(c(b, "cpu_time")), ratio(rel), f"{c(b, 'correction_s'):.3f} s",
                     f"{c(b, 'pgo_s'):.3f} s", ba,
                     f"{c(b, 'pgo_iterations'):.0f} / {c(b, 'ba_iterations'):.0f}",
                     f"{c(b, 'mean_2d_error_m'):.3f} m"])
    return table(["mode", "CPU per sequence [ms]", "CPU / ours", "correction_s (wall)", "pgo_s",
                  "ba_s (eval / factor / setup)", "PGO / BA iterations", "mean 2D error"],
                 rows) + ["", run_line(ctx, path)]


def t_vo(results):
    path = os.path.join(results, "vo.json")
    if not os.path.exists(path):
        return None
    ctx, bench = load(path)
    labels = {"BM_Vo_Sequence/1/0": "VO, BA 1 thread, synchronous",
              "BM_Vo_Sequence/1/1": "VO, BA 1 thread, pipelined (default)",
              "BM_Vo_Sequence/2/1": "VO, BA 2 threads, pipelined",
              "BM_Vo_OrbOnly/15": "floor: ORB alone, oversample 1.5 (as the VO uses it)",
              "BM_Vo_OrbOnly/10": "ORB alone, oversample 1.0",
              "BM_Vo_OrbOnly/20": "ORB alone, oversample 2.0",
              "BM_Vo_OrbOnly/30": "ORB alone, oversample 3.0 (round-1 VO)"}
    floor = bench.get("BM_Vo_OrbOnly/15")
    rows = []
    for name, label in labels.items():
        b = bench.get(name)
        if not b:
            continue
        cpu = c(b, "ms_cpu_all_threads")
        stages = "–"
        if c(b, "ms_features") is not None:
            stages = " / ".join(f"{c(b, k):.1f}" for k in
                                ("ms_features", "ms_tracking", "ms_triangulation", "ms_local_ba"))
        kf = f"{c(b, 'tracked'):.0f} / {c(b, 'keyframes'):.0f}" if c(b, "keyframes") else "–"
        rows.append([label, f"**{c(b, 'frames_per_s'):.1f}**", f"{cpu:.1f}",
                     ratio(cpu / c(floor, "ms_cpu_all_threads")) if floor else "–", stages, kf])
    return table(["case (150 frames)", "frames/s (wall)", "CPU ms / frame (all threads)",
                  "CPU / ORB floor", "wall ms / frame: features / tracking / triangulation / local BA",
                  "tracked / keyframes"], rows) + ["", run_line(ctx, path)]


def t_kvld(results):
    path = os.path.join(results, "kvld.json")
    if not os.path.exists(path):
        return None
    ctx, bench = load(path)
    orb = bench.get("BM_Orb_DetectCompute")
    rows = []
    for name, b in bench.items():
        m = re.match(r"BM_Kvld_Filter/(\d+)", name)
        if m:
            label = f"K-VLD, {int(m.group(1)):,} putative matches"
            extra = (f"kept {c(b, 'kept'):.0f}, {c(b, 'vld_pairs'):,.0f} VLD pairs of "
                     f"{c(b, 'tested_pairs'):,.0f} tested, {c(b, 'runs'):.0f} run(s)")
        elif name == "BM_Kvld_ImageScale":
            label, extra = "peer: ImageScale of one 1241×376 image", f"{c(b, 'levels'):.0f} levels"
        elif name == "BM_Orb_DetectCompute":
            label, extra = "peer: ORB detect + compute, one frame", f"{c(b, 'keypoints'):,.0f} keypoints"
        else:
            continue
        rows.append((name, [label, ms(c(b, "real_time")), f"**{ms(c(b, 'cpu_time'))}**",
                            ratio(c(b, "cpu_time") / c(orb, "cpu_time")) if orb else "–", extra]))
    rows.sort(key=lambda r: (not r[0].startswith("BM_Kvld_Filter"),
                             int(re.sub(r"\D", "", r[0]) or 0)))
    return table(["case", "wall [ms]", "CPU [ms]", "CPU / ORB", "counters"],
                 [r[1] for r in rows]) + ["", run_line(ctx, path)]


def t_geotag(results):
    path = os.path.join(results, "geotag.json")
    if not os.path.exists(path):
        return None
    ctx, bench = load(path)
    pairs = [("putative ORB matching, 2,000 × 2,000 (ratio 0.8 + mutual)", "BM_Match_Ours",
              "BM_Match_BFMatcherPeer", "OpenCV BFMatcher knn + reverse match", "matches"),
             ("RootSIFT for retrieval, one 1241×376 image", "BM_RootSift/50", "BM_RootSift/100",
              "full resolution (retrieval_scale 1)", "features"),
             ("one view cut from a 2048×1024 panorama", "BM_CutView_Cutter", "BM_CutView_PerView",
              "cut_panorama_view (tables per view)", None)]
    rows = []
    for label, ours, peer, peer_label, counter in pairs:
        a, b = bench.get(ours), bench.get(peer)
        if not a or not b:
            continue
        counts = (f"{c(a, counter):,.0f} / {c(b, counter):,.0f}" if counter else "–")
        rows.append([label, f"**{ms(c(a, 'cpu_time'))}**", peer_label, ms(c(b, "cpu_time")),
                     f"**{c(b, 'cpu_time') / c(a, 'cpu_time'):.1f}×**", counts])
    orb = bench.get("BM_Orb_2000")
    if orb:
        rows.append(["reference: ORB detect + compute, 2,000 features, same image",
                     ms(c(orb, "cpu_time")), "–", "–", "–", "–"])
    return table(["step", "ours [ms CPU]", "peer / previous method", "peer [ms CPU]",
                  "speed-up", "counts (ours / peer)"], rows) + ["", run_line(ctx, path)]


def t_render(results):
    path = os.path.join(results, "render.json")
    if not os.path.exists(path):
        return None
    ctx, bench = load(path)
    floor = bench.get("BM_DepthFloor/2")
    labels = [("BM_Frame/2/1", "frame, adaptive quincunx (default), 2 threads"),
              ("BM_Frame/1/1", "frame, adaptive quincunx, 1 thread"),
              ("BM_Frame/2/0", "frame, 1 ray per pixel, 2 threads"),
              ("BM_Frame/2/2", "frame, 2×2 grid, 2 threads"),
              ("BM_DepthFloor/2", "floor: depth render (1 ray/px, no shading), 2 threads"),
              ("BM_DepthFloor/1", "floor: depth render, 1 thread"),
              ("BM_PngEncodeFrame", "PNG encoding of a frame"),
              ("BM_Panorama/2", "panorama 2048 × 1024, adaptive quincunx, 2 threads"),
              ("BM_WorldBuild", "world construction (300 frames + margins)")]
    rows = []
    for name, label in labels:
        b = bench.get(name)
        if not b:
            continue
        pc = c(b, "process_cpu_ms")
        rel = pc / c(floor, "process_cpu_ms") if (floor and pc and name.startswith(("BM_Frame", "BM_Depth"))) else None
        rows.append([label, ms(c(b, "real_time")), f"**{ms(pc)}**" if pc else ms(c(b, "cpu_time")),
                     ratio(rel)])
    return table(["case", "wall [ms]", "process CPU [ms] (all threads)", "CPU / depth floor"],
                 rows) + ["", run_line(ctx, path)]


def t_screening(results):
    path = os.path.join(results, "screening.json")
    if not os.path.exists(path):
        return None
    ctx, bench = load(path)
    rows = []
    for interval in (10, 2):
        floor = bench.get(f"BM_Screen_DenseFixes/{interval}/0")
        full = bench.get(f"BM_Screen_DenseFixes/{interval}/1")
        if not floor or not full:
            continue
        for b, label in ((floor, "no run test (floor)"), (full, "defaults (run test)")):
            rel = c(b, "cpu_time") / c(floor, "cpu_time")
            rows.append([f"every {interval} frames: {c(b, 'fixes'):.0f} fixes on "
                         f"{c(b, 'keyframes'):.0f} keyframes", label, ms(c(b, "cpu_time")),
                         ratio(rel), f"{c(b, 'rounds'):.0f}", f"{c(b, 'left_out'):.0f}"])
    if not rows:
        return None
    return table(["fixes", "screening", "CPU [ms]", "CPU / floor", "rounds", "left out"],
                 rows) + ["", run_line(ctx, path)]


TABLES = {
    "sim3_paired": t_sim3_paired,
    "sim3_cholmod": t_sim3_cholmod,
    "ba": t_ba,
    "se3": t_se3,
    "correction": t_correction,
    "screening": t_screening,
    "vo": t_vo,
    "kvld": t_kvld,
    "geotag": t_geotag,
    "render": t_render,
}


def main():
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--results", default=os.path.join(ROOT, "bench", "results"))
    g = ap.add_mutually_exclusive_group()
    g.add_argument("--write", metavar="MD")
    g.add_argument("--check", metavar="MD")
    args = ap.parse_args()

    generated = {}
    for name, fn in TABLES.items():
        try:
            lines = fn(args.results)
        except (ValueError, KeyError, TypeError, ZeroDivisionError) as e:  # a partial or odd file
            print(f"bench_tables: '{name}' skipped: {type(e).__name__}: {e}", file=sys.stderr)
            continue
        if lines is None:
            print(f"bench_tables: no input for '{name}' in {args.results}", file=sys.stderr)
        else:
            generated[name] = "\n".join(lines)

    md = args.write or args.check
    if not md:
        for name, text in generated.items():
            print(f"<!-- bench_tables:{name} -->\n{text}\n<!-- /bench_tables:{name} -->\n")
        return 0
    with open(md) as f:
        doc = f.read()
    new, missing = doc, []
    for name, text in generated.items():
        pat = re.compile(rf"(<!-- bench_tables:{name} -->\n)(?:.*?\n)?(<!-- /bench_tables:{name} -->)",
                         re.S)
        if not pat.search(new):
            missing.append(name)
            continue
        new = pat.sub(lambda m: m.group(1) + text + "\n" + m.group(2), new)
    for name in missing:
        print(f"bench_tables: {md} has no block for '{name}'", file=sys.stderr)
    rc = 1 if missing else 0
    if args.check:
        if new != doc:
            print(f"bench_tables: {md} is out of date; run scripts/bench_tables.py --write {md}",
                  file=sys.stderr)
            return 1
        return rc
    if new != doc:
        with open(md, "w") as f:
            f.write(new)
    return rc


if __name__ == "__main__":
    sys.exit(main())

#!/usr/bin/env python3
"""Turns bench_solver JSON output (one or more files) into the markdown tables of BENCHMARKS.md.

usage: bench/support/benchmarks_table.py run1.json [run2.json ...]
Uses the median aggregate when a case was repeated, the single run otherwise. CPU columns are
the process CPU time of the solve (std::clock, counter total_cpu_ms), wall columns the manual
time. "reach" = the first iteration whose cost is <= 1.001 x Ceres' final cost of the same run.
"""
import json
import re
import sys

rows = {}
for path in sys.argv[1:]:
    with open(path) as f:
        data = json.load(f)
    for b in data["benchmarks"]:
        name = b["run_name"] if "run_name" in b else b["name"]
        name = re.sub(r"/iterations:\d+|/manual_time", "", name)
        if b.get("run_type") == "aggregate" and b.get("aggregate_name") != "median":
            continue
        if b.get("run_type") == "aggregate" or name not in rows:
            rows[name] = b

GRAPHS = ["sphere2500", "parking-garage", "torus3D", "cubicle"]


def which_of(kind, arg):
    if kind == "Se3Graph":
        return GRAPHS[arg]
    if kind == "Ba":
        return "synthetic 500x50k" if arg == 0 else "KITTI 00"
    return f"{arg} kf"


def case_of(name):
    m = re.match(r"BM_(\w+?)_(OursCholmod|Ours|Ceres)/(\w+):(\d+)/threads:(\d+)", name)
    if not m:
        return None
    kind, who, _, arg, threads = m.groups()
    return kind, which_of(kind, int(arg)), who, int(threads)


def fmt_ms(v):
    return f"{v:,.0f}" if v >= 100 else f"{v:.1f}"


floors = {}
for name, b in rows.items():
    m = re.match(r"BM_Floor_(\w+)/(\w+):(\d+)", name)
    if m:
        kind, _, arg = m.groups()
        floors[(kind, which_of(kind, int(arg)))] = b

cases = {}
for name, b in rows.items():
    c = case_of(name)
    if c:
        kind, which, who, threads = c
        cases.setdefault((kind, which, threads), {})[who] = b

order = {"Se3Graph": 0, "Sim3Drift": 1, "Ba": 2}


def sort_key(k):
    kind, which, threads = k
    num = re.match(r"(\d+)", which)
    return (order[kind], int(num.group(1)) if num else which, threads)


def cpu(b):
    return b.get("total_cpu_ms", b["cpu_time"])


def solver_of(b):
    return b.get("label", "").split(":")[0] or "?"


print("| problem | threads | ours: solver | wall [ms] | CPU [ms] | iters | CPU ms/iter | final cost "
      "| reach: iter | wall [ms] | CPU [ms] "
      "| Ceres: wall [ms] | CPU [ms] | iters | CPU ms/iter | final cost "
      "| speed-up to convergence wall (CPU) | speed-up to reach wall (CPU) | cost ours/Ceres − 1 |")
print("|---|---|---|---|---|---|---|---|---|---|---|---|---|---|---|---|---|---|---|")
for k in sorted(cases, key=sort_key):
    kind, which, threads = k
    c = cases[k].get("Ceres")
    for who in ("Ours", "OursCholmod"):
        o = cases[k].get(who)
        if not o:
            continue
        cells = [f"{kind} {which}", str(threads), solver_of(o)]
        cells += [fmt_ms(o["real_time"]), fmt_ms(cpu(o)), str(int(o["lm_iterations"])),
                  f"{cpu(o) / o['lm_iterations']:.1f}", f"{o['final_cost']:.6g}"]
        if "reach_iterations" in o:
            cells += [str(int(o["reach_iterations"])), fmt_ms(o["reach_ms"]),
                      fmt_ms(o["reach_cpu_ms"])]
        else:
            cells += ["–", "–", "–"]
        if c:
            cells += [fmt_ms(c["real_time"]), fmt_ms(cpu(c)), str(int(c["lm_iterations"])),
                      f"{cpu(c) / c['lm_iterations']:.1f}", f"{c['final_cost']:.6g}",
                      f"{c['real_time'] / o['real_time']:.2f}× ({cpu(c) / cpu(o):.2f}×)"]
            if "reach_ms" in o:
                cells += [f"{c['real_time'] / o['reach_ms']:.2f}× "
                          f"({cpu(c) / o['reach_cpu_ms']:.2f}×)"]
            else:
                cells += ["–"]
            cells += [f"{o['final_cost'] / c['final_cost'] - 1:+.1e}"]
        else:
            cells += ["–"] * 8
        print("| " + " | ".join(cells) + " |")

print()
print("| problem | ours: solver | per iteration [ms] | factorize/iter [ms] | CHOLMOD floor [ms] "
      "| CHOLMOD GFlop/s | block floor [ms] | block GFlop/s | CHOLMOD ÷ block floor "
      "| iteration ÷ CHOLMOD floor | factorize/iter ÷ CHOLMOD floor |")
print("|---|---|---|---|---|---|---|---|---|---|---|")
for k in sorted(cases, key=sort_key):
    kind, which, threads = k
    fl = floors.get((kind, which))
    if threads != 1 or not fl:
        continue
    for who in ("Ours", "OursCholmod"):
        o = cases[k].get(who)
        if not o:
            continue
        it = o["time_per_iteration_ms"]
        fi = o["factorize_ms"] / o["lm_iterations"]
        cells = [f"{kind} {which}", solver_of(o), f"{it:.1f}", f"{fi:.1f}",
                 f"{fl['factor_ms']:.1f}", f"{fl['gflops']:.2f}"]
        if "block_factor_ms" in fl:
            cells += [f"{fl['block_factor_ms']:.1f}", f"{fl['block_gflops']:.2f}",
                      f"{fl['factor_ms'] / fl['block_factor_ms']:.2f}×"]
        else:
            cells += ["–", "–", "–"]
        cells += [f"{it / fl['factor_ms']:.2f}", f"{fi / fl['factor_ms']:.2f}"]
        print("| " + " | ".join(cells) + " |")

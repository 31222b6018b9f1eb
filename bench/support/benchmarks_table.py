#!/usr/bin/env python3
"""Turns bench_solver JSON output (one or more files) into the markdown table of BENCHMARKS.md.

usage: bench/support/benchmarks_table.py run1.json [run2.json ...]
Uses the median aggregate when a case was repeated, the single run otherwise.
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


def case_of(name):
    m = re.match(r"BM_(\w+?)_(Ours|Ceres)/(\w+):(\d+)/threads:(\d+)", name)
    if not m:
        return None
    kind, who, argname, arg, threads = m.groups()
    arg = int(arg)
    if kind == "Se3Graph":
        which = GRAPHS[arg]
    elif kind == "Ba":
        which = "synthetic 500x50k" if arg == 0 else "KITTI 00"
    else:
        which = f"{arg} kf"
    return kind, which, who, int(threads)


def fmt_ms(v):
    return f"{v:,.0f}" if v >= 100 else f"{v:.1f}"


floors = {}
for name, b in rows.items():
    m = re.match(r"BM_Floor_(\w+)/(\w+):(\d+)", name)
    if m:
        kind, _, arg = m.groups()
        arg = int(arg)
        key = (
            {"Se3Graph": "Se3Graph", "Sim3Drift": "Sim3Drift", "Ba": "Ba"}[kind],
            GRAPHS[arg] if kind == "Se3Graph" else
            ("synthetic 500x50k" if arg == 0 else "KITTI 00") if kind == "Ba" else f"{arg} kf",
        )
        floors[key] = b

cases = {}
for name, b in rows.items():
    c = case_of(name)
    if c:
        kind, which, who, threads = c
        cases.setdefault((kind, which, threads), {})[who] = b

print("| problem | threads | ours: wall [ms] | CPU [ms] | iters | ms/iter | final cost "
      "| Ceres: wall [ms] | CPU [ms] | iters | ms/iter | final cost "
      "| speed-up wall (CPU) | cost ours/Ceres − 1 | CHOLMOD floor [ms] | ours factorize/iter ÷ floor |")
print("|---|---|---|---|---|---|---|---|---|---|---|---|---|---|---|---|")
order = {"Se3Graph": 0, "Sim3Drift": 1, "Ba": 2}


def sort_key(k):
    kind, which, threads = k
    num = re.match(r"(\d+)", which)
    return (order[kind], int(num.group(1)) if num else which, threads)


for k in sorted(cases, key=sort_key):
    kind, which, threads = k
    o, c = cases[k].get("Ours"), cases[k].get("Ceres")
    fl = floors.get((kind, which))
    cells = [f"{kind} {which}", str(threads)]
    for b in (o, c):
        if b:
            cells += [fmt_ms(b["real_time"]), fmt_ms(b["cpu_time"]), str(int(b["lm_iterations"])),
                      f"{b['time_per_iteration_ms']:.1f}", f"{b['final_cost']:.6g}"]
        else:
            cells += ["–", "–", "–", "–", "–"]
    if o and c:
        cells += [f"{c['real_time'] / o['real_time']:.2f}× ({c['cpu_time'] / o['cpu_time']:.2f}×)",
                  f"{o['final_cost'] / c['final_cost'] - 1:+.1e}"]
    else:
        cells += ["–", "–"]
    if fl:
        cells += [f"{fl['factor_ms']:.1f}",
                  f"{o['factorize_ms'] / o['lm_iterations'] / fl['factor_ms']:.2f}" if o else "–"]
    else:
        cells += ["–", "–"]
    print("| " + " | ".join(cells) + " |")

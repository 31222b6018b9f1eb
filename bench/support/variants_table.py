#!/usr/bin/env python3
"""bench_solver JSON -> the "Round 4" table of BENCHMARKS.md: every solver variant of every
problem, with the time to reach each Ceres variant's final cost (within 0.1 %) and the ratios.

usage: bench/support/variants_table.py run1.json [run2.json ...]
Variants: Ceres (its defaults, initial trust-region radius 1e4), CeresLowDamping (radius 1e8),
Ours (bench defaults), OursCholmod, OursAccel (geodesic acceleration), OursLowDamping
(lambda0 = 1e-8), OursAccelLowDamping, OursAccelLowDampingCholmod. CPU = process CPU time of the
solve (counter total_cpu_ms); reach = the first iteration of our trace whose cost is
<= 1.001 x the final cost of the Ceres row with the same initial damping (counters reach_*).
"vs Ceres' defaults" divides the default Ceres row's CPU time by that same reach time; for the
low-damping rows this is conservative (their target, the low-damping Ceres cost, is the lower
of the two Ceres costs in every run so far). A low-damping row in a run without
CeresLowDamping shows its reach of the default Ceres row's cost (counters reach_default_*).
"""
import json
import re
import sys

rows = {}
for path in sys.argv[1:]:
    with open(path) as f:
        for b in json.load(f)["benchmarks"]:
            name = re.sub(r"/iterations:\d+|/manual_time", "", b.get("run_name", b["name"]))
            if b.get("run_type") == "aggregate" and b.get("aggregate_name") != "median":
                continue
            if b.get("run_type") == "aggregate" or name not in rows:
                rows[name] = b

GRAPHS = ["sphere2500", "parking-garage", "torus3D", "cubicle"]
cases = {}
for name, b in rows.items():
    m = re.match(r"BM_(Se3Graph|Sim3Drift|Ba)_(\w+)/\w+:(\d+)/threads:(\d+)", name)
    if not m:
        continue
    kind, who, arg, threads = m.groups()
    arg = int(arg)
    which = (GRAPHS[arg] if kind == "Se3Graph" else
             ("synthetic 500x50k" if arg == 0 else "KITTI 00") if kind == "Ba" else f"{arg} kf")
    cases.setdefault((kind, arg, which, int(threads)), {})[who] = b

print("| problem | threads | variant | CPU [ms] | iters | CPU ms/iter | final cost | reach: iter "
      "| reach CPU [ms] | to reach vs Ceres, same damping (CPU) | to reach vs Ceres' defaults (CPU) "
      "| cost / Ceres − 1 |")
print("|---|---|---|---|---|---|---|---|---|---|---|---|")
kinds = {"Se3Graph": 0, "Sim3Drift": 1, "Ba": 2}
for key in sorted(cases, key=lambda k: (kinds[k[0]], k[1], k[3])):
    kind, _, which, threads = key
    for who in ["Ceres", "CeresLowDamping", "Ours", "OursCholmod", "OursAccel", "OursLowDamping",
                "OursAccelLowDamping", "OursAccelLowDampingCholmod"]:
        b = cases[key].get(who)
        if b is None:
            continue
        cpu = b.get("total_cpu_ms", b["cpu_time"])
        it = b.get("lm_iterations", 0)
        line = (f"| {kind} {which} | {threads} | {who} | {cpu:,.0f} | {it:.0f} | "
                f"{cpu / max(it, 1):.1f} | {b.get('final_cost', float('nan')):.9g} | ")
        if who.startswith("Ceres"):
            line += "– | – | – | – | – |"
        else:
            ri = b.get("reach_iterations")
            ceres = cases[key].get("Ceres")
            rd = b.get("reach_default_iterations")
            if ri is not None:
                line += f"{ri:.0f} | {b['reach_cpu_ms']:,.0f} | {b['reach_ratio_cpu']:.2f}× | "
                line += (f"{ceres.get('total_cpu_ms', ceres['cpu_time']) / b['reach_cpu_ms']:.2f}× | "
                         if ceres is not None else "– | ")
            elif rd is not None:
                # no Ceres row with the same damping in the run: reach of Ceres' defaults
                line += (f"{rd:.0f} (of Ceres' defaults) | {b['reach_default_cpu_ms']:,.0f} | – | "
                         f"{b['reach_default_ratio_cpu']:.2f}× | ")
            else:
                line += "not reached | – | – | – | "
            line += f"{b.get('cost_vs_ceres', float('nan')):.1e} |"
        print(line)

#!/usr/bin/env python3
"""Kang & Cho 2011 Table 1, reproduced: run (or read) the `table1` benchmark and render the
paper's table beside Loom's numbers, and the paper's Fig. 12 (frames per second against
vertices and against springs).

usage:
  scripts/table1.py [--run] [--json table1.json] [--out docs/images/table1.png] [--md table1.md]
    --run     run build/bin/table1 (3 repetitions, medians) and write --json
    otherwise read --json written earlier
One HO step is one frame (the CSV's reading of the paper)."""
import argparse
import json
import os
import re
import subprocess
import sys

from loom_plot import have_matplotlib

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))


def run_bench(json_path):
    exe = os.path.join(ROOT, "build", "bin", "table1")
    if not os.path.exists(exe):
        sys.exit("build/bin/table1 not found: build first (scripts/setup.sh)")
    env = dict(os.environ, OMP_PROC_BIND="close", OMP_PLACES="cores")
    subprocess.run([exe, "--benchmark_repetitions=3", "--benchmark_report_aggregates_only=true",
                    "--benchmark_min_time=0.3", "--benchmark_filter=Triad|HoStep_double/|HoStep_float|SeStep_(double|float)/|Rk4Fused_(double|float)/|HoStep_shuffled",
                    "--benchmark_out_format=json", f"--benchmark_out={json_path}"], check=True, env=env)


def load(json_path):
    data = json.load(open(json_path))
    rows = {}
    for b in data["benchmarks"]:
        if b.get("aggregate_name") != "median":
            continue
        m = re.match(r"BM_(\w+?)/row:(\d+)/threads:(\d+)", b["run_name"])
        if not m:
            continue
        kind, row, threads = m.group(1), int(m.group(2)), int(m.group(3))
        rows.setdefault(row, {})[(kind, threads)] = b
    return data.get("context", {}), rows


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("--run", action="store_true")
    ap.add_argument("--json", default="table1.json")
    ap.add_argument("--out", default="table1.png")
    ap.add_argument("--md", default="")
    a = ap.parse_args()
    if a.run:
        run_bench(a.json)
    ctx, rows = load(a.json)
    lines = ["| vertices | springs: paper / kang_cho_table1 / radius_sqrt5 | paper fps (GTX 590) | "
             "HO double 1 thr fps (x paper) | HO double 2 thr fps (x paper) | HO float 2 thr fps (x paper) | "
             "RK4 double 2 thr fps | HO double 2 thr GB/s (bw frac) | SE double 2 thr ms (bw frac) | "
             "SE float 2 thr ms | RK4 fused double 2 thr ms (bw frac) | HO shuffled 2 thr ms: none / rcm |",
             "|---|---|---|---|---|---|---|---|---|---|---|---|"]
    pts = []
    ms = lambda b: f"{1e3 / b['fps']:.3g}" if b else "-"
    msbw = lambda b: f"{1e3 / b['fps']:.3g} ({b['bw_frac']:.2f})" if b else "-"
    for r in sorted(rows):
        d = rows[r]
        ho1, ho2 = d.get(("HoStep_double", 1)), d.get(("HoStep_double", 2))
        f2, s5 = d.get(("HoStep_float", 2)), d.get(("HoStep_double_sqrt5", 1))
        rk2 = d.get(("Rk4Step_double", 2)) or d.get(("Rk4Fused_double", 2))
        se2, sef2, rkf2 = d.get(("SeStep_double", 2)), d.get(("SeStep_float", 2)), d.get(("Rk4Fused_double", 2))
        shn, shr = d.get(("HoStep_shuffled_none", 2)), d.get(("HoStep_shuffled_rcm", 2))
        if not ho1:
            continue
        paper = ho1["paper_fps"]
        fmt = lambda b: f"{b['fps']:.0f} ({b['fps'] / paper:.1f}x)" if b else "-"
        springs = f"{ho1['paper_springs']:.0f} / {ho1.get('springs', 0):.0f} / " + (f"{s5['springs']:.0f}" if s5 else "-")
        rk = f"{rk2['fps']:.0f}" if rk2 else "-"
        bw = f"{ho2['GB/s']:.1f} ({ho2['bw_frac']:.2f})" if ho2 else "-"
        lines.append(f"| {ho1['vertices']:.0f} | {springs} | {paper} | {fmt(ho1)} | {fmt(ho2)} | {fmt(f2)} | {rk} | {bw} | "
                     f"{msbw(se2)} | {ms(sef2)} | {msbw(rkf2)} | {ms(shn)} / {ms(shr)} |")
        pts.append((ho1["vertices"], ho1["paper_springs"], paper, ho1["fps"], ho2["fps"] if ho2 else None,
                    f2["fps"] if f2 else None))
    table = "\n".join(lines)
    print(table)
    if a.md:
        open(a.md, "w").write(table + "\n")
    if not have_matplotlib([a for a in sys.argv if a != "--run"]):
        print("no matplotlib: table only (apt-get install python3-matplotlib)")
        return
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    fig, axes = plt.subplots(1, 2, figsize=(11, 4.2))
    for ax, col, label in ((axes[0], 0, "vertices"), (axes[1], 1, "springs (paper's counts)")):
        xs = [p[col] for p in pts]
        ax.plot(xs, [p[2] for p in pts], "s-", label="Kang & Cho 2011, GTX 590")
        ax.plot(xs, [p[3] for p in pts], "o-", label="Loom HO, double, 1 thread")
        if all(p[4] for p in pts):
            ax.plot(xs, [p[4] for p in pts], "o--", label="Loom HO, double, 2 threads")
        if all(p[5] for p in pts):
            ax.plot(xs, [p[5] for p in pts], "^:", label="Loom HO, float, 2 threads")
        ax.set_xlabel(label)
        ax.set_ylabel("frames (steps) per second")
        ax.set_yscale("log")
        ax.grid(True, alpha=0.3)
    axes[0].legend(fontsize=8)
    fig.suptitle("Table 1 / Fig. 12: one HO step per frame")
    fig.tight_layout()
    fig.savefig(a.out, dpi=110)
    print("wrote", a.out)


if __name__ == "__main__":
    main()

#!/usr/bin/env python3
"""Scaling summary of a Google Benchmark JSON file from bench_baraff_witkin (bw_solver/...)
or bench_solvers: per scene/solver the metric at every grid, the log-log slope of the metric
against the vertex count (least squares over the grids from --from up, default 64^2), the
ratio 512^2 / 256^2, and the iteration ratio 256^2 / 32^2 (issue 15's goals: slope <= 1.15,
512^2 within 5x of 256^2, iterations at most 2x).

  build/bin/bench_baraff_witkin --benchmark_filter=bw_solver --benchmark_out=bw.json \
      --benchmark_out_format=json
  scripts/bench_scaling.py bw.json                 # metric step_ms
  scripts/bench_scaling.py solvers.json --metric real_time
"""
import argparse
import json
import math
import re
import sys
from collections import defaultdict


def fit_slope(points):
    """Least-squares slope of log(y) against log(x)."""
    xs = [math.log(x) for x, _ in points]
    ys = [math.log(y) for _, y in points]
    n = len(xs)
    mx, my = sum(xs) / n, sum(ys) / n
    sxx = sum((x - mx) ** 2 for x in xs)
    if sxx == 0:
        return float("nan")
    return sum((x - mx) * (y - my) for x, y in zip(xs, ys)) / sxx


def main():
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("json", help="--benchmark_out file (JSON)")
    ap.add_argument("--metric", default="step_ms", help="counter or real_time (default step_ms)")
    ap.add_argument("--from", dest="start", type=int, default=64, help="smallest grid n in the fit (default 64)")
    a = ap.parse_args()
    with open(a.json) as f:
        data = json.load(f)
    series = defaultdict(dict)  # family -> n -> (metric, iters)
    for b in data.get("benchmarks", []):
        if b.get("run_type") == "aggregate" and b.get("aggregate_name") != "median":
            continue
        name = b["name"].split("/iterations:")[0].replace("/real_time", "")
        m = re.match(r"bw_solver/([a-z]+)(\d+)/(.+)$", name)
        if m:
            family, n = m.group(1) + " " + m.group(3), int(m.group(2))
        else:
            m = re.match(r"(.+)/(\d+)$", name)  # bench_solvers: <solver>/<phase>/<n>
            if not m:
                continue
            family, n = m.group(1), int(m.group(2))
        value = b.get(a.metric)
        if value is None:
            continue
        series[family][n] = (float(value), b.get("iters"))
    if not series:
        sys.exit("no benchmark with the metric '%s' in %s" % (a.metric, a.json))
    sizes = sorted({n for s in series.values() for n in s})
    head = "%-58s" % "scene/solver" + "".join("%12s" % ("%d^2" % n) for n in sizes)
    print(head + "%8s%10s%10s" % ("slope", "512/256", "it256/32"))
    for family in sorted(series):
        s = series[family]
        cells = "".join("%12s" % ("%.4g" % s[n][0] if n in s else "-") for n in sizes)
        pts = [(n * n, s[n][0]) for n in sorted(s) if n >= a.start and s[n][0] > 0]
        slope = "%.2f" % fit_slope(pts) if len(pts) >= 2 else "-"
        ratio = "%.2f" % (s[512][0] / s[256][0]) if 512 in s and 256 in s and s[256][0] > 0 else "-"
        its = "-"
        if 256 in s and 32 in s and s[256][1] and s[32][1]:
            its = "%.2f" % (s[256][1] / s[32][1])
        print("%-58s%s%8s%10s%10s" % (family[:58], cells, slope, ratio, its))
        if any(s[n][1] for n in s):
            print("%-58s%s" % ("  iterations", "".join("%12s" % ("%.1f" % s[n][1] if n in s and s[n][1] else "-")
                                                      for n in sizes)))


if __name__ == "__main__":
    main()

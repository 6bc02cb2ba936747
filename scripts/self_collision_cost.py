#!/usr/bin/env python3
"""Self-collision cost table and log-log slope from bench_self_collision's JSON output.

  LOOM_BENCH_DRAPE_CACHE=/tmp/loom_drape build/bin/bench_self_collision --benchmark_filter=BM_Step \
      --benchmark_repetitions=3 --benchmark_report_aggregates_only=true \
      --benchmark_out=sc.json --benchmark_out_format=json
  scripts/self_collision_cost.py sc.json [more.json ...]   (several runs' files are merged)

For each integrator and grid N (N^2 vertices) it prints the step without self-collision, the step
with it, their difference, the three phases the self-collision code times itself (broad, narrow,
response: counters broad_ms, narrow_ms, response_ms, with baraff_witkin's search for its
self-contacts inside its step added to broad and narrow: search_broad_ms, search_narrow_ms) and
their sum, and the ratio of the two
steps. Then, per integrator, the least-squares slope of log(cost) against log(vertices) over the
grids, for the phase sum and for the difference of the steps (goal of issue 12: at most 1.2), and
whether the ratio at 128^2 is at most 2 (goal for symplectic_euler). Times are Google Benchmark's
real time (wall clock) per step in ms; with repetitions, the median aggregate is used.
"""
import json
import math
import re
import sys


def load(paths):
    data = {"benchmarks": []}
    for path in paths:
        with open(path) as f:
            data["benchmarks"] += json.load(f)["benchmarks"]
    rows = {}
    have_median = any(b.get("aggregate_name") == "median" for b in data["benchmarks"])
    for b in data["benchmarks"]:
        if have_median and b.get("aggregate_name") != "median":
            continue
        if not have_median and b.get("run_type") == "aggregate":
            continue
        m = re.match(r"BM_Step/(\w+?)_(without|self_collision)/(\d+)/(\d+)", b["run_name"] if "run_name" in b else b["name"])
        if not m:
            continue
        unit = {"ns": 1e-6, "us": 1e-3, "ms": 1.0, "s": 1e3}[b.get("time_unit", "ns")]
        key = (m.group(1), int(m.group(3)), m.group(2) == "self_collision")
        rows[key] = {
            "time": b["real_time"] * unit,
            "broad": b.get("broad_ms", 0.0),
            "narrow": b.get("narrow_ms", 0.0),
            "response": b.get("response_ms", 0.0),
            "search_broad": b.get("search_broad_ms", 0.0),
            "search_narrow": b.get("search_narrow_ms", 0.0),
            "threads": int(m.group(4)),
        }
    return rows


def slope(points):
    """Least-squares slope of log y against log x."""
    pts = [(math.log(x), math.log(y)) for x, y in points if x > 0 and y > 0]
    if len(pts) < 2:
        return float("nan")
    mx = sum(p[0] for p in pts) / len(pts)
    my = sum(p[1] for p in pts) / len(pts)
    sxx = sum((p[0] - mx) ** 2 for p in pts)
    sxy = sum((p[0] - mx) * (p[1] - my) for p in pts)
    return sxy / sxx


def main():
    if len(sys.argv) < 2:
        sys.exit(__doc__)
    rows = load(sys.argv[1:])
    integrators = sorted({k[0] for k in rows})
    ok = True
    for integ in integrators:
        ns = sorted({k[1] for k in rows if k[0] == integ})
        print(f"\n{integ}")
        print(f"{'N':>5} {'vertices':>9} {'without':>9} {'with':>9} {'extra':>9} {'broad':>8} {'narrow':>8} "
              f"{'response':>8} {'phases':>8} {'ratio':>6}   (ms per step)")
        phases, extras = [], []
        ratio128 = None
        for n in ns:
            w0 = rows.get((integ, n, False))
            w1 = rows.get((integ, n, True))
            if not w0 or not w1:
                continue
            # The integrator's own search inside its step (baraff_witkin) is self-collision's too.
            broad = w1["broad"] + w1["search_broad"]
            narrow = w1["narrow"] + w1["search_narrow"]
            ph = broad + narrow + w1["response"]
            extra = w1["time"] - w0["time"]
            ratio = w1["time"] / w0["time"]
            if n == 128:
                ratio128 = ratio
            v = n * n
            phases.append((v, ph))
            extras.append((v, extra))
            print(f"{n:>5} {v:>9} {w0['time']:>9.3f} {w1['time']:>9.3f} {extra:>9.3f} {broad:>8.3f} "
                  f"{narrow:>8.3f} {w1['response']:>8.3f} {ph:>8.3f} {ratio:>6.2f}"
                  + (f"   (in-step search {w1['search_broad'] + w1['search_narrow']:.3f})"
                     if w1["search_broad"] + w1["search_narrow"] > 0 else ""))
        sp, se = slope(phases), slope(extras)
        print(f"slope of log(cost) vs log(vertices): phases {sp:.2f}, with - without {se:.2f} (goal <= 1.2)")
        if ratio128 is not None:
            print(f"with / without at 128^2: {ratio128:.2f}" + (" (goal <= 2)" if integ == "symplectic_euler" else ""))
            if integ == "symplectic_euler" and ratio128 > 2:
                ok = False
        if sp > 1.2:
            ok = False
    print("\ngoals met" if ok else "\ngoals NOT met")


if __name__ == "__main__":
    main()

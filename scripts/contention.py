#!/usr/bin/env python3
"""Threads on a busy machine: every shipped scene with threads 1, 2 and auto, alone and next to
a competing CPU-bound process pinned to core 0 (issue 16's contention benchmark).

usage:
  scripts/contention.py [--loom build/bin/loom] [--budget 1.5] [--sim 1.0] [--repeat 3]
                        [--scenes 'scenes/*.yaml'] [--json contention.json] [--plan]

Each scene runs for the same number of steps under every setting: 1 s of simulated time (the
issue's figure), unless one thread would need more than --budget seconds of stepping for that;
then the run is capped at --budget seconds of one-thread stepping (the table marks those rows
"capped" and prints the steps and the simulated time used; --plan prints the plan and the
estimated total time without running the table). On the machine this was written on, 1 s of
simulated time takes from 0.05 s (hanging_10x10_k2000) to about 20 minutes (wool_hanging_256,
Baraff-Witkin on 65,536 vertices) of one-thread wall time; running every cell of 36 for 1 s,
three times, would take hours, so the cap keeps the whole table under about 10 minutes.

The step cost is calibrated first with a short one-thread run (the integrator's own time per
step from `loom run`'s summary line; the rest of the run's wall time is its start-up). Times in
the table are the wall-clock seconds of the whole `loom run` (start-up, steps, output), the
median of --repeat runs (3 x --repeat for scenes whose one-thread run is estimated under 0.5 s), the settings interleaved (1, 2, auto, 1, 2, auto, ...) so that a slow
minute of the machine does not fall on one setting. The "auto ends on" column is the count
`threads: auto` kept at the end of its runs (from its summary line); the JSON also keeps each auto
run's whole summary (the count it started on, the others' load it measured at start, probes and
probes held back by load) and every run's CPU seconds (user + system).

The goal (exit code 1 when missed): with threads: auto, a run is never more than 10% slower
than the better of threads 1 and 2, alone and loaded. OMP_NUM_THREADS is removed from the
runs' environment (it would override `threads`).
"""
import argparse
import glob
import json
import os
import re
import shutil
import statistics
import subprocess
import sys
import tempfile
import time

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
SUMMARY = re.compile(r"\(([0-9.eE+-]+) ms per step in the integrator\)")
AUTO = re.compile(r"threads auto: ended on (\d+)")
AUTO_LINE = re.compile(r"loom: threads auto: (.*)")


def scene_timing(path):
    """(dt, substeps) of a scene file."""
    import yaml
    with open(path) as f:
        doc = yaml.safe_load(f)
    integ = doc.get("integrator", {}) or {}
    return float(integ.get("dt", 1e-3)), int(integ.get("substeps", 1))


def run_once(loom, scene, out, frames, substeps, threads, env):
    """(wall seconds, integrator ms per step, the count auto ended on or None, auto's summary or None,
    user + system CPU seconds of the run)."""
    cmd = [loom, "run", scene, "--out", out, "--overwrite", "--frames", str(frames),
           "--set", f"integrator.substeps={substeps}", "--set", f"threads={threads}"]
    c0 = os.times()
    t0 = time.perf_counter()
    r = subprocess.run(cmd, env=env, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    t = time.perf_counter() - t0
    c1 = os.times()
    cpu = (c1.children_user - c0.children_user) + (c1.children_system - c0.children_system)
    if r.returncode != 0:
        raise RuntimeError(f"{' '.join(cmd)} failed ({r.returncode}): {r.stderr.strip()[-400:]}")
    m = SUMMARY.search(r.stdout)
    a = AUTO.search(r.stdout)
    line = AUTO_LINE.search(r.stdout)
    return (t, (float(m.group(1)) if m else None), (int(a.group(1)) if a else None),
            (line.group(1) if line else None), cpu)


def plan_scene(a, sc, tmp, env):
    name = os.path.splitext(os.path.basename(sc))[0]
    dt, substeps = scene_timing(sc)
    # One step first (a Baraff-Witkin step on 65,536 vertices takes seconds), then 10 when
    # that was cheap: the first step carries set-up work, so one step overstates the cost.
    cal = 1
    wall, ms, *_ = run_once(a.loom, sc, os.path.join(tmp, name + "_cal"), 1, 1, 1, env)
    step_cost = (ms / 1e3) if ms else wall
    if step_cost < a.budget / 10:
        cal = 10
        wall, ms, *_ = run_once(a.loom, sc, os.path.join(tmp, name + "_cal"), 1, cal, 1, env)
        step_cost = (ms / 1e3) if ms else wall / cal
    startup = max(0.0, wall - cal * step_cost)
    want = max(1, int(round(a.sim / dt)))
    steps = max(1, min(want, int(a.budget / step_cost)))
    capped = steps < want
    if not capped:  # whole frames covering at least the simulated time asked for
        frames, sub = -(-want // substeps), substeps
    elif steps >= substeps:
        frames, sub = steps // substeps, substeps
    else:
        frames, sub = 1, steps
    steps = frames * sub
    return {"scene": name, "path": sc, "frames": frames, "substeps": sub, "steps": steps,
            "sim_time": steps * dt, "capped": capped, "one_thread_seconds_for_sim": want * step_cost + startup,
            "est_one_thread": steps * step_cost + startup}


def main():
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--loom", default=os.path.join(ROOT, "build", "bin", "loom"))
    ap.add_argument("--budget", type=float, default=1.5,
                    help="wall seconds of one-thread stepping at most per run (caps the steps)")
    ap.add_argument("--sim", type=float, default=1.0, help="simulated seconds per run (the issue's 1 s)")
    ap.add_argument("--repeat", type=int, default=3, help="runs per cell (the median is reported)")
    ap.add_argument("--scenes", default=os.path.join(ROOT, "scenes", "*.yaml"))
    ap.add_argument("--json", default="")
    ap.add_argument("--plan", action="store_true", help="calibrate, print the plan and the estimated time, stop")
    a = ap.parse_args()
    if not os.path.exists(a.loom):
        sys.exit(f"{a.loom} not found: build first (cmake --build build --target loom and the plugins)")
    if not shutil.which("taskset"):
        sys.exit("taskset not found (util-linux): needed to pin the competing process")
    env = dict(os.environ)
    env.pop("OMP_NUM_THREADS", None)
    tmp = tempfile.mkdtemp(prefix="loom_contention_")
    rows = []
    hog = None
    t_start = time.perf_counter()
    try:
        plans = [plan_scene(a, sc, tmp, env) for sc in sorted(glob.glob(a.scenes))]
        # Alone: 1 + ~0.6 + ~0.6 one-thread times; loaded: 1 + ~2.5 + ~1 (measured ratios).
        est = sum(p["est_one_thread"] * (3 if p["est_one_thread"] < 0.5 else 1) for p in plans) * a.repeat * (2.2 + 4.5)
        for p in plans:
            cap = (f"capped: 1 s would take ~{p['one_thread_seconds_for_sim']:.0f} s on one thread"
                   if p["capped"] else "1 s")
            print(f"{p['scene']}: {p['frames']} frame(s) x {p['substeps']} steps = {p['sim_time']:.4g} s simulated "
                  f"({cap}; ~{p['est_one_thread']:.2f} s per one-thread run)", flush=True)
        print(f"estimated total: ~{est / 60:.1f} min ({a.repeat} runs per cell)", flush=True)
        if a.plan:
            return 0
        for cond in ("alone", "loaded"):
            if cond == "loaded":
                hog = subprocess.Popen(["taskset", "-c", "0", sys.executable, "-c", "while True: pass"])
                time.sleep(0.5)
            for p in plans:
                runs = {"1": [], "2": [], "auto": []}
                cpu = {"1": [], "2": [], "auto": []}
                ends = []
                auto_lines = []
                # Runs under half a second are mostly start-up and output: three times the runs.
                reps = a.repeat * (3 if p["est_one_thread"] < 0.5 else 1)
                for rep in range(reps):
                    for threads in ("1", "2", "auto"):
                        t, _, end, line, c = run_once(a.loom, p["path"], os.path.join(tmp, f"{p['scene']}_{threads}"),
                                                      p["frames"], p["substeps"], threads, env)
                        runs[threads].append(t)
                        cpu[threads].append(c)
                        if threads == "auto" and end is not None:
                            ends.append(end)
                            auto_lines.append(line)
                med = {k: statistics.median(v) for k, v in runs.items()}
                best = min(med["1"], med["2"])
                ratio = med["auto"] / best
                row = {"scene": p["scene"], "condition": cond, "steps": p["steps"], "sim_time": p["sim_time"],
                       "capped": p["capped"], "t1": med["1"], "t2": med["2"], "tauto": med["auto"],
                       "runs": runs, "cpu_seconds": cpu, "auto_ends_on": ends, "auto_summaries": auto_lines,
                       "auto_over_best": ratio, "ok": ratio <= 1.10}
                rows.append(row)
                print(f"  {cond:6s} {p['scene']}: 1 thr {med['1']:.2f} s, 2 thr {med['2']:.2f} s, "
                      f"auto {med['auto']:.2f} s (auto / best {ratio:.2f}; auto ends on {ends})", flush=True)
                if auto_lines:  # start count, load seen at start, probes: what auto did
                    print(f"    auto: {auto_lines[0]}", flush=True)
            if hog:
                hog.kill()
                hog.wait()
                hog = None
    finally:
        if hog:
            hog.kill()
            hog.wait()
        shutil.rmtree(tmp, ignore_errors=True)
    print()
    print("| scene | steps | simulated | condition | 1 thread | 2 threads | auto | auto ends on | auto / best | goal |")
    print("|---|---|---|---|---|---|---|---|---|---|")
    for r in rows:
        sim = f"{r['sim_time']:.3g} s" + (" (capped)" if r["capped"] else "")
        ends = " ".join(str(e) for e in r["auto_ends_on"]) or "-"
        print(f"| {r['scene']} | {r['steps']} | {sim} | {r['condition']} | {r['t1']:.2f} s | {r['t2']:.2f} s | "
              f"{r['tauto']:.2f} s | {ends} | {r['auto_over_best']:.2f} | {'ok' if r['ok'] else 'MISSED'} |")
    missed = [r for r in rows if not r["ok"]]
    total = time.perf_counter() - t_start
    print(f"\ngoal (auto <= 1.10 x best of 1 and 2, medians of {a.repeat}): "
          f"{len(rows) - len(missed)} of {len(rows)} cells met; the script took {total / 60:.1f} min")
    if a.json:
        with open(a.json, "w") as f:
            json.dump({"rows": rows, "budget": a.budget, "sim": a.sim, "repeat": a.repeat,
                       "seconds": total}, f, indent=1)
    return 1 if missed else 0


if __name__ == "__main__":
    sys.exit(main())

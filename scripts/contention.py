#!/usr/bin/env python3
"""Threads on a busy machine: every shipped scene with threads 1, 2 and auto, alone and next to
a competing CPU-bound process pinned to core 0 (issue 16's contention benchmark).

usage:
  scripts/contention.py [--loom build/bin/loom] [--budget 1.5] [--max-sim 1.0] [--repeat 1]
                        [--scenes 'scenes/*.yaml'] [--json contention.json]

Each scene runs for the same simulated time under every setting: 1 s (the issue's figure) when
one thread does it within --budget seconds of wall time, else fewer steps (the table prints the
simulated time and the step count used). The step cost is calibrated first with a short
one-thread run (a few steps, startup included, so an upper bound). Times are wall-clock seconds
of the whole `loom run` (startup, build, steps, output), the median of --repeat runs.

The goal (exit code 1 when missed): with threads: auto, a run is never more than 10% slower
than the better of threads 1 and 2, alone and loaded. OMP_NUM_THREADS is removed from the
runs' environment (it would override `threads`).
"""
import argparse
import glob
import json
import os
import shutil
import statistics
import subprocess
import sys
import tempfile
import time

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))


def scene_timing(path):
    """(dt, substeps) of a scene file."""
    import yaml
    with open(path) as f:
        doc = yaml.safe_load(f)
    integ = doc.get("integrator", {}) or {}
    dt = float(integ.get("dt", 1e-3))
    substeps = int(integ.get("substeps", 1))
    return dt, substeps


def run_once(loom, scene, out, frames, substeps, threads, env):
    cmd = [loom, "run", scene, "--out", out, "--overwrite", "--quiet", "--frames", str(frames),
           "--set", f"integrator.substeps={substeps}", "--set", f"threads={threads}"]
    t0 = time.perf_counter()
    r = subprocess.run(cmd, env=env, stdout=subprocess.DEVNULL, stderr=subprocess.PIPE, text=True)
    t = time.perf_counter() - t0
    if r.returncode != 0:
        raise RuntimeError(f"{' '.join(cmd)} failed ({r.returncode}): {r.stderr.strip()[-400:]}")
    return t


def main():
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--loom", default=os.path.join(ROOT, "build", "bin", "loom"))
    ap.add_argument("--budget", type=float, default=1.5, help="wall seconds per one-thread run (sets the steps)")
    ap.add_argument("--max-sim", type=float, default=1.0, help="simulated seconds at most per run")
    ap.add_argument("--repeat", type=int, default=1)
    ap.add_argument("--scenes", default=os.path.join(ROOT, "scenes", "*.yaml"))
    ap.add_argument("--json", default="")
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
    try:
        scenes = sorted(glob.glob(a.scenes))
        plans = []
        for sc in scenes:
            name = os.path.splitext(os.path.basename(sc))[0]
            dt, substeps = scene_timing(sc)
            cal = min(substeps, 10)
            tcal = run_once(a.loom, sc, os.path.join(tmp, name + "_cal"), 1, cal, 1, env)
            step_cost = tcal / cal
            max_steps = max(1, int(round(a.max_sim / dt)))
            steps = max(cal, min(max_steps, int(a.budget / step_cost)))
            if steps >= substeps:
                frames, sub = steps // substeps, substeps
            else:
                frames, sub = 1, steps
            plans.append((sc, name, frames, sub, frames * sub, frames * sub * dt))
            print(f"{name}: {frames} frame(s) x {sub} steps = {frames * sub * dt:.4g} s simulated", flush=True)
        for cond in ("alone", "loaded"):
            if cond == "loaded":
                hog = subprocess.Popen(["taskset", "-c", "0", sys.executable, "-c", "while True: pass"])
                time.sleep(0.5)
            for sc, name, frames, sub, steps, sim in plans:
                res = {}
                for threads in ("1", "2", "auto"):
                    ts = [run_once(a.loom, sc, os.path.join(tmp, f"{name}_{threads}"), frames, sub, threads, env)
                          for _ in range(a.repeat)]
                    res[threads] = statistics.median(ts)
                best = min(res["1"], res["2"])
                ratio = res["auto"] / best
                rows.append({"scene": name, "condition": cond, "steps": steps, "sim_time": sim, "t1": res["1"],
                             "t2": res["2"], "tauto": res["auto"], "auto_over_best": ratio, "ok": ratio <= 1.10})
                print(f"  {cond:6s} {name}: 1 thr {res['1']:.2f} s, 2 thr {res['2']:.2f} s, auto {res['auto']:.2f} s "
                      f"(auto / best {ratio:.2f})", flush=True)
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
    print("| scene | steps | simulated | condition | 1 thread | 2 threads | auto | auto / best | goal |")
    print("|---|---|---|---|---|---|---|---|---|")
    for r in rows:
        print(f"| {r['scene']} | {r['steps']} | {r['sim_time']:.3g} s | {r['condition']} | {r['t1']:.2f} s | "
              f"{r['t2']:.2f} s | {r['tauto']:.2f} s | {r['auto_over_best']:.2f} | {'ok' if r['ok'] else 'MISSED'} |")
    missed = [r for r in rows if not r["ok"]]
    print(f"\ngoal (auto <= 1.10 x best of 1 and 2): {len(rows) - len(missed)} of {len(rows)} met")
    if a.json:
        with open(a.json, "w") as f:
            json.dump({"rows": rows, "budget": a.budget, "max_sim": a.max_sim, "repeat": a.repeat}, f, indent=1)
    return 1 if missed else 0


if __name__ == "__main__":
    sys.exit(main())

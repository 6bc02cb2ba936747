#!/usr/bin/env python3
"""Threads on a busy machine: every shipped scene with threads 1, 2 and auto, alone and next to
a competing CPU-bound process pinned to core 0 (issue 16's contention benchmark).

usage:
  scripts/contention.py [--loom build/bin/loom] [--budget 1.5] [--sim 1.0] [--repeat 3]
                        [--max-repeat 9] [--minutes 7.5] [--scenes FILE_OR_GLOB ...]
                        [--json contention.json] [--plan] [--overhead]

Each scene runs for the same number of steps under every setting: 1 s of simulated time (the
issue's figure), unless one thread would need more than --budget seconds of stepping for that;
then the run is capped at --budget seconds of one-thread stepping (the table marks those rows
"capped" and prints the steps and the simulated time used; --plan prints the plan and the
estimated time without running the table). On the machine this was written on, 1 s of
simulated time takes from 0.05 s (hanging_10x10_k2000) to about 20 minutes (wool_hanging_256,
Baraff-Witkin on 65,536 vertices) of one-thread wall time; running every cell of 36 for 1 s
would take hours, so the cap and --minutes keep the whole table under 8 minutes.

The step cost is calibrated first with a short one-thread run (the integrator's own time per
step from `loom run`'s summary line; the rest of the run's wall time is its start-up); a plan
longer than that run is then checked by a one-thread run of it, and cut to the frames whose
measured step times fit the budget when its steps cost more than twice the calibrated step
(plan_scene: a falling cloth's first steps are much cheaper than its steps in contact). Times are
the wall-clock seconds of the whole `loom run` (start-up, steps, output); every setting of a
scene writes into the same output folder (out_dir: the file system's cost depends on the folder).

Method (the statistics are in scripts/contention_stats.py, tested by
tests/scripts/test_contention_stats.py):
- A cell (a scene, alone or loaded) is measured in repetitions; a repetition runs threads 1, 2
  and auto back to back, in an order that rotates through all six orders (run_order: any three
  consecutive repetitions are a Latin square), so a drift of the machine or the run just before
  does not favour one setting. --repeat repetitions per cell (3 x --repeat for scenes whose
  one-thread run is estimated under 0.5 s, where start-up and output dominate).
- Each setting's median with its interquartile range; the ratio median(auto) / the better of
  median(1) and median(2), with a 90% percentile bootstrap interval over repetitions (the whole
  statistic recomputed on resampled repetitions, including which count is the better).
- A cell whose interval straddles 1.10 is "unclear"; such cells get one more repetition at a
  time, round robin, up to --max-repeat (x3 for the short scenes), while the extra repetition
  fits in --minutes (the alone pass gets its share of the time left after both passes' base
  repetitions). The verdict is the ratio itself against 1.10: extra repetitions make it more
  reliable, they do not change the comparison.

The goal (exit code 1 when missed): with threads: auto, a run is never more than 10% slower
than the better of threads 1 and 2, alone and loaded. OMP_NUM_THREADS is removed from the
runs' environment (it would override `threads`). The "auto ends on" column counts the runs of
`threads: auto` by the count they ended on; the JSON keeps every run's wall and CPU seconds
(user + system, from wait4), the integrator's ms per step from its summary line (`step_ms`:
the steps' share of the wall, the rest being start-up and output), each repetition's order and
each auto run's whole summary (the count it started on, the others' load it measured at start,
probes and probes held back, the steps and step seconds on each count, the sample length).

--overhead measures instead what auto costs against the fixed count it ends on: per scene and
condition, --repeat pairs (x3 for short scenes) of auto and that fixed count back to back
(auto first, then second, alternately); it prints the median wall and CPU seconds of each and
the median paired difference with its 90% bootstrap interval.
"""
import argparse
import csv
import glob
import json
import os
import re
import shutil
import signal
import statistics
import subprocess
import sys
import tempfile
import time

from contention_stats import GOAL, SETTINGS, cell_stats, median_difference, run_order

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
    # The output goes to files and the child is reaped with wait4, whose rusage gives its CPU
    # time in microseconds (os.times() counts 10 ms ticks).
    with tempfile.TemporaryFile("w+") as fo, tempfile.TemporaryFile("w+") as fe:
        t0 = time.perf_counter()
        proc = subprocess.Popen(cmd, env=env, stdout=fo, stderr=fe, text=True)
        _, status, ru = os.wait4(proc.pid, 0)
        t = time.perf_counter() - t0
        proc.returncode = os.waitstatus_to_exitcode(status)
        fo.seek(0)
        fe.seek(0)
        r = subprocess.CompletedProcess(cmd, proc.returncode, fo.read(), fe.read())
    cpu = ru.ru_utime + ru.ru_stime
    if r.returncode != 0:
        raise RuntimeError(f"{' '.join(cmd)} failed ({r.returncode}): {r.stderr.strip()[-400:]}")
    m = SUMMARY.search(r.stdout)
    a = AUTO.search(r.stdout)
    line = AUTO_LINE.search(r.stdout)
    return (t, (float(m.group(1)) if m else None), (int(a.group(1)) if a else None),
            (line.group(1) if line else None), cpu)


def out_dir(tmp, scene):
    """The output folder of every run of a scene, whatever its thread setting. One folder per
    setting made the settings differ by the file system, not by threads: on ext4, creating a
    file costs a scan of the inodes recently deleted in the folder's block group, which the
    --overwrite runs before had left in different numbers in each folder (hanging_10x10_k2000,
    2026-12-01: threads 1 took 62.8 ms a run in one folder and 40.8 ms in another, auto 40.1 and
    64.7 ms in the same two folders, docs/BENCHMARKS.md)."""
    return os.path.join(tmp, scene)


def frames_for(steps, want, substeps):
    """(frames, steps per frame) of a run of about `steps` steps (at most `want`, the steps of
    the simulated time asked for): whole frames of the scene's substeps when the run is not
    capped or holds at least one frame, else one frame of `steps` steps."""
    if steps >= want:  # whole frames covering at least the simulated time asked for
        return -(-want // substeps), substeps
    if steps >= substeps:
        return steps // substeps, substeps
    return 1, max(1, steps)


def plan_scene(a, sc, tmp, env):
    name = os.path.splitext(os.path.basename(sc))[0]
    dt, substeps = scene_timing(sc)
    cal_out = os.path.join(tmp, name + "_cal")
    # One step first (a Baraff-Witkin step on 65,536 vertices takes seconds), then 10 when
    # that was cheap: the first step carries set-up work, so one step overstates the cost.
    cal = 1
    wall, ms, *_ = run_once(a.loom, sc, cal_out, 1, 1, 1, env)
    step_cost = (ms / 1e3) if ms else wall
    if step_cost < a.budget / 10:
        cal = 10
        wall, ms, *_ = run_once(a.loom, sc, cal_out, 1, cal, 1, env)
        step_cost = (ms / 1e3) if ms else wall / cal
    startup = max(0.0, wall - cal * step_cost)
    want = max(1, int(round(a.sim / dt)))
    frames, sub = frames_for(max(1, min(want, int(a.budget / step_cost))), want, substeps)
    # The first steps can be much cheaper than the later ones (a cloth falling before it lands:
    # draped_ball_gnatv_bw's steps cost 3-5 ms in the fall and about 100 ms in contact), so a
    # plan that runs more steps than the calibration is checked by a one-thread run of it. When
    # its steps took more than twice the calibrated cost, the run is cut to the frames whose
    # step time (stats.csv: wall_ms_per_step, per frame) fits the budget: the frames measured.
    est = None
    if frames * sub > cal:
        wall, ms, *_ = run_once(a.loom, sc, cal_out, frames, sub, 1, env)
        if ms and ms / 1e3 > 2 * step_cost:
            with open(os.path.join(cal_out, "stats.csv")) as f:
                rows = [r for r in csv.DictReader(f) if int(r["frame"]) >= 1]
            spent, keep = 0.0, 0
            for r in rows:
                cost = float(r["wall_ms_per_step"]) / 1e3 * sub
                if keep >= 1 and spent + cost > a.budget:
                    break
                spent += cost
                keep += 1
            frames, est = max(1, keep), spent + startup
            step_cost = ms / 1e3   # the whole planned run's mean, for one_thread_seconds_for_sim
    steps = frames * sub
    return {"scene": name, "path": sc, "frames": frames, "substeps": sub, "steps": steps,
            "sim_time": steps * dt, "capped": steps < want, "one_thread_seconds_for_sim": want * step_cost + startup,
            "est_one_thread": est if est is not None else steps * step_cost + startup}


def fmt_spread(c):
    """'0.56 s (0.54-0.59)': the median and, in brackets, the interquartile range."""
    return f"{c['median']:.2f} s ({c['q1']:.2f}-{c['q3']:.2f})"


def fmt_ends(ends):
    """'1 (7), 2 (2)': how many auto runs ended on each count."""
    return ", ".join(f"{k} ({ends.count(k)})" for k in sorted(set(ends))) or "-"


class Cell:
    """One scene in one condition: the repetitions run so far, each the three settings back to
    back in run_order(rep)."""

    def __init__(self, plan, cond, base_reps):
        self.p, self.cond, self.base = plan, cond, base_reps
        self.runs = {k: [] for k in SETTINGS}
        self.cpu = {k: [] for k in SETTINGS}
        self.step_ms = {k: [] for k in SETTINGS}  # the integrator's ms per step (summary line)
        self.orders, self.ends, self.auto_lines = [], [], []
        self.seconds = 0.0  # wall time spent on this cell
        self.stats = None

    def run_rep(self, a, tmp, env):
        order = run_order(len(self.orders))
        t0 = time.perf_counter()
        for threads in order:
            t, ms, end, line, c = run_once(a.loom, self.p["path"], out_dir(tmp, self.p["scene"]),
                                          self.p["frames"], self.p["substeps"], threads, env)
            self.runs[threads].append(t)
            self.cpu[threads].append(c)
            self.step_ms[threads].append(ms)
            if threads == "auto" and end is not None:
                self.ends.append(end)
                self.auto_lines.append(line)
        self.orders.append(list(order))
        self.seconds += time.perf_counter() - t0
        self.stats = cell_stats(self.runs["1"], self.runs["2"], self.runs["auto"])

    def line(self):
        s = self.stats
        return (f"  {self.cond:6s} {self.p['scene']}: 1 thr {fmt_spread(s['1'])}, 2 thr {fmt_spread(s['2'])}, "
                f"auto {fmt_spread(s['auto'])}; auto / best {s['ratio']:.2f} [{s['lo']:.2f}, {s['hi']:.2f}] "
                f"from {s['n']} runs each{'' if s['clear'] else ' (unclear)'}; auto ends on {fmt_ends(self.ends)}")


def run_base(cells, a, tmp, env):
    """The base repetitions of every cell of a condition."""
    for c in cells:
        for _ in range(c.base):
            c.run_rep(a, tmp, env)
        print(c.line(), flush=True)
        if c.auto_lines:  # start count, load seen at start, probes: what auto did
            print(f"    auto: {c.auto_lines[0]}", flush=True)


def run_extra(cells, a, tmp, env, deadline):
    """One more repetition at a time for the cells whose interval still straddles the goal
    (round robin, so the extra runs spread over the condition's minutes), while the cell has
    fewer than its maximum and a repetition (at the cell's pace so far) ends before `deadline`
    (perf_counter seconds)."""
    while True:
        ran = False
        for c in cells:
            s = c.stats
            if s["clear"] or s["n"] >= c.base * a.max_repeat // a.repeat:
                continue
            if time.perf_counter() + c.seconds / s["n"] > deadline:
                continue
            c.run_rep(a, tmp, env)
            ran = True
            print(c.line(), flush=True)
        if not ran:
            return


def overhead(plans, a, tmp, env, cond):
    """--overhead: auto against the fixed count it ends on, in pairs run back to back (auto
    first in even pairs, second in odd ones). The fixed count is the one auto's first run ended
    on; pairs whose auto run ended elsewhere are left out of the differences. Prints the median
    wall and CPU seconds of each and the median paired difference with its 90% interval."""
    rows = []
    for p in plans:
        reps = a.repeat * (3 if p["est_one_thread"] < 0.5 else 1)
        out = out_dir(tmp, p["scene"])  # every setting writes into the scene's one folder
        first = run_once(a.loom, p["path"], out, p["frames"], p["substeps"], "auto", env)
        fixed = str(first[2] or 1)
        pairs = {"auto": [], fixed: []}
        ends, lines = [], []
        for r in range(reps):
            res = {}
            for th in (("auto", fixed) if r % 2 == 0 else (fixed, "auto")):
                res[th] = run_once(a.loom, p["path"], out, p["frames"], p["substeps"], th, env)
            ends.append(res["auto"][2])
            lines.append(res["auto"][3])
            if str(res["auto"][2]) == fixed:
                for th in pairs:
                    pairs[th].append(res[th])
        row = {"scene": p["scene"], "condition": cond, "fixed": fixed, "auto_ends_on": ends,
               "auto_summaries": lines, "pairs": len(pairs[fixed])}
        if pairs[fixed]:
            for name, k in (("wall", 0), ("cpu", 4)):
                av, fv = [x[k] for x in pairs["auto"]], [x[k] for x in pairs[fixed]]
                row[name] = {"auto": statistics.median(av), "fixed": statistics.median(fv),
                             "diff": median_difference(av, fv), "auto_runs": av, "fixed_runs": fv}
            w, c = row["wall"], row["cpu"]
            print(f"  {cond:6s} {p['scene']}: auto against threads {fixed}, {row['pairs']} pairs: wall "
                  f"{w['auto']:.3f} / {w['fixed']:.3f} s, auto - fixed {1e3 * w['diff'][0]:+.1f} ms "
                  f"[{1e3 * w['diff'][1]:+.1f}, {1e3 * w['diff'][2]:+.1f}]; CPU {c['auto']:.3f} / {c['fixed']:.3f} s, "
                  f"{1e3 * c['diff'][0]:+.1f} ms [{1e3 * c['diff'][1]:+.1f}, {1e3 * c['diff'][2]:+.1f}]", flush=True)
        else:
            print(f"  {cond:6s} {p['scene']}: auto never ended on {fixed} again (ends {ends}): no pairs", flush=True)
        rows.append(row)
    return rows


def main():
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--loom", default=os.path.join(ROOT, "build", "bin", "loom"))
    ap.add_argument("--budget", type=float, default=1.5,
                    help="wall seconds of one-thread stepping at most per run (caps the steps)")
    ap.add_argument("--sim", type=float, default=1.0, help="simulated seconds per run (the issue's 1 s)")
    ap.add_argument("--repeat", type=int, default=3,
                    help="repetitions per cell before any extra ones (x3 for runs under 0.5 s)")
    ap.add_argument("--max-repeat", type=int, default=9,
                    help="repetitions per cell at most, extra ones included (x3 for runs under 0.5 s)")
    ap.add_argument("--minutes", type=float, default=7.5,
                    help="extra repetitions start only when they end before this (the base repetitions always run)")
    ap.add_argument("--scenes", nargs="+", default=[os.path.join(ROOT, "scenes", "*.yaml")],
                    help="scene files or globs (default: every shipped scene)")
    ap.add_argument("--json", default="")
    ap.add_argument("--plan", action="store_true", help="calibrate, print the plan and the estimated time, stop")
    ap.add_argument("--overhead", action="store_true",
                    help="instead of the table: auto against the fixed count it ends on, in pairs (--repeat pairs)")
    a = ap.parse_args()
    a.max_repeat = max(a.max_repeat, a.repeat)
    if not os.path.exists(a.loom):
        sys.exit(f"{a.loom} not found: build first (cmake --build build --target loom and the plugins)")
    if not shutil.which("taskset"):
        sys.exit("taskset not found (util-linux): needed to pin the competing process")
    env = dict(os.environ)
    env.pop("OMP_NUM_THREADS", None)
    # A SIGTERM (timeout, kill) unwinds through the finally below, which stops the competing
    # process; Python's default would exit at once and leave it spinning on core 0.
    signal.signal(signal.SIGTERM, lambda *_: sys.exit(143))
    tmp = tempfile.mkdtemp(prefix="loom_contention_")
    cells = []
    hog = None
    t_start = time.perf_counter()
    limit = t_start + 60.0 * a.minutes
    try:
        files = sorted({f for g in a.scenes for f in glob.glob(g)})
        if not files:
            sys.exit(f"no scene matches {' '.join(a.scenes)}")
        plans = [plan_scene(a, sc, tmp, env) for sc in files]
        # Runs under half a second are mostly start-up and output: three times the repetitions.
        base = {p["scene"]: a.repeat * (3 if p["est_one_thread"] < 0.5 else 1) for p in plans}
        # A repetition's three runs, in one-thread times: alone 1 + ~0.6 + ~0.6, loaded 1 + ~2.5
        # + ~1 (measured ratios), plus start-up.
        one = {p["scene"]: p["est_one_thread"] for p in plans}
        est = {"alone": sum(one[k] * base[k] for k in one) * 2.2, "loaded": sum(one[k] * base[k] for k in one) * 4.5}
        for p in plans:
            cap = (f"capped: 1 s would take ~{p['one_thread_seconds_for_sim']:.0f} s on one thread"
                   if p["capped"] else "1 s")
            print(f"{p['scene']}: {p['frames']} frame(s) x {p['substeps']} steps = {p['sim_time']:.4g} s simulated "
                  f"({cap}; ~{p['est_one_thread']:.2f} s per one-thread run)", flush=True)
        print(f"estimated: ~{(est['alone'] + est['loaded']) / 60:.1f} min for {a.repeat} repetitions per cell; "
              f"extra repetitions (up to {a.max_repeat}) for unclear cells until {a.minutes:g} min", flush=True)
        if a.plan:
            return 0
        over = []
        for cond in ("alone", "loaded"):
            if cond == "loaded":
                hog = subprocess.Popen(["taskset", "-c", "0", sys.executable, "-c", "while True: pass"])
                time.sleep(0.5)
            if a.overhead:
                over += overhead(plans, a, tmp, env, cond)
                if hog:
                    hog.kill()
                    hog.wait()
                    hog = None
                continue
            cs = [Cell(p, cond, base[p["scene"]]) for p in plans]
            t0 = time.perf_counter()
            run_base(cs, a, tmp, env)
            if cond == "alone":
                # The alone pass's extra repetitions get its share of the minutes left after both
                # passes' base repetitions (the loaded base predicted at the alone pass's pace).
                pace = (time.perf_counter() - t0) / max(est["alone"], 1e-9)
                slack = limit - time.perf_counter() - pace * est["loaded"]
                run_extra(cs, a, tmp, env,
                          time.perf_counter() + max(0.0, slack) * est["alone"] / max(est["alone"] + est["loaded"], 1e-9))
            else:
                run_extra(cs, a, tmp, env, limit)
            cells += cs
            if hog:
                hog.kill()
                hog.wait()
                hog = None
    finally:
        if hog:
            hog.kill()
            hog.wait()
        shutil.rmtree(tmp, ignore_errors=True)
    total = time.perf_counter() - t_start
    if a.overhead:
        if a.json:
            with open(a.json, "w") as f:
                json.dump({"overhead": over, "repeat": a.repeat, "seconds": total}, f, indent=1)
        print(f"the script took {total / 60:.1f} min")
        return 0
    print()
    print("Medians with the interquartile range in brackets; auto / best: median of auto over the better median "
          "of 1 and 2 threads, with its 90% bootstrap interval over repetitions.")
    print()
    print("| scene | steps | simulated | condition | runs | 1 thread | 2 threads | auto | auto ends on | "
          "auto / best [90% interval] | goal |")
    print("|---|---|---|---|---|---|---|---|---|---|---|")
    for c in cells:
        p, s = c.p, c.stats
        sim = f"{p['sim_time']:.3g} s" + (" (capped)" if p["capped"] else "")
        goal = ("ok" if s["ok"] else "MISSED") + ("" if s["clear"] else " (unclear)")
        print(f"| {p['scene']} | {p['steps']} | {sim} | {c.cond} | {s['n']} | {fmt_spread(s['1'])} | "
              f"{fmt_spread(s['2'])} | {fmt_spread(s['auto'])} | {fmt_ends(c.ends)} | "
              f"{s['ratio']:.2f} [{s['lo']:.2f}, {s['hi']:.2f}] | {goal} |")
    missed = [c for c in cells if not c.stats["ok"]]
    unclear = [c for c in cells if not c.stats["clear"]]
    print(f"\ngoal (auto <= {GOAL:.2f} x the better of 1 and 2): {len(cells) - len(missed)} of {len(cells)} cells met, "
          f"{len(missed)} missed; {len(unclear)} of {len(cells)} unclear (the 90% interval straddles {GOAL:.2f}); "
          f"the script took {total / 60:.1f} min")
    if a.json:
        rows = [{"scene": c.p["scene"], "condition": c.cond, "steps": c.p["steps"], "sim_time": c.p["sim_time"],
                 "capped": c.p["capped"], "runs": c.runs, "cpu_seconds": c.cpu, "step_ms": c.step_ms, "orders": c.orders,
                 "auto_ends_on": c.ends, "auto_summaries": c.auto_lines, "stats": c.stats} for c in cells]
        with open(a.json, "w") as f:
            json.dump({"rows": rows, "budget": a.budget, "sim": a.sim, "repeat": a.repeat,
                       "max_repeat": a.max_repeat, "minutes": a.minutes, "seconds": total}, f, indent=1)
    return 1 if missed else 0


if __name__ == "__main__":
    sys.exit(main())

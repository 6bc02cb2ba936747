"""Statistics of scripts/contention.py (issue 16's contention benchmark), kept apart from the
timing so that tests/scripts/test_contention_stats.py checks them on fixed inputs.

A cell (one scene, alone or loaded) holds R repetitions; repetition r ran threads 1, 2 and auto
back to back (in the order run_order(r)), so the three times of one repetition share the
machine's state at that moment. The goal compares auto with the better of 1 and 2:

  ratio = median(auto) / min(median(1 thread), median(2 threads))

and is met when ratio <= GOAL (1.10). The uncertainty of the ratio is a percentile bootstrap
over repetitions: whole repetitions are drawn with replacement (keeping the three times of a
repetition together) and the whole statistic is recomputed, including which of 1 and 2 is the
better, so the interval also carries the bias of taking the smaller of two noisy medians (it
makes auto look worse when 1 and 2 are close). A cell is "clear" when the interval lies on one
side of GOAL, else "unclear": more repetitions can then decide it (contention.py adds them while
its time allows). The verdict itself is the point estimate against GOAL, as before: more
repetitions make it more reliable, they do not change what is compared.
"""
import random
import statistics

GOAL = 1.10
SETTINGS = ("1", "2", "auto")
# The six orders of three settings. Any three consecutive repetitions from 0 or 3 form a Latin
# square (each setting once in each position), and the six together put every ordered pair of
# settings next to each other twice, so neither a drift nor what ran just before favours one.
ORDERS = (("1", "2", "auto"), ("2", "auto", "1"), ("auto", "1", "2"),
          ("1", "auto", "2"), ("auto", "2", "1"), ("2", "1", "auto"))


def run_order(rep):
    """The order of the three settings in repetition rep (0-based)."""
    return ORDERS[rep % len(ORDERS)]


def quartiles(v):
    """(first quartile, median, third quartile) of v, linear interpolation between order
    statistics (statistics.quantiles' 'inclusive' method; a single value is all three)."""
    if len(v) == 1:
        return v[0], v[0], v[0]
    q1, q2, q3 = statistics.quantiles(v, n=4, method="inclusive")
    return q1, q2, q3


def ratio_of(t1, t2, tauto):
    """(auto / better median, the better setting '1' or '2') for the times of one cell."""
    m1, m2, ma = statistics.median(t1), statistics.median(t2), statistics.median(tauto)
    best = "1" if m1 <= m2 else "2"
    return ma / min(m1, m2), best


def bootstrap_interval(t1, t2, tauto, level=0.90, draws=2000, seed=1):
    """Percentile bootstrap interval (lo, hi) of ratio_of over repetitions (see the top of the
    file). Deterministic for a given seed."""
    n = len(tauto)
    if not (len(t1) == len(t2) == n) or n == 0:
        raise ValueError("the three settings need the same number of repetitions (at least one)")
    rng = random.Random(seed)
    vals = []
    for _ in range(draws):
        idx = [rng.randrange(n) for _ in range(n)]
        vals.append(ratio_of([t1[i] for i in idx], [t2[i] for i in idx], [tauto[i] for i in idx])[0])
    vals.sort()
    a = (1.0 - level) / 2.0
    lo = vals[max(0, int(a * draws))]
    hi = vals[min(draws - 1, int((1.0 - a) * draws))]
    return lo, hi


def cell_stats(t1, t2, tauto, level=0.90, draws=2000, seed=1):
    """Everything the table reports for one cell: per setting the median, quartiles, min and max
    (seconds); the better fixed count, the ratio, its bootstrap interval, whether the goal is met
    (ratio <= GOAL) and whether that is clear (the interval on the verdict's side of GOAL)."""
    out = {"n": len(tauto)}
    for k, v in zip(SETTINGS, (t1, t2, tauto)):
        q1, med, q3 = quartiles(v)
        out[k] = {"median": med, "q1": q1, "q3": q3, "min": min(v), "max": max(v)}
    ratio, best = ratio_of(t1, t2, tauto)
    lo, hi = bootstrap_interval(t1, t2, tauto, level, draws, seed)
    out.update({"best": best, "ratio": ratio, "lo": lo, "hi": hi, "level": level,
                "ok": ratio <= GOAL,
                "clear": (hi <= GOAL) if ratio <= GOAL else (lo > GOAL)})
    return out


def median_difference(a, b, level=0.90, draws=2000, seed=1):
    """Paired runs a[i], b[i] (run back to back): (median of a[i] - b[i], lo, hi), the interval a
    percentile bootstrap over pairs. Used by contention.py --overhead (auto against the fixed
    count it ended on)."""
    n = len(a)
    if len(b) != n or n == 0:
        raise ValueError("paired samples need the same length (at least one pair)")
    d = [x - y for x, y in zip(a, b)]
    rng = random.Random(seed)
    vals = sorted(statistics.median([d[rng.randrange(n)] for _ in range(n)]) for _ in range(draws))
    lo_q = (1.0 - level) / 2.0
    return (statistics.median(d), vals[max(0, int(lo_q * draws))],
            vals[min(draws - 1, int((1.0 - lo_q) * draws))])


def simulate(cv, t2_over_t1, true_ratio, base, max_reps=None, trials=400, seed=1, draws=400):
    """What the method does with run times of known spread: each run is its setting's true time
    times a lognormal factor with coefficient of variation about cv (1 thread 1.0, 2 threads
    t2_over_t1, auto true_ratio x the better). A cell starts with `base` repetitions; with
    max_reps, unclear cells get one more at a time up to max_reps (contention.py without its time
    limit). Returns (fraction of cells that read a miss, mean repetitions per cell)."""
    rng = random.Random(seed)
    best = min(1.0, t2_over_t1)
    misses = reps = 0
    for _ in range(trials):
        t1, t2, ta = [], [], []
        top, want = max_reps or base, base
        while True:
            while len(ta) < want:
                t1.append(rng.lognormvariate(0.0, cv))
                t2.append(t2_over_t1 * rng.lognormvariate(0.0, cv))
                ta.append(true_ratio * best * rng.lognormvariate(0.0, cv))
            s = cell_stats(t1, t2, ta, draws=draws, seed=rng.randrange(1 << 30))
            if s["clear"] or s["n"] >= top or max_reps is None:
                break
            want += 1
        misses += not s["ok"]
        reps += s["n"]
    return misses / trials, reps / trials


if __name__ == "__main__":
    # python3 scripts/contention_stats.py: the table of docs/BENCHMARKS.md ("Contention
    # benchmark: method"): how often a cell reads a miss when auto is as fast as the better count
    # (true ratio 1.00) or 5% slower, for fixed repetitions and for the extra-repetition rule.
    print("| run-to-run spread (cv) | 1 vs 2 threads | true auto / best | 3 runs | 5 runs | 9 runs | 3 + extra up to 9 (mean runs) |")
    print("|---|---|---|---|---|---|---|")
    for cv in (0.05, 0.07, 0.10):
        for far, label in ((1.6, "2 is 1.6x slower"), (1.0, "equal")):
            for true in (1.00, 1.05):
                fixed = [simulate(cv, far, true, n)[0] for n in (3, 5, 9)]
                m, r = simulate(cv, far, true, 3, 9)
                print(f"| {cv:.2f} | {label} | {true:.2f} | " + " | ".join(f"{f:.3f}" for f in fixed)
                      + f" | {m:.3f} ({r:.1f}) |", flush=True)

"""scripts/contention_stats.py on fixed inputs: the ratio against the better of 1 and 2, the
spread, the bootstrap interval over repetitions (against an exact enumeration of every
resample) and the run order's balance. usage: test_contention_stats.py <scripts dir>"""
import itertools
import os
import sys
import unittest

sys.path.insert(0, sys.argv.pop(1) if len(sys.argv) > 1 else
                os.path.join(os.path.dirname(__file__), "..", "..", "scripts"))
import contention_stats as cs  # noqa: E402
import contention  # noqa: E402


def exact_ratios(t1, t2, ta):
    """The ratio for every one of the n^n resamples of n repetitions (equally likely), computed
    here without contention_stats: sorted medians by hand."""
    def med(v):
        s = sorted(v)
        k = len(s)
        return s[k // 2] if k % 2 else 0.5 * (s[k // 2 - 1] + s[k // 2])
    n = len(ta)
    out = []
    for idx in itertools.product(range(n), repeat=n):
        out.append(med([ta[i] for i in idx]) / min(med([t1[i] for i in idx]), med([t2[i] for i in idx])))
    return sorted(out)


class Ratio(unittest.TestCase):
    def test_better_of_one_and_two(self):
        # 1 thread is the better (median 1.0 against 2.0): 1.05 / 1.0.
        r, best = cs.ratio_of([1.0, 0.9, 1.2], [2.0, 2.1, 1.9], [1.05, 1.0, 1.3])
        self.assertEqual(best, "1")
        self.assertAlmostEqual(r, 1.05)
        # 2 threads the better: medians 0.8 (1 thread: 1.5) and auto 0.84.
        r, best = cs.ratio_of([1.5, 1.6, 1.4], [0.8, 0.7, 0.9], [0.84, 0.9, 0.8])
        self.assertEqual(best, "2")
        self.assertAlmostEqual(r, 0.84 / 0.8)

    def test_even_count_median(self):
        r, _ = cs.ratio_of([1.0, 3.0], [4.0, 4.0], [2.0, 4.0])
        self.assertAlmostEqual(r, 3.0 / 2.0)

    def test_spread(self):
        s = cs.cell_stats([1, 2, 3, 4, 5], [9, 9, 9, 9, 9], [1, 2, 3, 4, 5])
        # inclusive quartiles of 1..5: 2, 3, 4; min 1, max 5
        self.assertEqual((s["1"]["q1"], s["1"]["median"], s["1"]["q3"]), (2, 3, 4))
        self.assertEqual((s["auto"]["min"], s["auto"]["max"]), (1, 5))
        self.assertEqual(s["n"], 5)


class Interval(unittest.TestCase):
    def test_equal_times_give_a_point(self):
        s = cs.cell_stats([1.0] * 4, [2.0] * 4, [1.0] * 4)
        self.assertEqual((s["ratio"], s["lo"], s["hi"]), (1.0, 1.0, 1.0))
        self.assertTrue(s["ok"] and s["clear"])

    def test_against_every_resample(self):
        # Four repetitions: 256 equally likely resamples. The Monte Carlo percentiles (4000
        # draws) must fall between the exact 2% and 8% (lo) and 92% and 98% (hi) quantiles.
        t1 = [1.00, 1.08, 0.95, 1.20]
        t2 = [1.02, 0.97, 1.15, 1.01]
        ta = [1.10, 1.00, 1.25, 1.05]
        ex = exact_ratios(t1, t2, ta)
        lo, hi = cs.bootstrap_interval(t1, t2, ta, level=0.90, draws=4000, seed=7)
        q = lambda p: ex[min(len(ex) - 1, int(p * len(ex)))]  # noqa: E731
        self.assertGreaterEqual(lo, q(0.02))
        self.assertLessEqual(lo, q(0.08))
        self.assertGreaterEqual(hi, q(0.92))
        self.assertLessEqual(hi, q(0.98))
        self.assertLess(lo, hi)

    def test_deterministic(self):
        a = cs.bootstrap_interval([1, 2, 3], [2, 3, 1], [3, 1, 2], seed=3)
        b = cs.bootstrap_interval([1, 2, 3], [2, 3, 1], [3, 1, 2], seed=3)
        self.assertEqual(a, b)

    def test_unequal_lengths_refused(self):
        with self.assertRaises(ValueError):
            cs.bootstrap_interval([1, 2], [1, 2, 3], [1, 2, 3])

    def test_verdicts(self):
        # auto 1.3x the better count in every repetition: a clear miss.
        s = cs.cell_stats([1.0, 1.01, 0.99, 1.0, 1.02], [2.0] * 5, [1.3, 1.31, 1.29, 1.3, 1.33])
        self.assertFalse(s["ok"])
        self.assertTrue(s["clear"])
        self.assertGreater(s["lo"], cs.GOAL)
        # A point estimate just under the goal from widely spread times: met, but not clearly.
        s = cs.cell_stats([1.0, 0.7, 1.3, 1.0, 0.8], [2.0] * 5, [1.08, 1.5, 0.8, 1.2, 0.9])
        self.assertAlmostEqual(s["ratio"], 1.08)
        self.assertTrue(s["ok"])
        self.assertFalse(s["clear"])
        self.assertLessEqual(s["lo"], s["ratio"])
        self.assertGreater(s["hi"], cs.GOAL)


class Paired(unittest.TestCase):
    def test_median_difference_against_every_resample(self):
        a = [1.00, 1.20, 0.90, 1.05, 1.10]
        b = [0.95, 1.10, 1.00, 1.00, 1.02]
        d = [x - y for x, y in zip(a, b)]  # 0.05, 0.10, -0.10, 0.05, 0.08
        med, lo, hi = cs.median_difference(a, b, level=0.90, draws=4000, seed=5)
        self.assertAlmostEqual(med, 0.05)
        # exact distribution of the resampled median: all 5^5 resamples
        ex = sorted(sorted(d[i] for i in idx)[2] for idx in itertools.product(range(5), repeat=5))
        q = lambda p: ex[min(len(ex) - 1, int(p * len(ex)))]  # noqa: E731
        self.assertGreaterEqual(lo, q(0.02))
        self.assertLessEqual(lo, q(0.08))
        self.assertGreaterEqual(hi, q(0.92))
        self.assertLessEqual(hi, q(0.98))

    def test_no_difference(self):
        self.assertEqual(cs.median_difference([2.0, 3.0], [2.0, 3.0]), (0.0, 0.0, 0.0))
        with self.assertRaises(ValueError):
            cs.median_difference([1.0], [])


class Simulation(unittest.TestCase):
    def test_without_spread_the_verdict_is_the_true_ratio(self):
        # cv 0: every run is its true time, so the cell reads exactly the true ratio; it is
        # clear at once (the interval is a point), so the extra-repetition rule adds nothing.
        self.assertEqual(cs.simulate(0.0, 1.6, 1.05, 3, trials=20), (0.0, 3.0))
        self.assertEqual(cs.simulate(0.0, 1.0, 1.2, 3, trials=20), (1.0, 3.0))
        self.assertEqual(cs.simulate(0.0, 0.6, 1.2, 3, max_reps=9, trials=20), (1.0, 3.0))

    def test_extra_repetitions_stay_within_the_bounds(self):
        m, r = cs.simulate(0.07, 1.0, 1.0, 3, max_reps=6, trials=60, seed=2)
        self.assertTrue(0.0 <= m <= 1.0)
        self.assertTrue(3.0 <= r <= 6.0)


class Order(unittest.TestCase):
    def test_latin_squares_and_pairs(self):
        orders = [cs.run_order(r) for r in range(6)]
        self.assertEqual(len(set(orders)), 6)  # all six permutations
        for block in (orders[:3], orders[3:]):
            for pos in range(3):  # each setting once in each position
                self.assertEqual(sorted(o[pos] for o in block), sorted(cs.SETTINGS))
        pairs = {}
        for o in orders:
            for a, b in zip(o, o[1:]):
                pairs[(a, b)] = pairs.get((a, b), 0) + 1
        self.assertEqual(len(pairs), 6)
        self.assertTrue(all(c == 2 for c in pairs.values()))
        self.assertEqual(cs.run_order(6), cs.run_order(0))


class Plan(unittest.TestCase):
    """contention.frames_for: the frames of a planned run (the rest of plan_scene runs loom)."""
    def test_uncapped_runs_whole_frames_covering_the_simulated_time(self):
        self.assertEqual(contention.frames_for(500, 500, 8), (63, 8))     # 504 steps >= 500
        self.assertEqual(contention.frames_for(900, 500, 8), (63, 8))

    def test_capped_runs_whole_frames_within_the_steps(self):
        self.assertEqual(contention.frames_for(375, 500, 8), (46, 8))     # 368 steps
        self.assertEqual(contention.frames_for(8, 500, 8), (1, 8))

    def test_fewer_steps_than_a_frame_make_one_short_frame(self):
        self.assertEqual(contention.frames_for(5, 500, 8), (1, 5))
        self.assertEqual(contention.frames_for(0, 500, 8), (1, 1))


if __name__ == "__main__":
    unittest.main()

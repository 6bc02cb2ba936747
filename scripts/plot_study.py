#!/usr/bin/env python3
"""Plot a Loom study: error against wall time per simulated second, one line per combo.

usage: plot_study.py study.csv study.png
One panel per measurement time. Points are the step ladder (h0 / 2^k); runs that diverged,
failed or timed out are drawn as crosses on the top edge of the panel."""
import csv
import sys
from collections import defaultdict

from loom_plot import require_matplotlib

require_matplotlib()
import matplotlib
matplotlib.use("Agg")
import matplotlib.pyplot as plt


def main(src, dst):
    rows = list(csv.DictReader(open(src)))
    times = sorted({float(r["time"]) for r in rows})
    fig, axes = plt.subplots(1, len(times), figsize=(6 * len(times), 4.8), squeeze=False)
    for ax, t in zip(axes[0], times):
        by_combo = defaultdict(list)
        for r in rows:
            if float(r["time"]) == t:
                by_combo[r["combo"]].append(r)
        ok_err = [float(r["rms_error"]) for r in rows if r["status"] == "ok" and float(r["rms_error"]) > 0]
        top = max(ok_err) * 3 if ok_err else 1.0
        for name, rs in by_combo.items():
            ok = [r for r in rs if r["status"] == "ok" and float(r["rms_error"]) > 0]
            bad = [r for r in rs if r["status"] != "ok"]
            line, = ax.loglog([float(r["wall_per_sim_second"]) for r in ok], [float(r["rms_error"]) for r in ok],
                              "o-", label=name, markersize=4)
            if bad:
                ax.plot([max(float(r["h"]), 1e-9) * 0 + (min(float(x["wall_per_sim_second"]) for x in ok) if ok else 1e-3)
                         for r in bad], [top] * len(bad), "x", color=line.get_color(), markersize=8)
        ax.set_xlabel("wall time per simulated second (s)")
        ax.set_ylabel("RMS position error / cloth size")
        ax.set_title(f"t = {t:g} s (x: diverged or failed)")
        ax.grid(True, which="both", alpha=0.3)
    axes[0][0].legend(fontsize=7)
    fig.tight_layout()
    fig.savefig(dst, dpi=110)


if __name__ == "__main__":
    main(sys.argv[1], sys.argv[2])

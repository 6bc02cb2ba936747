#!/usr/bin/env python3
"""Plot a Loom stability atlas (`loom study ... --stability` writes stability.csv): the largest
stable step of each combo against the swept value, log-log, with the bracket
[h_stable, h_unstable] the bisection left as a band.

usage: plot_stability.py stability.csv stability.png
Exit 3 when matplotlib cannot be imported."""
import sys
from collections import defaultdict

from loom_plot import csv_rows, pyplot_or_exit


def number(text):
    try:
        return float(text)
    except ValueError:
        return None


def main(src, dst):
    plt = pyplot_or_exit("plot_stability.py")
    rows = csv_rows(src, "plot_stability.py")
    by_combo = defaultdict(list)
    for r in rows:
        by_combo[r["combo"]].append(r)
    key = rows[0]["key"]
    numeric = all(number(r["value"]) is not None for r in rows)
    labels = sorted({r["value"] for r in rows}, key=lambda v: number(v) if numeric else v)
    fig, ax = plt.subplots(figsize=(8, 5.5))
    for name, rs in by_combo.items():
        xs = [number(r["value"]) if numeric else labels.index(r["value"]) for r in rs]
        lo = [float(r["h_stable"]) for r in rs]
        hi = [float(r["h_unstable"]) if float(r["h_unstable"]) > 0 else float(r["h_stable"]) for r in rs]
        order = sorted(range(len(xs)), key=lambda i: xs[i])
        xs, lo, hi = [xs[i] for i in order], [lo[i] for i in order], [hi[i] for i in order]
        line, = ax.plot(xs, lo, "o-", label=name, markersize=4)
        ax.fill_between(xs, lo, hi, color=line.get_color(), alpha=0.2)
    ax.set_yscale("log")
    if numeric:
        ax.set_xscale("log")
    else:
        ax.set_xticks(range(len(labels)))
        ax.set_xticklabels(labels, rotation=30, fontsize=8)
    ax.set_xlabel(key)
    ax.set_ylabel("largest stable step h (s)")
    ax.set_title("stability atlas (band: bisection bracket)")
    ax.grid(True, which="both", alpha=0.3)
    ax.legend(fontsize=7)
    fig.tight_layout()
    fig.savefig(dst, dpi=100)


if __name__ == "__main__":
    if len(sys.argv) != 3:
        sys.exit(__doc__)
    main(sys.argv[1], sys.argv[2])

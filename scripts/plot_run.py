#!/usr/bin/env python3
"""Plot the stats.csv of a Loom run: energies, largest strain, solver work and time per step
against simulated time (what `loom plot RUN_DIR` draws).

usage: plot_run.py stats.csv stats.png
Exit 3 when matplotlib cannot be imported (loom plot then names the package to install)."""
import os
import sys

from loom_plot import csv_rows, pyplot_or_exit


def main(src, dst):
    plt = pyplot_or_exit("plot_run.py")
    rows = csv_rows(src, "plot_run.py")
    t = [float(r["time"]) for r in rows]
    col = lambda k: [float(r[k]) for r in rows]  # noqa: E731
    # force_evaluations and linear_iterations are running totals: per frame = differences.
    def per_frame(k):
        v = col(k)
        return [0.0] + [b - a for a, b in zip(v, v[1:])]

    fig, ax = plt.subplots(2, 2, figsize=(11, 7), sharex=True)
    e = ax[0][0]
    for k, label in (("kinetic_energy", "kinetic"), ("gravitational_energy", "gravitational"),
                     ("elastic_energy", "elastic"), ("total_energy", "total")):
        e.plot(t, col(k), label=label, lw=2 if k == "total_energy" else 1)
    e.set_ylabel("energy (J)")
    e.legend(fontsize=8)
    e.set_title("energies")
    s = ax[0][1]
    s.plot(t, col("max_strain"), color="C3")
    s.set_ylabel("largest strain")
    s.set_title("largest strain")
    it = ax[1][0]
    it.plot(t, per_frame("linear_iterations"), label="linear iterations", color="C4")
    it.plot(t, per_frame("force_evaluations"), label="force evaluations", color="C5")
    it.set_ylabel("per frame")
    it.set_title("solver work")
    it.legend(fontsize=8)
    w = ax[1][1]
    w.plot(t, col("wall_ms_per_step"), color="C2", label="whole step")
    if "self_collision_ms_per_step" in rows[0]:  # scenes with self_collision
        w.plot(t, col("self_collision_ms_per_step"), color="C1", label="of it self-collision")
        w.legend(fontsize=8)
    w.set_ylabel("wall time per step (ms)")
    w.set_title("step time")
    for a in (it, w):
        a.set_xlabel("simulated time (s)")
    for a in fig.axes:
        a.grid(True, alpha=0.3)
    fig.suptitle(os.path.basename(os.path.dirname(os.path.abspath(src))) or src)
    fig.tight_layout()
    fig.savefig(dst, dpi=100)


if __name__ == "__main__":
    if len(sys.argv) != 3:
        sys.exit(__doc__)
    main(sys.argv[1], sys.argv[2])

#!/usr/bin/env python3
"""Draw a material file's curves as Loom uses them: the samples (converted to the model's measure),
the interpolant, its linear extension past the data, and the energy density.

  scripts/plot_material.py materials/wool.yaml out/wool_curves.png [--interpolation bspline]
      [--tool build/bin/loom-material-curves]

The numbers come from loom-material-curves (the same code that loads the material in a run),
called with an argument vector.
"""
import argparse
import csv
import io
import os
import subprocess
import sys
from collections import defaultdict

from loom_plot import require_matplotlib


def main():
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("material")
    ap.add_argument("png")
    ap.add_argument("--interpolation", default="monotone_cubic", choices=["monotone_cubic", "bspline"])
    ap.add_argument("--tool", default=os.path.join(os.path.dirname(os.path.abspath(__file__)), "..", "build", "bin",
                                                   "loom-material-curves"))
    a = ap.parse_args()
    require_matplotlib()
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    out = subprocess.run([a.tool, a.material, "--interpolation", a.interpolation], check=True, capture_output=True,
                         text=True).stdout
    rows = defaultdict(lambda: defaultdict(list))
    for r in csv.DictReader(io.StringIO(out)):
        rows[r["curve"]][r["kind"]].append(r)
    fig, axes = plt.subplots(2, 3, figsize=(15, 8), squeeze=False)
    for col, name in enumerate(("weft", "warp", "shear")):
        c = rows[name]
        ax, ae = axes[0][col], axes[1][col]
        for kind, style, label in (("data", "-", "interpolant (%s)" % a.interpolation),
                                   ("extension", ":", "linear extension past the data")):
            pts = sorted(c[kind], key=lambda r: float(r["strain"]))
            # plot each side of the extension separately (no line across the data)
            segs, cur = [], []
            for r in pts:
                if cur and kind == "extension" and float(r["strain"]) > float(c["sample"][0]["strain"]) > float(cur[-1]["strain"]):
                    segs.append(cur)
                    cur = []
                cur.append(r)
            segs.append(cur)
            for k, seg in enumerate(segs):
                xs = [float(r["strain"]) for r in seg]
                ax.plot(xs, [float(r["stress"]) for r in seg], style, color="C0", label=label if k == 0 else None)
                ae.plot(xs, [float(r["energy"]) for r in seg], style, color="C1", label=("energy W" if kind == "data" else None) if k == 0 else None)
        ax.plot([float(r["strain"]) for r in c["sample"]], [float(r["stress"]) for r in c["sample"]], "o", mfc="none",
                color="k", label="samples (model measure)")
        ax.set_title("%s: stress (N/m, green_pk2)" % name)
        ax.set_xlabel("strain (%s)" % ("u.v" if name == "shear" else "Green-Lagrange"))
        ae.set_title("%s: energy density W (J/m^2)" % name)
        ae.set_xlabel(ax.get_xlabel())
        ax.legend(fontsize=8)
        ae.legend(fontsize=8)
    fig.suptitle(os.path.basename(a.material))
    fig.tight_layout()
    d = os.path.dirname(a.png)
    if d:
        os.makedirs(d, exist_ok=True)
    fig.savefig(a.png, dpi=110)
    print("wrote", a.png)


if __name__ == "__main__":
    main()

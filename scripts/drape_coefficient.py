#!/usr/bin/env python3
"""Drape coefficient of a run's last OBJ frame (Cusick): DC = (A_p - A_s) / (A_f - A_s), where
A_p is the area of the draped cloth's projection onto the horizontal plane (the union of its
projected triangles: overlapping folds count once), A_s the support disc's area pi r^2 and A_f
the flat specimen's area. A_p is measured by rasterising the projected triangles on a square
grid of `--pixel` (default 0.25 mm) and counting covered pixel centres.
Usage: scripts/drape_coefficient.py RUN_DIR_OR_OBJ --support-radius R --flat-area A [--up y]
"""
import argparse
import glob
import math
import os


def read_obj(path):
    verts, faces = [], []
    with open(path) as f:
        for line in f:
            p = line.split()
            if not p:
                continue
            if p[0] == "v":
                verts.append(tuple(float(c) for c in p[1:4]))
            elif p[0] == "f":
                idx = [int(t.split("/")[0]) - 1 for t in p[1:]]
                for k in range(1, len(idx) - 1):
                    faces.append((idx[0], idx[k], idx[k + 1]))
    return verts, faces


def projected_area(verts, faces, up, pixel):
    a, b = [k for k in range(3) if k != up]
    pts = [(v[a], v[b]) for v in verts]
    xmin = min(p[0] for p in pts); ymin = min(p[1] for p in pts)
    covered = set()
    for f in faces:
        (x0, y0), (x1, y1), (x2, y2) = (pts[f[0]], pts[f[1]], pts[f[2]])
        d = (x1 - x0) * (y2 - y0) - (x2 - x0) * (y1 - y0)
        if d == 0:
            continue
        i0 = int(math.floor((min(x0, x1, x2) - xmin) / pixel)); i1 = int(math.ceil((max(x0, x1, x2) - xmin) / pixel))
        j0 = int(math.floor((min(y0, y1, y2) - ymin) / pixel)); j1 = int(math.ceil((max(y0, y1, y2) - ymin) / pixel))
        for i in range(i0, i1 + 1):
            px = xmin + (i + 0.5) * pixel
            for j in range(j0, j1 + 1):
                py = ymin + (j + 0.5) * pixel
                l1 = ((x1 - px) * (y2 - py) - (x2 - px) * (y1 - py)) / d
                l2 = ((x2 - px) * (y0 - py) - (x0 - px) * (y2 - py)) / d
                if l1 >= 0 and l2 >= 0 and l1 + l2 <= 1:
                    covered.add((i, j))
    return len(covered) * pixel * pixel


def main():
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("run")
    ap.add_argument("--support-radius", type=float, required=True)
    ap.add_argument("--flat-area", type=float, required=True)
    ap.add_argument("--up", default="y", choices=["x", "y", "z"])
    ap.add_argument("--pixel", type=float, default=2.5e-4)
    args = ap.parse_args()
    path = args.run
    if os.path.isdir(path):
        frames = sorted(glob.glob(os.path.join(path, "frame_*.obj")))
        if not frames:
            raise SystemExit(f"{path}: no frame_*.obj files")
        path = frames[-1]
    verts, faces = read_obj(path)
    ap_area = projected_area(verts, faces, "xyz".index(args.up), args.pixel)
    a_s = math.pi * args.support_radius ** 2
    dc = (ap_area - a_s) / (args.flat_area - a_s)
    print(f"{path}: projected area {ap_area:.6f} m^2, support {a_s:.6f} m^2, flat {args.flat_area:.6f} m^2, "
          f"drape coefficient {dc:.4f}")


if __name__ == "__main__":
    main()

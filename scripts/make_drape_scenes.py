#!/usr/bin/env python3
"""Write the Cusick-style drape scenes scenes/drape_<label>.yaml: a 0.3 m x 0.3 m square of a
measured fabric (materials/wang2011/), 31 x 31 vertices, clamped flat on a central support
disc of radius 0.09 m (every vertex within it pinned, as the Cusick tester clamps the
specimen between two discs), released under gravity and stepped by baraff_witkin at
h = 1/60 s for 5 s. scripts/drape_coefficient.py measures the drape coefficient of the
last frame. Usage: scripts/make_drape_scenes.py [repository root]
"""
import os
import sys

FABRICS = [("denim", "11oz-black-denim", "99% cotton denim, jeans"),
           ("knit", "gray-interlock", "60/40 cotton/polyester interlock knit, t-shirt"),
           ("polyester", "white-dots-on-blk", "100% polyester, tablecloth")]
N, SIDE, SUPPORT = 31, 0.3, 0.09


def support_vertices():
    h = SIDE / (N - 1)
    c = SIDE / 2
    out = []
    for iy in range(N):
        for ix in range(N):
            if (ix * h - c) ** 2 + (iy * h - c) ** 2 <= SUPPORT ** 2 + 1e-12:
                out.append(iy * N + ix)
    return out


def main():
    root = sys.argv[1] if len(sys.argv) > 1 else os.path.join(os.path.dirname(os.path.abspath(__file__)), "..")
    pins = support_vertices()
    for label, fabric, what in FABRICS:
        text = f"""# Cusick-style drape of {fabric} ({what}; Wang et al. 2011, materials/wang2011/):
# a {SIDE} m square, {N} x {N} vertices, clamped flat on a central support disc of radius {SUPPORT} m
# (the {len(pins)} vertices within it are pinned), released under gravity, baraff_witkin at h = 1/60 s.
# Written by scripts/make_drape_scenes.py. Drape coefficient of the last frame:
#   scripts/drape_coefficient.py out/drape_{label} --support-radius {SUPPORT} --flat-area {SIDE * SIDE:g}
name: drape_{label}
description: {fabric} square draped over a {2 * SUPPORT:g} m support disc (Cusick-style), gnatv + hinge bending, baraff_witkin h = 1/60
mesh:
  grid: {{nx: {N}, ny: {N}, width: {SIDE}, height: {SIDE}, plane: xz}}   # weft along x, warp along -z
material:
  type: gnatv
  fabric: {fabric}               # membrane curves and anisotropic bending from the library
integrator:
  type: baraff_witkin
  dt: 0.0166666666666667         # 1/60 s
  substeps: 1
  kang_cho_damping: 0.001
solver:
  type: [cholmod, eigen_ldlt]
backend: cpu
threads: auto
pins: [{{vertices: [{", ".join(str(p) for p in pins)}]}}]
gravity: [0, -9.81, 0]
frames: 300                      # 5 s
output: {{dir: out/drape_{label}, obj: true, stats: true, every: 30}}
"""
        with open(os.path.join(root, "scenes", f"drape_{label}.yaml"), "w") as f:
            f.write(text)
    print("wrote scenes/drape_{%s}.yaml (%d support vertices)" % (",".join(l for l, _, _ in FABRICS), len(pins)))


if __name__ == "__main__":
    main()

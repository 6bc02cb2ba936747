#!/usr/bin/env python3
"""Convert the Wang, O'Brien & Ramamoorthi 2011 measured fabrics (ARCSim JSON tables in
materials/wang2011/data/) into Loom material files (gnatv curves + hinge bending), written
to materials/wang2011/<name>.yaml. The reading of the tables is documented in
materials/wang2011/README.md and docs/NUMERICS.md section 6; tests/bending/test_fabrics.cpp
checks the result against an independent implementation of the model.

Usage: scripts/wang2011_to_loom.py [repository root]   (standard library only)
"""
import glob
import json
import math
import os
import sys

STRAIN_STEP = 0.005
AXIAL_RANGE = (-0.2, 0.6)   # Green strain of the weft and warp curves
SHEAR_RANGE = (-0.6, 0.6)   # eps_uv = u.v


def stiffness(row0, row_angle, stretch, comp):
    """ARCSim's stiffness coefficient (after its factor 2) at the largest principal stretch
    `stretch`, for the direction row `row_angle`: linear in (stretch - 1) from the zero-strain
    row (stretch 1) to the direction row (stretch 7/6), constant beyond, clamped at 0."""
    s = min(max(6.0 * (stretch - 1.0), 0.0), 1.0)
    return 2.0 * max((1.0 - s) * row0[comp] + s * row_angle[comp], 0.0)


def axial_curve(rows, angle_row, comp):
    """sigma(eps) = k(eps) eps for uniaxial Green strain eps along weft (angle row 1, comp 0)
    or warp (row 5, comp 2). Under compression the largest stretch is 1 (zero-strain row)."""
    n = int(round((AXIAL_RANGE[1] - AXIAL_RANGE[0]) / STRAIN_STEP))
    out = []
    for k in range(n + 1):
        e = AXIAL_RANGE[0] + k * STRAIN_STEP
        if abs(e) < 1e-12:
            e = 0.0
        stretch = math.sqrt(1.0 + 2.0 * e) if e > 0 else 1.0
        out.append(stiffness(rows[0], rows[angle_row], stretch, comp) * e)
    return out


def shear_curve(rows):
    """sigma_uv(eps_uv) = S_01 at G_01 = eps_uv / 2: k3 G_01; the largest stretch is
    sqrt(1 + |eps_uv|) along 45 degrees (row 3)."""
    n = int(round((SHEAR_RANGE[1] - SHEAR_RANGE[0]) / STRAIN_STEP))
    out = []
    for k in range(n + 1):
        e = SHEAR_RANGE[0] + k * STRAIN_STEP
        if abs(e) < 1e-12:
            e = 0.0
        stretch = math.sqrt(1.0 + abs(e))
        out.append(stiffness(rows[0], rows[3], stretch, 3) * 0.5 * e)
    return out


def monotone_envelope(values, start):
    """Hold the peak where the secant stress would fall with strain (a negative stiffness,
    which Loom's curves refuse): running maximum upward from zero strain, running minimum
    downward. Changes only the shear of ivory-rib-knit and navy-sparkle-sweat, beyond
    |eps_uv| ~ 0.2."""
    out = list(values)
    zero = int(round(-start / STRAIN_STEP))
    for i in range(zero + 1, len(out)):
        out[i] = max(out[i], out[i - 1])
    for i in range(zero - 1, -1, -1):
        out[i] = min(out[i], out[i + 1])
    return out


def fmt_list(values):
    return "[" + ", ".join("%.9g" % v for v in values) + "]"


def convert(path, out_dir):
    name = os.path.splitext(os.path.basename(path))[0]
    with open(path) as f:
        d = json.load(f)
    rows = d["stretching"]
    bend = d["bending"]
    assert len(rows) == 6 and all(len(r) == 4 for r in rows), path
    assert len(bend) == 3 and all(len(r) == 5 for r in bend), path
    # ARCSim's bending rows are by the hinge edge's angle to the weft (0, 45, 90 degrees);
    # its energy is ke theta^2 |e|^2 / (8 (A1 + A2)) = Loom's with B = ke / 4. An edge along
    # the weft bends with the curvature along the warp. Sample 0 (curvature -> 0).
    b_warp, b_bias, b_weft = (bend[0][0] / 4.0, bend[1][0] / 4.0, bend[2][0] / 4.0)
    text = []
    text.append("# %s: Wang, O'Brien & Ramamoorthi 2011 measured fabric as a Loom material file" % name)
    text.append("# (gnatv curves + hinge bending), written by scripts/wang2011_to_loom.py from")
    text.append("# data/%s.json; the reading of the tables is in README.md. Do not edit by hand." % name)
    text.append("name: %s" % name)
    text.append('source: "Wang, O\'Brien, Ramamoorthi 2011, Data-Driven Elastic Models for Cloth (ARCSim '
                'materials/%s.json)"' % name)
    text.append("units: {stress: N/m, strain: green_lagrange, areal_density: kg/m^2, bending: N m}")
    text.append("areal_density: %.9g" % d["density"])
    # The Wang model gives stress = k(strain) * Green strain (an energy in Green strain): the
    # curves are the model's own second Piola-Kirchhoff stress against Green-Lagrange strain.
    text.append("curves:")
    text.append("  weft: {measure: green_pk2, start: %.9g, step: %.9g, stress: %s}" % (AXIAL_RANGE[0], STRAIN_STEP,
                                                                    fmt_list(monotone_envelope(axial_curve(rows, 1, 0), AXIAL_RANGE[0]))))
    text.append("  warp: {measure: green_pk2, start: %.9g, step: %.9g, stress: %s}" % (AXIAL_RANGE[0], STRAIN_STEP,
                                                                    fmt_list(monotone_envelope(axial_curve(rows, 5, 2), AXIAL_RANGE[0]))))
    text.append("  shear: {measure: green_pk2, start: %.9g, step: %.9g, stress: %s}" % (SHEAR_RANGE[0], STRAIN_STEP,
                                                                     fmt_list(monotone_envelope(shear_curve(rows), SHEAR_RANGE[0]))))
    text.append("bending: {stiffness: {weft: %.9g, warp: %.9g, bias: %.9g}}" % (b_weft, b_warp, b_bias))
    with open(os.path.join(out_dir, name + ".yaml"), "w") as f:
        f.write("\n".join(text) + "\n")
    return name


def main():
    root = sys.argv[1] if len(sys.argv) > 1 else os.path.join(os.path.dirname(os.path.abspath(__file__)), "..")
    base = os.path.join(root, "materials", "wang2011")
    names = [convert(p, base) for p in sorted(glob.glob(os.path.join(base, "data", "*.json")))]
    print("wrote %d fabrics: %s" % (len(names), ", ".join(names)))


if __name__ == "__main__":
    main()

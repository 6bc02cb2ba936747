#!/usr/bin/env python3
"""Write the garment-on-body meshes of scenes/skirt_on_body.yaml: a low-poly body (a closed
surface of revolution) and a flared skirt (an open surface of revolution, irregularly triangulated).

Usage: scripts/make_garment.py [OUT_DIR]      (default: scenes/meshes next to this script's repo)
  writes OUT_DIR/body_hips.obj and OUT_DIR/skirt_flared.obj and prints what it measured.

Provenance: written for Loom (2026-11-30); standard library only; deterministic (a fixed
seed), so the committed OBJ files are what this script writes.

Body (metres, y up, axis x = z = 0): a surface of revolution of the meridian r(y) below,
circular cross-sections. Between the knots (y, r) = (0.05, 0.12) knee, (0.45, 0.175) hips,
(0.62, 0.13) waist, (0.76, 0.15) chest, r(y) is a half cosine (r0 + (r1 - r0)(1 - cos pi w)/2,
w the fraction of the segment), so r' = 0 at every knot; below the knee and above the chest
a quarter ellipse closes the body at the poles y = 0 and y = 0.82. tests/colliders/
test_skirt_on_body.cpp repeats this profile (BODY_KNOTS, the caps) as the analytic body the
cloth is checked against: keep the two in step. The mesh is 32 vertices around each of 37
rings (3 cm apart up the side, 6 more on each cap by angle) plus two poles: 2368 faces,
outward (counter-clockwise seen from outside), closed and manifold. Its faces lie inside the
analytic surface by at most the depth printed (1.6 mm, on the hips and the caps).

Skirt: an open surface of revolution around the body, in the scene's rest pose. Its top ring
(48 vertices, exactly at y = 0.62, what the scene's pin box selects) has radius 0.14 (waist
0.13 + 5 mm collider thickness + 5 mm); down to the hips (y = 0.45) it follows the body
5 mm outside the thickness (fitted), and below them it flares: the slope dr/d(-y) grows
linearly from 0 to FLARE = 0.7 over 8 cm, then stays, down to the hem (an exact ring at
y = 0.20, radius 0.332). The flare is more cloth than the hips hold up: under gravity it falls
into folds. Rings about 1.8 cm apart along the profile hold a number of vertices proportional
to their circumference (48 at the top, 114 at the hem), each interior vertex jittered along
the surface (along the profile and around, up to 22% of the spacing; it stays on the surface
of revolution), and neighbouring rings are zipped by the shorter diagonal: an irregular
triangulation, not a grid (edges 1.0-3.1 cm, mean 2.0 cm).

Texture coordinates: conformal ones of the surface of revolution, u = |angle| x r_top
and v = r_top x (integral of ds / r down the profile), so that an edge's direction on the
skirt (its angle to the weft, which anisotropic hinge bending uses) is its direction in
(u, v), and the warp (the texture v axis) runs down the skirt, the weft around it. The
texture's scale follows 1 / r: a texture's weave looks 2.4 times larger at the hem than at
the waist in renders. The angle is taken in (-pi, pi] and u folds back at 0 and pi: the OBJ
loader keeps one vt per vertex, so a tube cannot carry a u that grows once around it (the
triangles across the seam would span the whole texture: a squeezed stripe in renders, and
hinges that read as weft-wise). Nothing physical changes with the fold: gnatv's weft
direction depends only on the v differences within a triangle (dP/du up to its sign, which
the material does not see), and a hinge's rigidity only on its angle to the weft up to a
reflection. (The loader now keeps a vt per face corner, so a real seam would work too; this
script keeps the fold so that the shipped mesh stays as it is.)
"""
import math
import os
import random
import sys

# Meridian knots (y, r) between which r(y) is a half cosine; the caps close the ends.
BODY_KNOTS = [(0.05, 0.12), (0.45, 0.175), (0.62, 0.13), (0.76, 0.15)]
BOTTOM_POLE = 0.0   # the bottom cap: a quarter ellipse from (0.05, 0.12) down to (0, 0)
TOP_POLE = 0.82     # the top cap: a quarter ellipse from (0.76, 0.15) up to (0, 0.82)
BODY_AROUND = 32
BODY_CAP_RINGS = 6

WAIST_Y = 0.62
COLLIDER_THICKNESS = 0.005
SKIRT_GAP = 0.005         # beyond the collider thickness, from the waist to the hips
SKIRT_TOP_R = 0.13 + COLLIDER_THICKNESS + SKIRT_GAP
HEM_Y = 0.20
FLARE = 0.7               # dr/d(-y) of the flare below the hips
FLARE_BLEND = 0.08        # the flare's slope grows linearly over this drop below the hips
SKIRT_TOP_N = 48
SKIRT_RING_DS = 0.018     # ring spacing along the profile (m)
JITTER = 0.22             # fraction of the spacing
SEED = 20261130


def body_radius(y):
    """r(y) of the body's meridian between the first and last knot."""
    for (y0, r0), (y1, r1) in zip(BODY_KNOTS, BODY_KNOTS[1:]):
        if y0 <= y <= y1:
            w = (y - y0) / (y1 - y0)
            return r0 + (r1 - r0) * (1.0 - math.cos(math.pi * w)) / 2.0
    raise ValueError("y outside the knots")


def meridian(samples_per_segment, cap_rings):
    """Points (r, y) along the meridian from the bottom pole to the top pole (poles excluded)."""
    pts = []
    yb, rb = BODY_KNOTS[0]
    for k in range(1, cap_rings + 1):  # bottom cap, from just above the pole up to the knee knot
        t = (math.pi / 2) * k / (cap_rings + 1)
        pts.append((rb * math.sin(t), yb - (yb - BOTTOM_POLE) * math.cos(t)))
    for (y0, _), (y1, _) in zip(BODY_KNOTS, BODY_KNOTS[1:]):
        n = samples_per_segment(y1 - y0)
        for k in range(n):
            y = y0 + (y1 - y0) * k / n
            pts.append((body_radius(y), y))
    yt, rt = BODY_KNOTS[-1]
    for k in range(0, cap_rings + 1):  # top cap, from the chest knot toward the pole
        t = (math.pi / 2) * k / (cap_rings + 1)
        pts.append((rt * math.cos(t), yt + (TOP_POLE - yt) * math.sin(t)))
    return pts


def make_body():
    rings = meridian(lambda length: max(2, round(length / 0.03)), BODY_CAP_RINGS)
    verts = [(0.0, BOTTOM_POLE, 0.0)]
    for r, y in rings:
        for i in range(BODY_AROUND):
            a = 2 * math.pi * i / BODY_AROUND
            verts.append((r * math.cos(a), y, r * math.sin(a)))
    verts.append((0.0, TOP_POLE, 0.0))
    top = len(verts) - 1
    n = BODY_AROUND

    def ring(j, i):
        return 1 + j * n + (i % n)

    faces = []
    for i in range(n):
        faces.append((0, ring(0, i), ring(0, i + 1)))
    for j in range(len(rings) - 1):
        for i in range(n):
            a, b, c, d = ring(j, i), ring(j, i + 1), ring(j + 1, i + 1), ring(j + 1, i)
            faces += [(a, d, c), (a, c, b)]
    for i in range(n):
        faces.append((top, ring(len(rings) - 1, i + 1), ring(len(rings) - 1, i)))
    return verts, faces


_FINE = []


def analytic_distance(p):
    """Signed distance of a point to the analytic body (positive outside), from a fine meridian."""
    r, y = math.hypot(p[0], p[2]), p[1]
    if not _FINE:
        _FINE.extend([(0.0, BOTTOM_POLE)] + meridian(lambda length: max(2, round(length / 0.001)), 200)
                     + [(0.0, TOP_POLE)])
    fine = _FINE
    best = float("inf")
    for (r0, y0), (r1, y1) in zip(fine, fine[1:]):
        dr, dy = r1 - r0, y1 - y0
        t = max(0.0, min(1.0, ((r - r0) * dr + (y - y0) * dy) / (dr * dr + dy * dy)))
        best = min(best, math.hypot(r - r0 - t * dr, y - y0 - t * dy))
    inside = BOTTOM_POLE < y < TOP_POLE and r < radius_at(y)
    return -best if inside else best


def radius_at(y):
    yb, rb = BODY_KNOTS[0]
    yt, rt = BODY_KNOTS[-1]
    if y < yb:
        return rb * math.sqrt(max(0.0, 1 - ((yb - y) / (yb - BOTTOM_POLE)) ** 2))
    if y > yt:
        return rt * math.sqrt(max(0.0, 1 - ((y - yt) / (TOP_POLE - yt)) ** 2))
    return body_radius(y)


def cross(u, w):
    return (u[1] * w[2] - u[2] * w[1], u[2] * w[0] - u[0] * w[2], u[0] * w[1] - u[1] * w[0])


def sub(a, b):
    return (a[0] - b[0], a[1] - b[1], a[2] - b[2])


def check_closed_outward(verts, faces):
    edges = {}
    for f in faces:
        for k in range(3):
            e = (f[k], f[(k + 1) % 3])
            assert e not in edges, "edge traversed twice in one direction"
            edges[e] = 1
    for (a, b) in edges:
        assert (b, a) in edges, "open edge"
    vol = 0.0
    for a, b, c in faces:
        vol += sum(x * y for x, y in zip(verts[a], cross(verts[b], verts[c]))) / 6.0
    assert vol > 0, "body wound inward"
    return vol


def body_depth(verts, faces):
    """Largest depth of the faces inside the analytic body (sampled at 7 points of each face)."""
    depth = 0.0
    for f in faces:
        a, b, c = (verts[i] for i in f)
        for w in ((1 / 3, 1 / 3, 1 / 3), (0.5, 0.5, 0), (0, 0.5, 0.5), (0.5, 0, 0.5), (2 / 3, 1 / 6, 1 / 6),
                  (1 / 6, 2 / 3, 1 / 6), (1 / 6, 1 / 6, 2 / 3)):
            p = tuple(w[0] * a[k] + w[1] * b[k] + w[2] * c[k] for k in range(3))
            if 0.01 < p[1] < 0.81:
                depth = max(depth, -analytic_distance_fast(p))
    return depth


def analytic_distance_fast(p):
    """The signed distance, for points near the side of the body (a local search on the meridian)."""
    r, y = math.hypot(p[0], p[2]), p[1]
    best = float("inf")
    steps = 200
    for k in range(-steps, steps + 1):
        yy = y + 0.04 * k / steps
        if not (BOTTOM_POLE <= yy <= TOP_POLE):
            continue
        best = min(best, math.hypot(r - radius_at(yy), y - yy))
    return -best if r < radius_at(y) else best


def skirt_radius(y):
    """The skirt's profile: fitted from the waist to the hips (the body plus the thickness plus
    SKIRT_GAP), then flaring below the hips with slope FLARE, reached smoothly over FLARE_BLEND."""
    y_hip, r_hip = BODY_KNOTS[1]
    if y >= y_hip:
        return body_radius(y) + COLLIDER_THICKNESS + SKIRT_GAP
    d = y_hip - y
    r0 = r_hip + COLLIDER_THICKNESS + SKIRT_GAP
    if d < FLARE_BLEND:
        return r0 + FLARE * d * d / (2 * FLARE_BLEND)
    return r0 + FLARE * (d - FLARE_BLEND / 2)


def skirt_meridian():
    """(y, arc length s from the top ring, q) along the skirt's profile, finely sampled, with
    q = SKIRT_TOP_R * integral ds / r: (angle * SKIRT_TOP_R, q) are conformal coordinates of the
    surface of revolution (angles between directions on it are those between their (du, dq))."""
    pts, s, q, y = [(WAIST_Y, 0.0, 0.0)], 0.0, 0.0, WAIST_Y
    step = 0.0002
    while y > HEM_Y + 1e-12:
        y1 = max(HEM_Y, y - step)
        d = math.hypot(y - y1, skirt_radius(y) - skirt_radius(y1))
        s += d
        q += SKIRT_TOP_R * d / skirt_radius((y + y1) / 2)
        pts.append((y1, s, q))
        y = y1
    return pts


def make_skirt():
    rng = random.Random(SEED)
    prof = skirt_meridian()
    length = prof[-1][1]

    def at(s, col):  # column col (0: y, 2: q) at arc length s (linear in the fine table)
        s = max(0.0, min(length, s))
        lo, hi = 0, len(prof) - 1
        while hi - lo > 1:
            mid = (lo + hi) // 2
            if prof[mid][1] <= s:
                lo = mid
            else:
                hi = mid
        a, b = prof[lo], prof[hi]
        return a[col] + (b[col] - a[col]) * (s - a[1]) / (b[1] - a[1]) if b[1] > a[1] else a[col]

    def y_at(s):
        return at(s, 0)

    nrings = max(2, round(length / SKIRT_RING_DS)) + 1
    ds = length / (nrings - 1)
    spacing = 2 * math.pi * SKIRT_TOP_R / SKIRT_TOP_N
    verts, uvs, rings = [], [], []
    u_scale = SKIRT_TOP_R
    for j in range(nrings):
        s0 = j * ds
        exact = j == 0 or j == nrings - 1
        n = SKIRT_TOP_N if j == 0 else max(SKIRT_TOP_N, round(2 * math.pi * skirt_radius(y_at(s0)) / spacing))
        offset = 0.0 if exact else rng.uniform(0, 1)
        ring = []
        for i in range(n):
            a = 2 * math.pi * (i + offset) / n
            s = s0
            if not exact:
                a += rng.uniform(-JITTER, JITTER) * 2 * math.pi / n
                s += rng.uniform(-JITTER, JITTER) * ds
            if j == 0:
                y, q = WAIST_Y, 0.0
            elif j == nrings - 1:
                y, q = HEM_Y, prof[-1][2]
            else:
                y, q = y_at(s), at(s, 2)
            r = skirt_radius(y)
            ring.append((a, len(verts)))
            verts.append((r * math.cos(a), y, -r * math.sin(a)))
            uvs.append((abs(math.remainder(a, 2 * math.pi)) * u_scale, q))
        ring.sort()
        rings.append(ring)
    faces = []
    for upper, lower in zip(rings, rings[1:]):
        faces += zip_rings(upper, lower, verts)
    return verts, uvs, faces, nrings, length


def zip_rings(upper, lower, verts):
    """Triangulate the band between two rings (lists of (angle, index) sorted by angle) by the
    shorter diagonal, going once around. Faces are wound so their normals point away from the axis."""

    def dist(i, j):
        d = sub(verts[i], verts[j])
        return math.sqrt(sum(x * x for x in d))

    nu, nl = len(upper), len(lower)
    # Start the lower ring at the vertex closest in angle to the upper ring's first vertex.
    a0 = upper[0][0]
    k0 = min(range(nl), key=lambda k: abs(math.remainder(lower[k][0] - a0, 2 * math.pi)))
    U = [upper[i][1] for i in range(nu)] + [upper[0][1]]
    L = [lower[(k0 + k) % nl][1] for k in range(nl)] + [lower[k0][1]]
    i = k = 0
    faces = []
    while i < nu or k < nl:
        advance_upper = k == nl or (i < nu and dist(U[i + 1], L[k]) < dist(U[i], L[k + 1]))
        if advance_upper:
            tri = (U[i], L[k], U[i + 1])
            i += 1
        else:
            tri = (U[i], L[k], L[k + 1])
            k += 1
        a, b, c = (verts[t] for t in tri)
        n = cross(sub(b, a), sub(c, a))
        cx, cz = (a[0] + b[0] + c[0]) / 3, (a[2] + b[2] + c[2]) / 3
        if n[0] * cx + n[2] * cz < 0:
            tri = (tri[0], tri[2], tri[1])
        faces.append(tri)
    return faces


def edge_lengths(verts, faces):
    lengths = {}
    for f in faces:
        for k in range(3):
            a, b = sorted((f[k], f[(k + 1) % 3]))
            d = sub(verts[a], verts[b])
            lengths[(a, b)] = math.sqrt(sum(x * x for x in d))
    return list(lengths.values())


def main():
    if len(sys.argv) > 2:
        sys.exit(__doc__)
    out = sys.argv[1] if len(sys.argv) == 2 else os.path.join(os.path.dirname(os.path.abspath(__file__)), "..",
                                                               "scenes", "meshes")
    bv, bf = make_body()
    vol = check_closed_outward(bv, bf)
    depth = body_depth(bv, bf)
    sv, suv, sf, nrings, length = make_skirt()
    lengths = edge_lengths(sv, sf)
    closest = min(analytic_distance(p) for p in sv)
    body_path = os.path.join(out, "body_hips.obj")
    with open(body_path, "w") as f:
        f.write("# Loom body for scenes/skirt_on_body.yaml, written by scripts/make_garment.py: a surface of\n"
                "# revolution (waist 0.13 m at y = 0.62, hips 0.175 m at y = 0.45), %d vertices, %d faces,\n"
                "# closed, counter-clockwise seen from outside; faces at most %.5f m inside the analytic profile\n"
                % (len(bv), len(bf), depth))
        for p in bv:
            f.write("v %.9f %.9f %.9f\n" % p)
        for a, b, c in bf:
            f.write("f %d %d %d\n" % (a + 1, b + 1, c + 1))
    skirt_path = os.path.join(out, "skirt_flared.obj")
    with open(skirt_path, "w") as f:
        f.write("# Loom skirt for scenes/skirt_on_body.yaml, written by scripts/make_garment.py: an open surface\n"
                "# of revolution, fitted from the waist (top ring r = %.4f m at y = %.2f) to the hips, flared below\n"
                "# (hem r = %.4f m at y = %.2f), %.4f m long; %d rings, irregular triangulation (jittered vertices,\n"
                "# shorter-diagonal zip): %d vertices, %d faces, edges %.4f-%.4f m (mean %.4f);\n"
                "# vt (conformal): u = |angle in (-pi, pi]| x %.4f m, v = that radius x integral of ds / r from the top\n"
                % (SKIRT_TOP_R, WAIST_Y, skirt_radius(HEM_Y), HEM_Y, length, nrings, len(sv), len(sf), min(lengths),
                   max(lengths), sum(lengths) / len(lengths), SKIRT_TOP_R))
        for p in sv:
            f.write("v %.9f %.9f %.9f\n" % p)
        for uv in suv:
            f.write("vt %.9f %.9f\n" % uv)
        for a, b, c in sf:
            f.write("f %d/%d %d/%d %d/%d\n" % (a + 1, a + 1, b + 1, b + 1, c + 1, c + 1))
    print("%s: %d vertices, %d faces, volume %.5f m^3, faces at most %.5f m inside the analytic body"
          % (body_path, len(bv), len(bf), vol, depth))
    print("%s: %d vertices, %d faces, %d rings, hem radius %.4f m, edges %.4f-%.4f m (mean %.4f), closest to "
          "the analytic body %.5f m" % (skirt_path, len(sv), len(sf), nrings, skirt_radius(HEM_Y), min(lengths), max(lengths),
                                    sum(lengths) / len(lengths), closest))


if __name__ == "__main__":
    main()

// The exact triangle-triangle intersection check: constructed cases with known answers
// (touching, coplanar, degenerate, one-ulp misses), invariances on integer soups full of
// degeneracies, and the grid broad phase against brute force on random soups, with an
// independent floating-point interval test (Moller 1997) on generic data.
#include <gtest/gtest.h>

#include <array>
#include <cmath>
#include <random>
#include <vector>

#include "loom/intersection_check.hpp"
#include "loom/mesh.hpp"

namespace {

using P = std::array<double, 3>;
using T3 = std::array<P, 3>;

bool hit(const T3& a, const T3& b) {
  return loom::triangles_intersect(a[0].data(), a[1].data(), a[2].data(), b[0].data(), b[1].data(), b[2].data());
}

// All 6 x 6 vertex orders and both argument orders must agree; returns the common answer.
bool hit_all_orders(const T3& a, const T3& b) {
  const int perm[6][3] = {{0, 1, 2}, {1, 2, 0}, {2, 0, 1}, {0, 2, 1}, {2, 1, 0}, {1, 0, 2}};
  const bool ref = hit(a, b);
  for (const auto& pa : perm)
    for (const auto& pb : perm) {
      const T3 ta{a[pa[0]], a[pa[1]], a[pa[2]]}, tb{b[pb[0]], b[pb[1]], b[pb[2]]};
      EXPECT_EQ(hit(ta, tb), ref);
      EXPECT_EQ(hit(tb, ta), ref);
    }
  return ref;
}

const T3 kBase{{{0, 0, 0}, {1, 0, 0}, {0, 1, 0}}};  // in z = 0, the right angle at the origin

double up(double x) { return std::nextafter(x, INFINITY); }
double down(double x) { return std::nextafter(x, -INFINITY); }

}  // namespace

TEST(TriTri, SeparatedParallelAndPiercing) {
  EXPECT_FALSE(hit_all_orders(kBase, T3{{{0, 0, 1}, {1, 0, 1}, {0, 1, 1}}}));
  // A vertical triangle through the interior of the base.
  EXPECT_TRUE(hit_all_orders(kBase, T3{{{0.2, 0.2, -1}, {0.3, 0.2, 1}, {0.2, 0.3, 1}}}));
  // The same, moved beyond the hypotenuse x + y = 1: misses.
  EXPECT_FALSE(hit_all_orders(kBase, T3{{{0.6, 0.6, -1}, {0.7, 0.6, 1}, {0.6, 0.7, 1}}}));
}

TEST(TriTri, TouchingCountsAndOneUlpAwayDoesNot) {
  // A vertex exactly on the base's interior, the rest above: touching.
  EXPECT_TRUE(hit_all_orders(kBase, T3{{{0.25, 0.25, 0}, {1, 1, 1}, {0, 1, 2}}}));
  // The same vertex 2^-600 above the plane: no contact. (Exact down to where products
  // underflow into subnormal numbers, as for any floating-point expansion arithmetic.)
  EXPECT_FALSE(hit_all_orders(kBase, T3{{{0.25, 0.25, std::ldexp(1.0, -600)}, {1, 1, 1}, {0, 1, 2}}}));
  // A vertex exactly on the hypotenuse (0.5, 0.5, 0), and one ulp outside it in x.
  EXPECT_TRUE(hit_all_orders(kBase, T3{{{0.5, 0.5, 0}, {1, 1, 1}, {0, 2, 1}}}));
  EXPECT_FALSE(hit_all_orders(kBase, T3{{{up(0.5), 0.5, 0}, {1, 1, 1}, {2, 1, 1}}}));
  // Edge against edge, not coplanar: B in the plane x = 0.5, its edge crossing the base's
  // edge y = 0 at (0.5, 0, 0); then B moved to y = -1e-100: a miss.
  EXPECT_TRUE(hit_all_orders(kBase, T3{{{0.5, 0, -1}, {0.5, 0, 1}, {0.5, -1, 0}}}));
  EXPECT_FALSE(hit_all_orders(kBase, T3{{{0.5, -1e-100, -1}, {0.5, -1e-100, 1}, {0.5, -1, 0}}}));
}

TEST(TriTri, CoplanarCases) {
  // Overlapping, disjoint, containment, a shared corner point, collinear overlapping edges,
  // and a one-ulp gap across the hypotenuse.
  EXPECT_TRUE(hit_all_orders(kBase, T3{{{0.5, 0.1, 0}, {1.5, 0.1, 0}, {0.5, 1.1, 0}}}));
  EXPECT_FALSE(hit_all_orders(kBase, T3{{{2, 2, 0}, {3, 2, 0}, {2, 3, 0}}}));
  EXPECT_TRUE(hit_all_orders(kBase, T3{{{0.1, 0.1, 0}, {0.2, 0.1, 0}, {0.1, 0.2, 0}}}));
  EXPECT_TRUE(hit_all_orders(kBase, T3{{{1, 0, 0}, {2, 0, 0}, {2, 1, 0}}}));
  EXPECT_TRUE(hit_all_orders(kBase, T3{{{0.5, 0, 0}, {1.5, 0, 0}, {1, -1, 0}}}));
  EXPECT_FALSE(hit_all_orders(kBase, T3{{{up(0.5), up(0.5), 0}, {1, 1, 0}, {2, 0.5, 0}}}));
  EXPECT_TRUE(hit_all_orders(kBase, T3{{{0.5, 0.5, 0}, {1, 1, 0}, {2, 0.5, 0}}}));
  // Coplanar in a tilted plane x + y + z = 1 (no axis-aligned plane): overlapping and not.
  const T3 tilted{{{1, 0, 0}, {0, 1, 0}, {0, 0, 1}}};
  EXPECT_TRUE(hit_all_orders(tilted, T3{{{0.5, 0.5, 0}, {0.5, 0, 0.5}, {1, 0.5, -0.5}}}));
  EXPECT_FALSE(hit_all_orders(tilted, T3{{{1.5, 0, -0.5}, {2, 0, -1}, {1.5, 0.5, -1}}}));
}

TEST(TriTri, DegenerateTriangles) {
  // A zero-area triangle (a segment) through the base's interior, one beside it, a point
  // triangle in the base and one just above, and two segments in 3D: crossing and skew.
  EXPECT_TRUE(hit_all_orders(kBase, T3{{{0.2, 0.2, -1}, {0.2, 0.2, 1}, {0.2, 0.2, 0.5}}}));
  EXPECT_FALSE(hit_all_orders(kBase, T3{{{0.8, 0.8, -1}, {0.8, 0.8, 1}, {0.8, 0.8, 0}}}));
  EXPECT_TRUE(hit_all_orders(kBase, T3{{{0.3, 0.3, 0}, {0.3, 0.3, 0}, {0.3, 0.3, 0}}}));
  EXPECT_FALSE(hit_all_orders(kBase, T3{{{0.3, 0.3, 1e-100}, {0.3, 0.3, 1e-100}, {0.3, 0.3, 1e-100}}}));
  const T3 seg1{{{0, 0, 0}, {2, 2, 2}, {1, 1, 1}}};
  EXPECT_TRUE(hit_all_orders(seg1, T3{{{0, 2, 1}, {2, 0, 1}, {2, 0, 1}}}));     // cross at (1, 1, 1)
  EXPECT_FALSE(hit_all_orders(seg1, T3{{{0, 2, 1.5}, {2, 0, 1}, {2, 0, 1}}}));  // skew
  EXPECT_TRUE(hit_all_orders(seg1, T3{{{2, 2, 2}, {3, 3, 3}, {4, 4, 4}}}));     // collinear, end to end
  EXPECT_FALSE(hit_all_orders(seg1, T3{{{up(2), 2, 2}, {3, 3, 3}, {4, 4, 4}}}));
}

TEST(TriTri, NearlyCoplanarDecidedExactly) {
  // B lies in the base's plane except for a tiny lift; a naive floating-point test sees
  // every sign as zero or noise. With the lift it is separated; with a dip it pierces.
  const double e = 1e-200;
  EXPECT_FALSE(hit_all_orders(kBase, T3{{{0.1, 0.1, e}, {0.9, 0.05, e}, {0.1, 0.8, 2 * e}}}));
  EXPECT_TRUE(hit_all_orders(kBase, T3{{{0.1, 0.1, -e}, {0.9, 0.05, e}, {0.1, 0.8, 2 * e}}}));
  // Large offsets: both triangles moved by 2^20 (exact for these dyadic coordinates).
  const double o = 1048576.0;
  const T3 a{{{o, o, o}, {o + 1, o, o}, {o, o + 1, o}}};
  EXPECT_TRUE(hit_all_orders(a, T3{{{o + 0.5, o + 0.5, o}, {o + 1, o + 1, o + 1}, {o, o + 2, o + 1}}}));
  EXPECT_FALSE(hit_all_orders(a, T3{{{up(o + 0.5), o + 0.5, o}, {o + 1, o + 1, o + 1}, {o + 2, o + 1, o + 1}}}));
  EXPECT_FALSE(hit_all_orders(a, T3{{{o + 0.25, o + 0.25, up(o)}, {o + 1, o + 1, o + 1}, {o, o + 1, o + 2}}}));
  EXPECT_TRUE(hit_all_orders(a, T3{{{o + 0.25, o + 0.25, down(o)}, {o + 1, o + 1, o + 1}, {o, o + 1, o + 2}}}));
}

TEST(TriTri, Orient3dExactOnRoundingTraps) {
  // Points on the line x = y = z spaced by ulps: four collinear points are coplanar (0), and
  // the sign of a point one ulp off a plane is exact.
  const double a[3] = {0.1, 0.1, 0.1}, b[3] = {0.3, 0.3, 0.3}, c[3] = {0.7, 0.7, 0.7};
  const double d[3] = {0.1, 0.2, 0.3}, e[3] = {0.5, 0.5, 0.5};
  EXPECT_EQ(loom::exact::orient3d(a, b, c, d), 0);  // a, b, c collinear
  const double p0[3] = {0, 0, 0}, p1[3] = {1, 0, 0}, p2[3] = {0, 1, 0};
  const double above[3] = {0.3, 0.3, std::ldexp(1.0, -600)}, below[3] = {0.3, 0.3, -std::ldexp(1.0, -600)};
  EXPECT_EQ(loom::exact::orient3d(p0, p1, p2, above), 1);
  EXPECT_EQ(loom::exact::orient3d(p0, p1, p2, below), -1);
  EXPECT_EQ(loom::exact::orient3d(p0, p1, p2, e), 1);
  // Shewchuk's classic orient2d trap: points near (0.5, 0.5) on the line y = x, in ulp steps.
  const double q[3] = {12, 12, 0}, r[3] = {24, 24, 0};
  for (int i = 0; i < 64; ++i)
    for (int j = 0; j < 64; ++j) {
      double s[3] = {0.5, 0.5, 0};
      for (int k = 0; k < i; ++k) s[0] = up(s[0]);
      for (int k = 0; k < j; ++k) s[1] = up(s[1]);
      const int expected = s[1] > s[0] ? 1 : (s[1] < s[0] ? -1 : 0);  // the line is y = x exactly
      ASSERT_EQ(loom::exact::orient2d(s, q, r, 0, 1), expected) << i << " " << j;
    }
}

namespace {

// Independent floating-point triangle-triangle test for generic data (no vertex on the other
// plane, no coplanar pairs): Moller's interval overlap on the planes' intersection line.
bool moller(const T3& A, const T3& B) {
  auto sub = [](const P& a, const P& b) { return P{a[0] - b[0], a[1] - b[1], a[2] - b[2]}; };
  auto cross = [](const P& a, const P& b) {
    return P{a[1] * b[2] - a[2] * b[1], a[2] * b[0] - a[0] * b[2], a[0] * b[1] - a[1] * b[0]};
  };
  auto dot = [](const P& a, const P& b) { return a[0] * b[0] + a[1] * b[1] + a[2] * b[2]; };
  const P nA = cross(sub(A[1], A[0]), sub(A[2], A[0])), nB = cross(sub(B[1], B[0]), sub(B[2], B[0]));
  double dB[3], dA[3];
  for (int k = 0; k < 3; ++k) {
    dB[k] = dot(nA, sub(B[k], A[0]));
    dA[k] = dot(nB, sub(A[k], B[0]));
  }
  auto same = [](const double* d) { return (d[0] > 0 && d[1] > 0 && d[2] > 0) || (d[0] < 0 && d[1] < 0 && d[2] < 0); };
  if (same(dB) || same(dA)) return false;
  const P L = cross(nA, nB);
  // Interval of a triangle on L: the two points where its edges cross the other plane.
  auto interval = [&](const T3& t, const double* d, double& lo, double& hi) {
    double s[2] = {0, 0};
    int m = 0;
    for (int k = 0; k < 3; ++k) {
      const int j = (k + 1) % 3;
      if ((d[k] > 0) != (d[j] > 0)) {
        const double w = d[k] / (d[k] - d[j]);
        P p;
        for (int c = 0; c < 3; ++c) p[c] = t[k][c] + w * (t[j][c] - t[k][c]);
        s[m++] = dot(L, p);
      }
    }
    lo = std::min(s[0], s[1]);
    hi = std::max(s[0], s[1]);
  };
  double a0, a1, b0, b1;
  interval(A, dA, a0, a1);
  interval(B, dB, b0, b1);
  return a0 <= b1 && b0 <= a1;
}

loom::Mesh soup(std::mt19937& rng, int n, double size, bool integer) {
  std::uniform_real_distribution<double> U(0, 1);
  std::uniform_int_distribution<int> I(0, 3);
  loom::Mesh m;
  for (int t = 0; t < n; ++t) {
    const double c[3] = {U(rng), U(rng), U(rng)};
    for (int v = 0; v < 3; ++v)
      for (int k = 0; k < 3; ++k) m.positions.push_back(integer ? I(rng) : c[k] + size * (U(rng) - 0.5));
    m.triangles.insert(m.triangles.end(), {3 * t, 3 * t + 1, 3 * t + 2});
  }
  return m;
}

T3 tri_of(const loom::Mesh& m, int t) {
  T3 r;
  for (int v = 0; v < 3; ++v)
    for (int k = 0; k < 3; ++k) r[v][k] = m.positions[3 * m.triangles[3 * t + v] + k];
  return r;
}

}  // namespace

TEST(TriTri, AgreesWithIndependentFloatTestOnGenericSoups) {
  std::mt19937 rng(7);
  int hits = 0;
  for (int round = 0; round < 4; ++round) {
    const loom::Mesh m = soup(rng, 150, 0.4, false);
    for (int i = 0; i < m.num_triangles(); ++i)
      for (int j = i + 1; j < m.num_triangles(); ++j) {
        const bool e = hit(tri_of(m, i), tri_of(m, j));
        ASSERT_EQ(e, moller(tri_of(m, i), tri_of(m, j))) << "pair " << i << " " << j << " round " << round;
        hits += e;
      }
  }
  EXPECT_GT(hits, 100);  // the soups do intersect: the comparison is not vacuous
}

TEST(TriTri, InvariantOnIntegerSoupsFullOfDegeneracies) {
  // Integer coordinates in {0..3}: coplanar pairs, shared points, collinear edges and
  // degenerate triangles everywhere. Every vertex and argument order, and an exact
  // rescaling (x 2^-7) plus translation (+1000), must give the same answers.
  std::mt19937 rng(11);
  const loom::Mesh m = soup(rng, 60, 0, true);
  int hits = 0;
  for (int i = 0; i < m.num_triangles(); ++i)
    for (int j = i + 1; j < m.num_triangles(); ++j) {
      const T3 a = tri_of(m, i), b = tri_of(m, j);
      const bool r = hit_all_orders(a, b);
      T3 a2 = a, b2 = b;
      for (auto* t : {&a2, &b2})
        for (auto& p : *t)
          for (auto& c : p) c = 1000.0 + c / 128.0;
      ASSERT_EQ(hit(a2, b2), r) << i << " " << j;
      hits += r;
    }
  EXPECT_GT(hits, 0);
  EXPECT_LT(hits, m.num_triangles() * (m.num_triangles() - 1) / 2);
}

TEST(IntersectionCheck, GridMatchesBruteForceOnRandomSoups) {
  std::mt19937 rng(3);
  for (int round = 0; round < 6; ++round) {
    const bool integer = round >= 4;
    const loom::Mesh m = soup(rng, integer ? 120 : 400, round < 2 ? 0.05 : 0.25, integer);
    std::vector<std::array<loom::Index, 2>> brute;
    for (int i = 0; i < m.num_triangles(); ++i)
      for (int j = i + 1; j < m.num_triangles(); ++j)
        if (hit(tri_of(m, i), tri_of(m, j))) brute.push_back({i, j});
    std::vector<std::array<loom::Index, 2>> grid;
    const std::size_t n = loom::count_intersecting_pairs(m, {}, &grid);
    EXPECT_EQ(n, brute.size()) << "round " << round;
    EXPECT_EQ(grid, brute) << "round " << round;
  }
}

TEST(IntersectionCheck, AdjacentPairsExcludedAndFlatGridClean) {
  // A flat grid: neighbours touch but share vertices; non-neighbours are disjoint: 0.
  const loom::Mesh g = loom::make_grid(12, 9, 1.0, 0.7, loom::GridPlane::XZ);
  EXPECT_EQ(loom::count_intersecting_pairs(g, {}), 0u);
  // The same grid folded along x = 0.5 onto a small angle does not intersect; pushed through
  // itself (the right half mirrored below the left half, crossing it) it does.
  std::vector<double> x = g.positions;
  const loom::Index n = g.num_vertices();
  for (loom::Index v = 0; v < n; ++v) {
    double& px = x[3 * v];
    double& py = x[3 * v + 1];
    if (px > 0.5) {
      const double d = px - 0.5;
      px = 0.5 - d * std::cos(0.2);
      py = d * std::sin(0.2);
    }
  }
  EXPECT_EQ(loom::count_intersecting_pairs(g, x), 0u);
  // Now the right half goes down through the left half (crossing y = 0 near x = 0.3): the
  // count is positive and equals a brute-force loop over all non-adjacent pairs.
  x = g.positions;
  for (loom::Index v = 0; v < n; ++v)
    if (x[3 * v] > 0.5) {
      const double d = x[3 * v] - 0.5;
      x[3 * v] = 0.5 - d * std::cos(0.2);
      x[3 * v + 1] = 0.02 - 0.1 * d;
    }
  std::size_t brute = 0;
  for (loom::Index i = 0; i < g.num_triangles(); ++i)
    for (loom::Index j = i + 1; j < g.num_triangles(); ++j) {
      const loom::Index* A = &g.triangles[3 * i];
      const loom::Index* B = &g.triangles[3 * j];
      bool adjacent = false;
      for (int p = 0; p < 3; ++p)
        for (int q = 0; q < 3; ++q) adjacent = adjacent || A[p] == B[q];
      if (!adjacent && loom::triangles_intersect(&x[3 * A[0]], &x[3 * A[1]], &x[3 * A[2]], &x[3 * B[0]], &x[3 * B[1]],
                                                 &x[3 * B[2]]))
        ++brute;
    }
  EXPECT_GT(brute, 10u);
  EXPECT_EQ(loom::count_intersecting_pairs(g, x), brute);
}

TEST(IntersectionCheck, OneTrianglePiercingASheetGivesExactlyOnePair) {
  // A 10 x 10 grid in z = 0 over [0,1]^2 plus one separate small triangle piercing the
  // interior of a single grid triangle (cells of 1/9; the triangle crosses z = 0 near
  // (0.3, 0.3), well inside one cell and away from its diagonal).
  loom::Mesh m = loom::make_grid(10, 10, 1.0, 1.0, loom::GridPlane::XY);
  const loom::Index base = m.num_vertices();
  const double h = 1.0 / 9.0;
  const double cx = 3 * h + 0.2 * h, cy = 2 * h + 0.5 * h;  // inside cell (3, 2), off both diagonals
  m.positions.insert(m.positions.end(), {cx, cy, -0.1, cx + 0.01 * h, cy, 0.1, cx, cy + 0.01 * h, 0.1});
  m.triangles.insert(m.triangles.end(), {base, base + 1, base + 2});
  std::vector<std::array<loom::Index, 2>> pairs;
  EXPECT_EQ(loom::count_intersecting_pairs(m, {}, &pairs), 1u);
  ASSERT_EQ(pairs.size(), 1u);
  EXPECT_EQ(pairs[0][1], m.num_triangles() - 1);
  // Pushed through the sheet at the grid's shared vertex (3h, 3h): it touches all the
  // triangles around that vertex (6 or 8 in the alternating-diagonal grid: count them).
  m.positions.resize(3 * static_cast<std::size_t>(base));
  const double vx = m.positions[3 * (3 * 10 + 3)], vy = m.positions[3 * (3 * 10 + 3) + 1];
  ASSERT_EQ(m.positions[3 * (3 * 10 + 3) + 2], 0.0);
  m.positions.insert(m.positions.end(), {vx, vy, -0.1, vx, vy, 0.1, vx + 1e-9, vy, 0.0});
  int around = 0;
  for (loom::Index t = 0; t + 1 < m.num_triangles(); ++t)
    for (int k = 0; k < 3; ++k) around += m.triangles[3 * t + k] == 3 * 10 + 3;
  // The third vertex (vx + 1e-9, vy, 0) lies in the sheet, inside the triangles on the
  // +x side of the vertex; they are already counted among those around the vertex.
  EXPECT_EQ(loom::count_intersecting_pairs(m, {}), static_cast<std::size_t>(around));
}

// loom::closest_approach and its distance functions (loom check --distance): analytic cases,
// dense sampling bounds on random configurations, the flat grid's s / sqrt(2), two parallel
// sheets at a known gap, and the grid broad phase against brute force on crumpled meshes.
#include <gtest/gtest.h>

#include <omp.h>

#include <algorithm>
#include <array>
#include <cmath>
#include <random>
#include <vector>

#include "loom/intersection_check.hpp"
#include "loom/mesh.hpp"

namespace {

using P = std::array<double, 3>;
namespace dist = loom::distance;

double norm(const P& a) { return std::sqrt(a[0] * a[0] + a[1] * a[1] + a[2] * a[2]); }
P at(const P& a, const P& b, double t) { return {a[0] + t * (b[0] - a[0]), a[1] + t * (b[1] - a[1]), a[2] + t * (b[2] - a[2])}; }
P minus(const P& a, const P& b) { return {a[0] - b[0], a[1] - b[1], a[2] - b[2]}; }

// Two copies of an nx x nx grid of spacing s in z = 0 and z = gap, the second shifted by (ox, oy).
loom::Mesh two_sheets(int nx, double s, double gap, double ox, double oy) {
  const loom::Mesh g = loom::make_grid(nx, nx, s * (nx - 1), s * (nx - 1), loom::GridPlane::XY);
  loom::Mesh m = g;
  const loom::Index n = g.num_vertices();
  for (loom::Index i = 0; i < n; ++i) {
    m.positions.push_back(g.positions[3 * i] + ox);
    m.positions.push_back(g.positions[3 * i + 1] + oy);
    m.positions.push_back(gap);
  }
  for (loom::Index t : g.triangles) m.triangles.push_back(t + n);
  m.uvs.clear();
  return m;
}

// Brute force over every non-adjacent element pair, with the same distance functions.
double brute_force(const loom::Mesh& m) {
  const auto& x = m.positions;
  auto p = [&](loom::Index v) { return &x[3 * static_cast<std::size_t>(v)]; };
  double best = INFINITY;
  const loom::Index nt = m.num_triangles();
  for (loom::Index v = 0; v < m.num_vertices(); ++v)
    for (loom::Index t = 0; t < nt; ++t) {
      const loom::Index* T = &m.triangles[3 * t];
      if (v == T[0] || v == T[1] || v == T[2]) continue;
      best = std::min(best, dist::point_triangle(p(v), p(T[0]), p(T[1]), p(T[2])));
    }
  const auto e = m.edges();
  for (std::size_t i = 0; i < e.size(); ++i)
    for (std::size_t j = i + 1; j < e.size(); ++j) {
      if (e[i][0] == e[j][0] || e[i][0] == e[j][1] || e[i][1] == e[j][0] || e[i][1] == e[j][1]) continue;
      best = std::min(best, dist::segment_segment(p(e[i][0]), p(e[i][1]), p(e[j][0]), p(e[j][1])));
    }
  return best;
}

}  // namespace

TEST(Distances, AnalyticCases) {
  const P a{0, 0, 0}, b{2, 0, 0}, c{0, 2, 0};
  // point - segment: above the middle, beyond each end, a degenerate segment
  EXPECT_DOUBLE_EQ(dist::point_segment(P{1, 3, 0}.data(), a.data(), b.data()), 3.0);
  EXPECT_DOUBLE_EQ(dist::point_segment(P{-3, 4, 0}.data(), a.data(), b.data()), 5.0);
  EXPECT_DOUBLE_EQ(dist::point_segment(P{5, 0, 4}.data(), a.data(), b.data()), 5.0);
  EXPECT_DOUBLE_EQ(dist::point_segment(P{3, 4, 0}.data(), a.data(), a.data()), 5.0);
  // point - triangle: over the face, in each vertex and edge region, in the plane, degenerate
  EXPECT_DOUBLE_EQ(dist::point_triangle(P{0.5, 0.5, -7}.data(), a.data(), b.data(), c.data()), 7.0);
  EXPECT_DOUBLE_EQ(dist::point_triangle(P{-3, -4, 0}.data(), a.data(), b.data(), c.data()), 5.0);
  EXPECT_DOUBLE_EQ(dist::point_triangle(P{5, -4, 0}.data(), a.data(), b.data(), c.data()), 5.0);
  EXPECT_DOUBLE_EQ(dist::point_triangle(P{0, 5, 4}.data(), a.data(), b.data(), c.data()), 5.0);
  EXPECT_DOUBLE_EQ(dist::point_triangle(P{1, -3, 4}.data(), a.data(), b.data(), c.data()), 5.0);  // edge ab
  EXPECT_NEAR(dist::point_triangle(P{2, 2, 0}.data(), a.data(), b.data(), c.data()), std::sqrt(2.0), 1e-15);  // edge bc
  EXPECT_DOUBLE_EQ(dist::point_triangle(P{1, 0.5, 0}.data(), a.data(), b.data(), c.data()), 0.0);  // inside
  const P d{4, 0, 0};  // a, b, d collinear: the triangle is the segment a-d
  EXPECT_DOUBLE_EQ(dist::point_triangle(P{3, 2, 0}.data(), a.data(), b.data(), d.data()), 2.0);
  EXPECT_DOUBLE_EQ(dist::point_triangle(P{7, 0, 4}.data(), a.data(), d.data(), b.data()), 5.0);
  EXPECT_DOUBLE_EQ(dist::point_triangle(P{0, 0, 3}.data(), a.data(), a.data(), a.data()), 3.0);
  // segment - segment: skew, crossing, parallel overlapping and apart, collinear, degenerate
  EXPECT_DOUBLE_EQ(dist::segment_segment(P{-1, 0, 0}.data(), P{1, 0, 0}.data(), P{0, -1, 2}.data(), P{0, 1, 2}.data()), 2.0);
  EXPECT_DOUBLE_EQ(dist::segment_segment(P{-1, 0, 0}.data(), P{1, 0, 0}.data(), P{0, -1, 0}.data(), P{0, 1, 0}.data()), 0.0);
  EXPECT_DOUBLE_EQ(dist::segment_segment(P{0, 0, 0}.data(), P{2, 0, 0}.data(), P{1, 3, 0}.data(), P{5, 3, 0}.data()), 3.0);
  EXPECT_DOUBLE_EQ(dist::segment_segment(P{0, 0, 0}.data(), P{2, 0, 0}.data(), P{5, 4, 0}.data(), P{9, 4, 0}.data()), 5.0);
  EXPECT_DOUBLE_EQ(dist::segment_segment(P{0, 0, 0}.data(), P{2, 0, 0}.data(), P{5, 0, 0}.data(), P{9, 0, 0}.data()), 3.0);
  EXPECT_DOUBLE_EQ(dist::segment_segment(P{0, 0, 0}.data(), P{2, 0, 0}.data(), P{1, 0, 3}.data(), P{1, 0, 3}.data()), 3.0);
  EXPECT_DOUBLE_EQ(dist::segment_segment(P{0, 0, 0}.data(), P{0, 0, 0}.data(), P{3, 4, 0}.data(), P{3, 4, 0}.data()), 5.0);
  // skew, closest points beyond an end of one segment: the clamp
  EXPECT_DOUBLE_EQ(dist::segment_segment(P{0, 0, 0}.data(), P{1, 0, 0}.data(), P{3, -1, 1}.data(), P{3, 1, 1}.data()),
                   std::sqrt(5.0));
}

// Random configurations against dense sampling: the sampled minimum is an upper bound, and no
// point of an element is farther than half a sample spacing (times the element's size) from a
// sample, which gives the lower bound.
TEST(Distances, WithinTheBoundsOfDenseSampling) {
  std::mt19937 rng(7);
  std::uniform_real_distribution<double> u(-1.0, 1.0);
  auto rp = [&] { return P{u(rng), u(rng), u(rng)}; };
  const int K = 200;
  for (int trial = 0; trial < 300; ++trial) {
    P p0 = rp(), p1 = rp(), q0 = rp(), q1 = rp(), t2 = rp();
    if (trial % 5 == 1) q1 = at(q0, minus(q0, minus(p1, p0)), -1.0);  // parallel to p0p1
    if (trial % 5 == 2) t2 = at(p0, p1, 1.7);                      // degenerate triangle
    double ss = INFINITY, pt = INFINITY;
    for (int i = 0; i <= K; ++i)
      for (int j = 0; j <= K; ++j) {
        ss = std::min(ss, norm(minus(at(p0, p1, double(i) / K), at(q0, q1, double(j) / K))));
        if (i + j <= K) {
          const double bi = double(i) / K, bj = double(j) / K;
          const P y{p0[0] + bi * (p1[0] - p0[0]) + bj * (t2[0] - p0[0]), p0[1] + bi * (p1[1] - p0[1]) + bj * (t2[1] - p0[1]),
                    p0[2] + bi * (p1[2] - p0[2]) + bj * (t2[2] - p0[2])};
          pt = std::min(pt, norm(minus(q0, y)));
        }
      }
    const double d_ss = dist::segment_segment(p0.data(), p1.data(), q0.data(), q1.data());
    const double slack_ss = 0.5 / K * (norm(minus(p1, p0)) + norm(minus(q1, q0)));
    EXPECT_LE(d_ss, ss + 1e-12) << trial;
    EXPECT_GE(d_ss, ss - slack_ss - 1e-12) << trial;
    const double d_pt = dist::point_triangle(q0.data(), p0.data(), p1.data(), t2.data());
    const double slack_pt = 1.0 / K * (norm(minus(p1, p0)) + norm(minus(t2, p0)));
    EXPECT_LE(d_pt, pt + 1e-12) << trial;
    EXPECT_GE(d_pt, pt - slack_pt - 1e-12) << trial;
    // the same double whatever the order of the vertices and of the two segments
    EXPECT_EQ(dist::segment_segment(p1.data(), p0.data(), q0.data(), q1.data()), d_ss) << trial;
    EXPECT_EQ(dist::segment_segment(q1.data(), q0.data(), p1.data(), p0.data()), d_ss) << trial;
    EXPECT_EQ(dist::segment_segment(q0.data(), q1.data(), p0.data(), p1.data()), d_ss) << trial;
    EXPECT_EQ(dist::point_triangle(q0.data(), t2.data(), p0.data(), p1.data()), d_pt) << trial;
    EXPECT_EQ(dist::point_triangle(q0.data(), p1.data(), p0.data(), t2.data()), d_pt) << trial;
  }
}

// A flat grid of spacing s: the closest non-adjacent elements are a vertex and the diagonal of
// its cell that it is not on (the triangle across the diagonal), and the diagonals of
// neighbouring cells: s / sqrt(2). The 64 x 64 grid of 1 m gives 0.01122 m, the distance in the
// thickness check's message for that cloth (self_collision, loom::SelfCollision::min_distance).
TEST(ClosestApproach, FlatGridIsSpacingOverRootTwo) {
  for (int n : {3, 8, 64}) {
    const loom::Mesh g = loom::make_grid(n, n, 1.0, 1.0, loom::GridPlane::XZ);
    const double s = 1.0 / (n - 1);
    const loom::ClosestApproach c = loom::closest_approach(g, {}, 2 * s);
    EXPECT_NEAR(c.distance, s / std::sqrt(2.0), 1e-15) << n;
    EXPECT_TRUE(c.vertex_triangle) << n;  // a tie with edge-edge pairs: vertex-triangle first
    // nothing below half the spacing
    EXPECT_FALSE(std::isfinite(loom::closest_approach(g, {}, 0.5 * s).distance)) << n;
  }
}

// Two parallel sheets: every element of one is at least `gap` from every element of the other,
// and a vertex above a triangle's interior is exactly there; in-sheet pairs are farther
// (s / sqrt(2) > gap).
TEST(ClosestApproach, TwoParallelSheetsAtTheirGap) {
  const double s = 0.01;
  for (double gap : {0.002, 0.004, 0.0061}) {
    const loom::Mesh m = two_sheets(9, s, gap, 0.0031, 0.0047);
    const loom::ClosestApproach c = loom::closest_approach(m, {}, s);
    EXPECT_NEAR(c.distance, gap, 1e-15) << gap;
    // the pair joins the two sheets
    const loom::Index n = 81;
    EXPECT_TRUE((c.v[0] < n) != (c.v[1] < n || c.v[2] < n) || !c.vertex_triangle) << gap;
  }
}

// The grid broad phase finds the brute-force minimum (same distance functions, so the same
// double) on crumpled meshes, for every search distance above it and on 1 and 2 threads.
TEST(ClosestApproach, MatchesBruteForceOnCrumpledMeshes) {
  std::mt19937 rng(3);
  std::normal_distribution<double> z(0.0, 0.08);
  for (int trial = 0; trial < 6; ++trial) {
    loom::Mesh m = loom::make_grid(9, 7, 1.0, 0.75, loom::GridPlane::XY, trial % 2 == 1);
    // fold the sheet over itself (a half turn about x = 0.5) and shake it
    for (std::size_t i = 0; i < m.positions.size(); i += 3) {
      const double x = m.positions[i];
      if (x > 0.5) {
        m.positions[i] = 1.0 - x;
        m.positions[i + 2] = 0.03 + 0.2 * (x - 0.5);
      }
      for (int k = 0; k < 3; ++k) m.positions[i + k] += 0.01 * z(rng);
    }
    const double bf = brute_force(m);
    ASSERT_TRUE(std::isfinite(bf));
    for (double within : {1.001 * bf, 2 * bf, 10.0}) {
      for (int threads : {1, 2}) {
        omp_set_num_threads(threads);
        const loom::ClosestApproach c = loom::closest_approach(m, {}, within);
        EXPECT_EQ(c.distance, bf) << "trial " << trial << " within " << within << " threads " << threads;
      }
    }
    EXPECT_FALSE(std::isfinite(loom::closest_approach(m, {}, bf).distance));  // none below the minimum itself
  }
  omp_set_num_threads(omp_get_num_procs());
}

TEST(ClosestApproach, BadInput) {
  const loom::Mesh g = loom::make_grid(3, 3, 1.0, 1.0);
  std::vector<double> x = g.positions;
  x[4] = NAN;
  EXPECT_THROW(loom::closest_approach(g, x, 1.0), loom::InputError);
  EXPECT_THROW(loom::closest_approach(g, {}, 0.0), loom::InputError);
  EXPECT_THROW(loom::closest_approach(g, std::vector<double>(6, 0.0), 1.0), loom::InputError);
}

// Self-collision building blocks: exact CCD times for constructed motions, closest-point
// distances against independent computations, and the refit BVH against brute force.
#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <random>
#include <string>

#include "loom/collider.hpp"
#include "loom/mesh.hpp"
#include "loom/params.hpp"
#include "loom/self_collision.hpp"
#include "loom/intersection_check.hpp"

using namespace loom;
using namespace loom::selfcol;

namespace {

void set4(double x[4][3], std::initializer_list<std::array<double, 3>> pts) {
  int i = 0;
  for (const auto& p : pts) {
    for (int k = 0; k < 3; ++k) x[i][k] = p[k];
    ++i;
  }
}

double norm3(const double* a) { return std::sqrt(a[0] * a[0] + a[1] * a[1] + a[2] * a[2]); }

// Point-segment distance by projection (independent of the library's Voronoi-region code).
double point_segment(const double* p, const double* a, const double* b) {
  double ab[3], ap[3];
  for (int k = 0; k < 3; ++k) ab[k] = b[k] - a[k], ap[k] = p[k] - a[k];
  double t = (ap[0] * ab[0] + ap[1] * ab[1] + ap[2] * ab[2]) / (ab[0] * ab[0] + ab[1] * ab[1] + ab[2] * ab[2]);
  t = std::clamp(t, 0.0, 1.0);
  double q[3];
  for (int k = 0; k < 3; ++k) q[k] = p[k] - (a[k] + t * ab[k]);
  return norm3(q);
}

// Point-triangle distance: the plane distance when the projection is inside (barycentric
// coordinates by solving the 2x2 normal equations), otherwise the nearest edge.
double brute_point_triangle(const double* p, const double* a, const double* b, const double* c) {
  double e1[3], e2[3], r[3];
  for (int k = 0; k < 3; ++k) e1[k] = b[k] - a[k], e2[k] = c[k] - a[k], r[k] = p[k] - a[k];
  auto d = [](const double* u, const double* v) { return u[0] * v[0] + u[1] * v[1] + u[2] * v[2]; };
  const double A = d(e1, e1), B = d(e1, e2), C = d(e2, e2), D = d(e1, r), E = d(e2, r);
  const double det = A * C - B * B;
  const double u = (C * D - B * E) / det, v = (A * E - B * D) / det;
  if (u >= 0 && v >= 0 && u + v <= 1) {
    double q[3];
    for (int k = 0; k < 3; ++k) q[k] = r[k] - u * e1[k] - v * e2[k];
    return norm3(q);
  }
  return std::min({point_segment(p, a, b), point_segment(p, b, c), point_segment(p, c, a)});
}

// Segment-segment distance: golden-section search on the convex function s -> dist(p(s), seg q).
double brute_segment_segment(const double* p0, const double* p1, const double* q0, const double* q1) {
  auto f = [&](double s) {
    double p[3];
    for (int k = 0; k < 3; ++k) p[k] = p0[k] + s * (p1[k] - p0[k]);
    return point_segment(p, q0, q1);
  };
  double lo = 0, hi = 1;
  const double g = (std::sqrt(5.0) - 1) / 2;
  for (int it = 0; it < 200; ++it) {
    const double m1 = hi - g * (hi - lo), m2 = lo + g * (hi - lo);
    if (f(m1) < f(m2)) hi = m2; else lo = m1;
  }
  return std::min({f(0.5 * (lo + hi)), f(0.0), f(1.0)});
}

}  // namespace

TEST(SelfCollisionCcd, VertexFallingThroughAFixedTriangleHitsAtTheCrossingTime) {
  double x0[4][3], x1[4][3];
  // p: z = 1 - 2t crosses the triangle z = 0 at t = 1/2.
  set4(x0, {{{0.2, 0.2, 1}}, {{0, 0, 0}}, {{1, 0, 0}}, {{0, 1, 0}}});
  set4(x1, {{{0.2, 0.2, -1}}, {{0, 0, 0}}, {{1, 0, 0}}, {{0, 1, 0}}});
  double t = -1;
  ASSERT_TRUE(ccd_vertex_triangle(x0, x1, 1e-9, t));
  EXPECT_NEAR(t, 0.5, 1e-12);
}

TEST(SelfCollisionCcd, VertexMeetsATiltingTriangleAtTheRootOfTheCoplanarityCubic) {
  // a = 0, b = (1,0,0) fixed, c(t) = (0, 1, 2t): the plane is z = 2t y. p(t) = (1/4, 1/4, 1 - 2t)
  // lies on it when 1 - 2t = t/2, t = 0.4, where p = (1/4, 1/4, 1/5) is inside the triangle.
  double x0[4][3], x1[4][3];
  set4(x0, {{{0.25, 0.25, 1}}, {{0, 0, 0}}, {{1, 0, 0}}, {{0, 1, 0}}});
  set4(x1, {{{0.25, 0.25, -1}}, {{0, 0, 0}}, {{1, 0, 0}}, {{0, 1, 2}}});
  double t = -1;
  ASSERT_TRUE(ccd_vertex_triangle(x0, x1, 1e-9, t));
  EXPECT_NEAR(t, 0.4, 1e-12);
  // Both moving: triangle rises z = -0.5 + t, vertex falls z = 1 - 3t: meet at t = 3/8.
  set4(x0, {{{0.3, 0.3, 1}}, {{0, 0, -0.5}}, {{1, 0, -0.5}}, {{0, 1, -0.5}}});
  set4(x1, {{{0.3, 0.3, -2}}, {{0, 0, 0.5}}, {{1, 0, 0.5}}, {{0, 1, 0.5}}});
  ASSERT_TRUE(ccd_vertex_triangle(x0, x1, 1e-9, t));
  EXPECT_NEAR(t, 0.375, 1e-12);
}

TEST(SelfCollisionCcd, VertexPassingBesideTheTriangleIsNoCollision) {
  double x0[4][3], x1[4][3];
  set4(x0, {{{0.8, 0.8, 1}}, {{0, 0, 0}}, {{1, 0, 0}}, {{0, 1, 0}}});  // x + y = 1.6 > 1: outside
  set4(x1, {{{0.8, 0.8, -1}}, {{0, 0, 0}}, {{1, 0, 0}}, {{0, 1, 0}}});
  double t;
  EXPECT_FALSE(ccd_vertex_triangle(x0, x1, 1e-9, t));
  // Stops short of the plane.
  set4(x1, {{{0.2, 0.2, 0.01}}, {{0, 0, 0}}, {{1, 0, 0}}, {{0, 1, 0}}});
  set4(x0, {{{0.2, 0.2, 1}}, {{0, 0, 0}}, {{1, 0, 0}}, {{0, 1, 0}}});
  EXPECT_FALSE(ccd_vertex_triangle(x0, x1, 1e-9, t));
}

TEST(SelfCollisionCcd, EdgesCrossingAtAnalyticTimes) {
  double x0[4][3], x1[4][3];
  // Edge 1 on the x axis, edge 2 parallel to y at z = 1 - 4t: they meet at t = 1/4.
  set4(x0, {{{-1, 0, 0}}, {{1, 0, 0}}, {{0.3, -1, 1}}, {{0.3, 1, 1}}});
  set4(x1, {{{-1, 0, 0}}, {{1, 0, 0}}, {{0.3, -1, -3}}, {{0.3, 1, -3}}});
  double t = -1;
  ASSERT_TRUE(ccd_edge_edge(x0, x1, 1e-9, t));
  EXPECT_NEAR(t, 0.25, 1e-12);
  // Edge 2 (the line y = -x at z = 0.5) stays, edge 1 rises z = t: the cubic is linear with its
  // root at t = 1/2, where the two edges cross at (0, 0, 0.5).
  set4(x0, {{{-1, 0, 0}}, {{1, 0, 0}}, {{-1, 1, 0.5}}, {{1, -1, 0.5}}});
  set4(x1, {{{-1, 0, 1}}, {{1, 0, 1}}, {{-1, 1, 0.5}}, {{1, -1, 0.5}}});
  ASSERT_TRUE(ccd_edge_edge(x0, x1, 1e-9, t));
  EXPECT_NEAR(t, 0.5, 1e-12);
  // Edge 2 passes beyond the end of edge 1: no collision.
  set4(x0, {{{-1, 0, 0}}, {{1, 0, 0}}, {{1.5, -1, 1}}, {{1.5, 1, 1}}});
  set4(x1, {{{-1, 0, 0}}, {{1, 0, 0}}, {{1.5, -1, -3}}, {{1.5, 1, -3}}});
  EXPECT_FALSE(ccd_edge_edge(x0, x1, 1e-9, t));
}

TEST(SelfCollisionCcd, CubicCandidateTimesContainTheRootsOfAKnownCubic) {
  // (t - 0.2)(t - 0.5)(t - 0.9) = t^3 - 1.6 t^2 + 0.73 t - 0.09
  double ts[7];
  const int n = cubic_candidate_times(-0.09, 0.73, -1.6, 1.0, ts);
  for (double r : {0.2, 0.5, 0.9}) {
    double best = 1;
    for (int i = 0; i < n; ++i) best = std::min(best, std::abs(ts[i] - r));
    EXPECT_LT(best, 1e-14) << r;
  }
  EXPECT_TRUE(std::is_sorted(ts, ts + n));
}

TEST(SelfCollisionDistance, PointTriangleAndSegmentSegmentMatchIndependentComputations) {
  std::mt19937 rng(7);
  std::uniform_real_distribution<double> u(-1, 1);
  for (int trial = 0; trial < 2000; ++trial) {
    double p[3], a[3], b[3], c[3], w[3];
    for (int k = 0; k < 3; ++k) p[k] = 2 * u(rng), a[k] = u(rng), b[k] = u(rng), c[k] = u(rng);
    const double d = point_triangle_distance(p, a, b, c, w);
    EXPECT_NEAR(d, brute_point_triangle(p, a, b, c), 1e-12);
    // The weights describe the closest point.
    double q[3];
    for (int k = 0; k < 3; ++k) q[k] = p[k] - (w[0] * a[k] + w[1] * b[k] + w[2] * c[k]);
    EXPECT_NEAR(norm3(q), d, 1e-12);
    EXPECT_NEAR(w[0] + w[1] + w[2], 1.0, 1e-12);
    double s, t;
    const double e = segment_segment_distance(p, a, b, c, s, t);
    EXPECT_NEAR(e, brute_segment_segment(p, a, b, c), 1e-9);
  }
}

TEST(SelfCollisionBvh, RefitCandidatesEqualBruteForceOnRandomlyMovedMeshes) {
  // Build once on a grid, then move the vertices at random (refit, no rebuild) and compare the
  // candidate pairs with an all-pairs test of the same inflated boxes.
  Mesh mesh = make_grid(9, 7, 1.0, 0.8, GridPlane::XZ);
  SelfCollision sc({0.01, 0.0}, mesh);
  std::mt19937 rng(3);
  std::normal_distribution<double> nd(0.0, 0.15);
  const Index nv = mesh.num_vertices(), nt = mesh.num_triangles();
  const auto edges = mesh.edges();
  for (int trial = 0; trial < 5; ++trial) {
    std::vector<double> x = mesh.positions;
    for (double& c : x) c += nd(rng);
    const double inflate = 0.05 + 0.05 * trial;
    std::vector<std::array<Index, 2>> vt, ee;
    sc.candidate_pairs(x, inflate, vt, ee);
    auto box = [&](std::initializer_list<Index> vs, double* lo, double* hi) {
      for (int k = 0; k < 3; ++k) lo[k] = 1e300, hi[k] = -1e300;
      for (Index v : vs)
        for (int k = 0; k < 3; ++k) lo[k] = std::min(lo[k], x[3 * v + k]), hi[k] = std::max(hi[k], x[3 * v + k]);
    };
    auto overlap = [&](const double* alo, const double* ahi, const double* blo, const double* bhi) {
      for (int k = 0; k < 3; ++k)
        if (alo[k] - inflate > bhi[k] || blo[k] > ahi[k] + inflate) return false;
      return true;
    };
    std::vector<std::array<Index, 2>> bvt, bee;
    for (Index v = 0; v < nv; ++v)
      for (Index t = 0; t < nt; ++t) {
        const Index* tv = &mesh.triangles[3 * t];
        if (v == tv[0] || v == tv[1] || v == tv[2]) continue;
        double alo[3], ahi[3], blo[3], bhi[3];
        box({v}, alo, ahi);
        box({tv[0], tv[1], tv[2]}, blo, bhi);
        if (overlap(alo, ahi, blo, bhi)) bvt.push_back({v, t});
      }
    for (Index e = 0; e < static_cast<Index>(edges.size()); ++e)
      for (Index f = e + 1; f < static_cast<Index>(edges.size()); ++f) {
        const auto &E = edges[e], &F = edges[f];
        if (E[0] == F[0] || E[0] == F[1] || E[1] == F[0] || E[1] == F[1]) continue;
        double alo[3], ahi[3], blo[3], bhi[3];
        box({E[0], E[1]}, alo, ahi);
        box({F[0], F[1]}, blo, bhi);
        if (overlap(alo, ahi, blo, bhi)) bee.push_back({e, f});
      }
    EXPECT_EQ(vt, bvt) << "trial " << trial;
    EXPECT_EQ(ee, bee) << "trial " << trial;
    EXPECT_GT(bvt.size(), 50u);
  }
}

TEST(SelfCollisionBvh, MinDistanceMatchesBruteForce) {
  Mesh mesh = make_grid(6, 6, 1.0, 1.0, GridPlane::XZ);
  SelfCollision sc({0.01, 0.0}, mesh);
  std::mt19937 rng(11);
  std::normal_distribution<double> nd(0.0, 0.05);
  std::vector<double> x = mesh.positions;
  for (double& c : x) c += nd(rng);
  double brute = 1e300;
  const Index nt = mesh.num_triangles();
  for (Index v = 0; v < mesh.num_vertices(); ++v)
    for (Index t = 0; t < nt; ++t) {
      const Index* tv = &mesh.triangles[3 * t];
      if (v == tv[0] || v == tv[1] || v == tv[2]) continue;
      brute = std::min(brute, brute_point_triangle(&x[3 * v], &x[3 * tv[0]], &x[3 * tv[1]], &x[3 * tv[2]]));
    }
  const auto edges = mesh.edges();
  for (std::size_t e = 0; e < edges.size(); ++e)
    for (std::size_t f = e + 1; f < edges.size(); ++f) {
      const auto &E = edges[e], &F = edges[f];
      if (E[0] == F[0] || E[0] == F[1] || E[1] == F[0] || E[1] == F[1]) continue;
      brute = std::min(brute, brute_segment_segment(&x[3 * E[0]], &x[3 * E[1]], &x[3 * F[0]], &x[3 * F[1]]));
    }
  EXPECT_NEAR(sc.min_distance(x, 10.0), brute, 1e-9);
}

namespace {

// Three separate triangles: A in the plane y = 0, B a small one 5 cm above it, C far away.
// In one step of h = 0.01 s, B moves 10 cm down (through A) and C moves sideways.
struct ThroughStep {
  Mesh mesh;
  State s;
  std::vector<double> x0, x1;
  ThroughStep() {
    mesh.positions = {0, 0, 0, 1, 0, 0, 0, 0, 1,                   // A
                      0.2, 0.05, 0.2, 0.3, 0.05, 0.2, 0.2, 0.05, 0.3,  // B
                      5, 0, 5, 6, 0, 5, 5, 0, 6};                  // C
    mesh.triangles = {0, 1, 2, 3, 4, 5, 6, 7, 8};
    s.resize(9);
    for (Index i = 0; i < 9; ++i) s.mass[i] = 0.01;
    s.update_inverse_masses();
    x0 = mesh.positions;
    x1 = x0;
    for (Index i = 3; i < 6; ++i) x1[3 * i + 1] -= 0.1;
    for (Index i = 6; i < 9; ++i) x1[3 * i] += 0.02;
  }
  void step(SelfCollision& sc, double h) {
    s.x = x0;
    sc.begin_step(s);
    s.x = x1;
    for (std::size_t k = 0; k < s.v.size(); ++k) s.v[k] = (x1[k] - x0[k]) / h;
    sc.resolve(s, h);
  }
};

}  // namespace

TEST(SelfCollisionResponse, ATriangleDrivenThroughAnotherStopsAboveItWithoutApproachVelocity) {
  ThroughStep t;
  for (Index b = 3; b < 6; ++b) ASSERT_LT(t.x1[3 * b + 1], 0.0);  // the unprotected step tunnels through A
  const double th = 0.01;
  SelfCollision sc({th, 0.0}, t.mesh);
  t.step(sc, 0.01);
  EXPECT_EQ(loom::count_intersecting_pairs(t.mesh, t.s.x), 0);
  EXPECT_EQ(sc.last_stats().frozen, 0);
  // Every vertex of B ends on the side of A's (tilted) plane it started on, and not closer than
  // the CCD separation (0.1 thickness) to A.
  const double* a0 = &t.s.x[0];
  const double* a1 = &t.s.x[3];
  const double* a2 = &t.s.x[6];
  double e1[3], e2[3], nrm[3];
  for (int k = 0; k < 3; ++k) e1[k] = a1[k] - a0[k], e2[k] = a2[k] - a0[k];
  nrm[0] = e1[1] * e2[2] - e1[2] * e2[1], nrm[1] = e1[2] * e2[0] - e1[0] * e2[2], nrm[2] = e1[0] * e2[1] - e1[1] * e2[0];
  if (nrm[1] < 0) for (double& c : nrm) c = -c;
  for (Index b = 3; b < 6; ++b) {
    const double* p = &t.s.x[3 * b];
    EXPECT_GT((p[0] - a0[0]) * nrm[0] + (p[1] - a0[1]) * nrm[1] + (p[2] - a0[2]) * nrm[2], 0.0) << b;
    double w[3];
    EXPECT_GT(point_triangle_distance(p, a0, a1, a2, w), 0.1 * th - 1e-12) << b;
  }
  // Momentum along y is conserved by the impulses (equal masses, none pinned).
  double p = 0;
  for (Index i = 0; i < 6; ++i) p += t.s.v[3 * i + 1];
  EXPECT_NEAR(p, 3 * (-0.1 / 0.01), 1e-9);
  for (Index i = 6; i < 9; ++i) EXPECT_EQ(t.s.x[3 * i], t.x1[3 * i]);          // C untouched
}

TEST(SelfCollisionResponse, FailSafeAloneReturnsTheCollidingVerticesToTheirStart) {
  ThroughStep t;
  SelfCollision::Options o{0.01, 0.0};
  o.ccd_iterations = 0;
  o.repulsion = false;
  SelfCollision sc(o, t.mesh);
  t.step(sc, 0.01);
  EXPECT_EQ(loom::count_intersecting_pairs(t.mesh, t.s.x), 0);
  EXPECT_EQ(sc.last_stats().frozen, 6);  // the vertices of the colliding pairs: B and A (A was at rest)
  for (Index i = 3; i < 6; ++i)
    for (int k = 0; k < 3; ++k) {
      EXPECT_EQ(t.s.x[3 * i + k], t.x0[3 * i + k]);
      EXPECT_EQ(t.s.v[3 * i + k], 0.0);
    }
  for (Index i = 6; i < 9; ++i) EXPECT_EQ(t.s.x[3 * i], t.x1[3 * i]);  // C moved as integrated
}


TEST(SelfCollisionResponse, AVertexPutBackOntoAColliderFarAlongItsPathIsCheckedAgainstPairsThatWereNotNear) {
  // The fail-safe after a clean CCD pass re-checks the pairs of the vertices that keep_outside
  // put back onto a collider, and only the near pairs while no vertex's displacement changed by
  // more than about half the thickness. Here the put-back changes it by 4-5 thicknesses:
  // vertex A of P (its other vertices at rest) and the small triangle E beside it (0.5 th
  // away, moving with A, so that the repulsion touches both) fall 15.5 cm from above a sphere
  // of radius 0.1 to 3.5-5.5 cm inside it; the projection onto the sphere carries their ends
  // 4.5-6.5 cm further down, through triangle C, which was 3 thicknesses farther than A's
  // step could bring it (a pair outside the near list). The fail-safe must find the crossings.
  const double th = 0.01;
  Mesh mesh;
  mesh.positions = {0, 0, 0.105, 0.3, 0, 0.2, 0.3, 0.05, 0.2,                      // P (vertex 0 = A)
                    -0.005, -0.01, 0.10, -0.005, 0.01, 0.10, -0.005, 0, 0.12,       // E
                    -0.01, -0.02, -0.08, 0.01, -0.02, -0.08, 0, 0.02, -0.08};      // C, inside the sphere
  mesh.triangles = {0, 1, 2, 3, 4, 5, 6, 7, 8};
  State s;
  s.resize(9);
  for (Index i = 0; i < 9; ++i) s.mass[i] = 0.01;
  s.update_inverse_masses();
  const std::vector<double> x0 = mesh.positions;
  std::vector<double> x1 = x0;
  x1[2] = -0.05;
  for (Index i = 3; i < 6; ++i) x1[3 * i + 2] -= 0.155;
  ASSERT_EQ(loom::count_intersecting_pairs(mesh, x0), 0);
  ASSERT_EQ(loom::count_intersecting_pairs(mesh, x1), 0);  // the unprojected ends do not reach C
  const ColliderSet colliders =
      ColliderSet::parse(Params::from_string("colliders: [{type: sphere, center: [0, 0, 0], radius: 0.1}]", "c.yaml")
                             .child("colliders"));
  SelfCollision sc({th, 0.0}, mesh);
  const double h = 0.01;
  s.x = x0;
  sc.begin_step(s);
  s.x = x1;
  for (std::size_t k = 0; k < s.v.size(); ++k) s.v[k] = (x1[k] - x0[k]) / h;
  sc.resolve(s, h, &colliders);
  ASSERT_GT(sc.last_stats().proximity, 0);  // E's repulsion touched A (keep_outside looks at touched vertices)
  EXPECT_EQ(sc.last_stats().ccd_collisions, 0);
  EXPECT_EQ(loom::count_intersecting_pairs(mesh, s.x), 0);
  EXPECT_GT(sc.last_stats().frozen, 0);
  for (int k = 0; k < 3; ++k) EXPECT_EQ(s.x[k], x0[k]);  // A returned to its start
}

TEST(SelfCollisionResponse, APinnedTriangleDrivenThroughFreeClothPushesItAndTheFailSafeEnds) {
  // A is pinned and moves up 10 cm through B (free, at rest 5 cm above): B must give way.
  ThroughStep t;
  for (Index i = 0; i < 3; ++i) t.s.pin(i);
  t.s.update_inverse_masses();
  t.x1 = t.x0;
  for (Index i = 0; i < 3; ++i) t.x1[3 * i + 1] += 0.1;
  const double th = 0.01;
  SelfCollision sc({th, 0.0}, t.mesh);
  t.step(sc, 0.01);
  EXPECT_EQ(loom::count_intersecting_pairs(t.mesh, t.s.x), 0u);
  for (Index i = 0; i < 3; ++i) EXPECT_EQ(t.s.x[3 * i + 1], 0.1);        // the pin moved as prescribed
  for (Index b = 3; b < 6; ++b) EXPECT_GT(t.s.x[3 * b + 1], 0.1);        // B pushed above A
  // With only the fail-safe, freezing B cannot stop a prescribed motion: it must still end.
  SelfCollision::Options o{th, 0.0};
  o.ccd_iterations = 0;
  o.repulsion = false;
  SelfCollision bare(o, t.mesh);
  t.step(bare, 0.01);
  EXPECT_EQ(bare.last_stats().frozen, 3);
}

namespace {

// The shaken sheet of the list-completeness tests: options, a state at rest with 1 g
// vertices, and one random shake per step (every `fast`-th vertex moves 4x as far).
SelfCollision::Options shaken_sheet_options(double thickness, double refresh_fraction) {
  SelfCollision::Options o;
  o.thickness = thickness;
  o.friction = 0.2;
  o.refresh_fraction = refresh_fraction;
  return o;
}

// The lists by brute force: every non-adjacent vertex-triangle and edge-edge pair whose distance
// at the reference positions X is below th + the largest reach of each element's vertices, in
// the lists' order (vertex, then triangle; edge pairs e < f).
void brute_force_lists(const Mesh& mesh, const std::vector<std::array<Index, 2>>& edges, const std::vector<double>& X,
                       const std::vector<double>& reach, double th, std::vector<std::array<Index, 2>>& bvt,
                       std::vector<std::array<Index, 2>>& bee) {
  bvt.clear();
  bee.clear();
  const Index nv = mesh.num_vertices(), nt = mesh.num_triangles();
  for (Index v = 0; v < nv; ++v)
    for (Index t = 0; t < nt; ++t) {
      const Index* tv = &mesh.triangles[3 * t];
      if (v == tv[0] || v == tv[1] || v == tv[2]) continue;
      const double r = th + reach[v] + std::max({reach[tv[0]], reach[tv[1]], reach[tv[2]]});
      double w[3];
      if (point_triangle_distance(&X[3 * v], &X[3 * tv[0]], &X[3 * tv[1]], &X[3 * tv[2]], w) < r) bvt.push_back({v, t});
    }
  for (Index e = 0; e < static_cast<Index>(edges.size()); ++e)
    for (Index f = e + 1; f < static_cast<Index>(edges.size()); ++f) {
      const auto &E = edges[e], &F = edges[f];
      if (E[0] == F[0] || E[0] == F[1] || E[1] == F[0] || E[1] == F[1]) continue;
      const double r = th + std::max(reach[E[0]], reach[E[1]]) + std::max(reach[F[0]], reach[F[1]]);
      double a, b;
      if (segment_segment_distance(&X[3 * E[0]], &X[3 * E[1]], &X[3 * F[0]], &X[3 * F[1]], a, b) < r) bee.push_back({e, f});
    }
}

State shaken_sheet_state(const Mesh& mesh) {
  State s;
  s.resize(mesh.num_vertices());
  for (Index i = 0; i < mesh.num_vertices(); ++i) s.mass[i] = 1e-3;
  s.update_inverse_masses();
  s.x = mesh.positions;
  return s;
}

// Every vertex moved at random (every `fast`-th vertex four times as far), plus `common` (a
// displacement of the whole sheet in the step, if given).
void shake(State& s, std::mt19937& rng, std::normal_distribution<double>& N, Index fast, double h,
           const double* common = nullptr) {
  for (Index i = 0; i < s.size(); ++i)
    for (int k = 0; k < 3; ++k) {
      const double dx = (i % fast == 0 ? 0.006 : 0.0015) * N(rng) + (common ? common[k] : 0.0);
      s.x[3 * i + k] += dx;
      s.v[3 * i + k] = dx / h;
    }
}

}  // namespace

TEST(SelfCollisionBvh, ListsKeptByRefreshOrRebuildHoldEveryPairThatComesWithinTheThickness) {
  // A 10 x 10 sheet shaken at random step after step (most vertices slow, every 17th fast), so
  // that vertices leave their reach at different steps. After each resolve(), every
  // non-adjacent pair closer than the thickness at the start, middle or end of the step (all
  // pairs, brute force) must be in the candidate lists: once keeping them by refreshes alone
  // (refresh_fraction 1), once by full rebuilds alone (0). Then the same while the whole sheet
  // also moves, by several thicknesses per step in a direction that turns from step to step:
  // the lists measure motion after the sheet's mean motion is taken off (their frame), which
  // must keep them complete whatever the common motion does. Then the same again while the
  // sheet also turns about its centroid by 0.08 rad per step (up to 2.8 thicknesses) about an
  // axis that wanders from step to step: the frame takes off the mean rotation too.
  const Mesh mesh = make_grid(10, 10, 0.3, 0.3, GridPlane::XZ);  // edge 0.033
  const Index nv = mesh.num_vertices(), nt = mesh.num_triangles();
  const auto edges = mesh.edges();
  const double th = 0.006, h = 0.01;
  for (const int motion : {0, 1, 2})  // shaken only; and moving; and moving and turning
  for (const double fraction : {1.0, 0.0}) {
    const bool moving = motion > 0;
    SelfCollision sc(shaken_sheet_options(th, fraction), mesh);
    State s = shaken_sheet_state(mesh);
    std::mt19937 rng(23);
    std::normal_distribution<double> N(0.0, 1.0);
    Index refreshed = 0, rebuilds = 0, near_pairs = 0;
    std::vector<std::array<Index, 2>> vt, ee;
    for (int step = 0; step < 150; ++step) {
      const std::vector<double> x0 = s.x;
      sc.begin_step(s);
      const double turn = 0.05 * step;  // rad: the common motion (5 thicknesses per step) turns
      const double common[3] = {0.03 * std::cos(turn), 0.01 * std::sin(3 * turn), 0.03 * std::sin(turn)};
      shake(s, rng, N, 17, h, moving ? common : nullptr);
      if (motion == 2) {  // the chord of a turn by 0.08 rad about a wandering axis through the centroid
        double c[3] = {0, 0, 0}, a[3] = {std::sin(turn), 1.0, std::cos(3 * turn)};
        const double la = std::sqrt(a[0] * a[0] + a[1] * a[1] + a[2] * a[2]);
        for (double& ak : a) ak /= la;
        for (Index i = 0; i < nv; ++i)
          for (int k = 0; k < 3; ++k) c[k] += x0[3 * i + k] / static_cast<double>(nv);
        const double sn = std::sin(0.08), cs = std::cos(0.08);
        for (Index i = 0; i < nv; ++i) {
          const double r[3] = {s.x[3 * i] - c[0], s.x[3 * i + 1] - c[1], s.x[3 * i + 2] - c[2]};
          const double ar = a[0] * r[0] + a[1] * r[1] + a[2] * r[2];
          const double axr[3] = {a[1] * r[2] - a[2] * r[1], a[2] * r[0] - a[0] * r[2], a[0] * r[1] - a[1] * r[0]};
          for (int k = 0; k < 3; ++k) {
            const double turned = c[k] + r[k] * cs + axr[k] * sn + a[k] * ar * (1 - cs);  // Rodrigues
            s.v[3 * i + k] += (turned - s.x[3 * i + k]) / h;
            s.x[3 * i + k] = turned;
          }
        }
      }
      sc.resolve(s, h);
      refreshed += sc.last_stats().refreshed;
      rebuilds += sc.last_stats().rebuilds;
      sc.candidate_lists(vt, ee);
      std::vector<double> xm(s.x.size());
      for (std::size_t q = 0; q < xm.size(); ++q) xm[q] = 0.5 * (x0[q] + s.x[q]);
      const std::vector<double>* at[3] = {&x0, &xm, &s.x};
      for (Index v = 0; v < nv; ++v)
        for (Index t = 0; t < nt; ++t) {
          const Index* tv = &mesh.triangles[3 * t];
          if (v == tv[0] || v == tv[1] || v == tv[2]) continue;
          double d = 1e300, w[3];
          for (const auto* X : at)
            d = std::min(d, point_triangle_distance(&(*X)[3 * v], &(*X)[3 * tv[0]], &(*X)[3 * tv[1]], &(*X)[3 * tv[2]], w));
          if (d >= th) continue;
          ++near_pairs;
          ASSERT_TRUE(std::binary_search(vt.begin(), vt.end(), std::array<Index, 2>{v, t}))
              << "vertex " << v << " triangle " << t << " at distance " << d << ", step " << step << ", fraction "
              << fraction << ", motion " << motion;
        }
      for (Index e = 0; e < static_cast<Index>(edges.size()); ++e)
        for (Index f = e + 1; f < static_cast<Index>(edges.size()); ++f) {
          const auto &E = edges[e], &F = edges[f];
          if (E[0] == F[0] || E[0] == F[1] || E[1] == F[0] || E[1] == F[1]) continue;
          double d = 1e300, a, b;
          for (const auto* X : at)
            d = std::min(d, segment_segment_distance(&(*X)[3 * E[0]], &(*X)[3 * E[1]], &(*X)[3 * F[0]], &(*X)[3 * F[1]], a, b));
          if (d >= th) continue;
          ++near_pairs;
          ASSERT_TRUE(std::binary_search(ee.begin(), ee.end(), std::array<Index, 2>{e, f}))
              << "edges " << e << ", " << f << " at distance " << d << ", step " << step << ", fraction " << fraction
              << ", motion " << motion;
        }
    }
    EXPECT_GT(near_pairs, 100) << fraction;  // the sheet did crumple: the check is not vacuous
    if (fraction == 1.0) {
      EXPECT_GT(refreshed, 50) << "motion " << motion;  // the refreshes were exercised
      EXPECT_EQ(rebuilds, 1);  // the first step only
    } else {
      EXPECT_EQ(refreshed, 0);
      EXPECT_GT(rebuilds, 10) << "motion " << motion;
    }
  }
}

TEST(SelfCollisionDistance, SeparatingAxisRejectionsNeverExceedTheDistance) {
  // segments_farther_than / point_triangle_farther_than may only answer "at least r" when the
  // distance (independent brute-force minimisation) is at least r. Random elements at every
  // scale of separation, with r just below, at and above the distance; plus touching,
  // parallel and degenerate elements.
  std::mt19937 rng(41);
  std::uniform_real_distribution<double> U(-1.0, 1.0);
  int rejected = 0, cases = 0;
  for (int trial = 0; trial < 3000; ++trial) {
    const double spread = trial % 3 == 0 ? 0.1 : (trial % 3 == 1 ? 1.0 : 3.0);
    double p[3], a[3], b[3], c[3];
    for (int k = 0; k < 3; ++k) {
      p[k] = spread * U(rng);
      a[k] = U(rng);
      b[k] = U(rng);
      c[k] = U(rng);
    }
    if (trial % 50 == 0)
      for (int k = 0; k < 3; ++k) c[k] = 0.5 * (a[k] + b[k]);  // degenerate triangle, and segment through a midpoint
    if (trial % 50 == 1)
      for (int k = 0; k < 3; ++k) c[k] = p[k] + (b[k] - a[k]);  // segments (a, b) and (p, c) parallel
    if (trial % 50 == 2)
      for (int k = 0; k < 3; ++k) p[k] = (a[k] + b[k] + c[k]) / 3.0;  // vertex at the centroid
    if (trial % 50 == 3)
      for (int k = 0; k < 3; ++k) p[k] = a[k] + b[k] - c[k];  // segments (a, b), (p, c) crossing at their midpoints
    if (trial % 50 == 4)
      for (int k = 0; k < 3; ++k) p[k] = b[k] + (b[k] - a[k]), c[k] = b[k] + 2 * (b[k] - a[k]);  // collinear, in a row
    if (trial % 50 == 5)
      for (int k = 0; k < 3; ++k) p[k] = a[k] + 0.25 * (b[k] - a[k]), c[k] = a[k] + 0.75 * (b[k] - a[k]);  // overlapping
    const double dvt = brute_point_triangle(p, a, b, c);
    const double dee = brute_segment_segment(a, b, p, c);
    for (const double f : {0.0, 0.5, 0.9, 0.999, 1.001, 1.1, 2.0}) {
      // r = f d, and for elements that touch (d = 0) a small positive r: never "farther".
      if (dvt == 0 && point_triangle_farther_than(p, a, b, c, 1e-3 * (1 + f))) ADD_FAILURE() << "touching, trial " << trial;
      if (dee == 0 && segments_farther_than(a, b, p, c, 1e-3 * (1 + f))) ADD_FAILURE() << "touching, trial " << trial;
      ++cases;
      if (point_triangle_farther_than(p, a, b, c, f * dvt)) {
        ++rejected;
        EXPECT_GE(dvt, f * dvt - 1e-9) << "vertex-triangle rejected above its distance, trial " << trial;
      }
      if (segments_farther_than(a, b, p, c, f * dee)) {
        ++rejected;
        EXPECT_GE(dee, f * dee - 1e-9) << "edge-edge rejected above its distance, trial " << trial;
      }
    }
  }
  EXPECT_GT(rejected, cases / 10);  // the bound does reject (it is not trivially false)

  // On a flat sheet, neighbours beside each other (the pairs a rebuild mostly visits) are
  // rejected at half an edge: their distances are at least 0.707 edge, and the axis between
  // the centres lies in the sheet, across the gap between them.
  const Mesh mesh = make_grid(5, 5, 1.0, 1.0, GridPlane::XZ);  // edge 0.25
  const double r = 0.5 * 0.25;
  const auto edges = mesh.edges();
  const double* x = mesh.positions.data();
  int pairs = 0, kept = 0;
  for (Index v = 0; v < mesh.num_vertices(); ++v)
    for (Index t = 0; t < mesh.num_triangles(); ++t) {
      const Index* tv = &mesh.triangles[3 * t];
      if (v == tv[0] || v == tv[1] || v == tv[2]) continue;
      ++pairs;
      ASSERT_GE(brute_point_triangle(&x[3 * v], &x[3 * tv[0]], &x[3 * tv[1]], &x[3 * tv[2]]), 0.7 * 0.25);
      kept += point_triangle_farther_than(&x[3 * v], &x[3 * tv[0]], &x[3 * tv[1]], &x[3 * tv[2]], r) ? 0 : 1;
    }
  for (std::size_t e = 0; e < edges.size(); ++e)
    for (std::size_t f = e + 1; f < edges.size(); ++f) {
      const auto &E = edges[e], &F = edges[f];
      if (E[0] == F[0] || E[0] == F[1] || E[1] == F[0] || E[1] == F[1]) continue;
      ++pairs;
      kept += segments_farther_than(&x[3 * E[0]], &x[3 * E[1]], &x[3 * F[0]], &x[3 * F[1]], r) ? 0 : 1;
    }
  EXPECT_EQ(kept, 0) << "of " << pairs << " non-adjacent pairs of the flat sheet";
}

TEST(SelfCollisionDistance, TriangleRejectionNeverExceedsAnElementPairDistance) {
  // triangles_farther_than(A, B, r) lets a rebuild skip every vertex-triangle and edge-edge
  // pair of A's and B's elements, so it may only answer "at least r" when each of those 15
  // distances (vertex of one against the other triangle, edge against edge; brute-force
  // minimisation, independent of the code) is at least r. Random triangles at several
  // separations, with r below, at and above the smallest; triangles sharing a vertex never.
  std::mt19937 rng(43);
  std::uniform_real_distribution<double> U(-1.0, 1.0);
  int rejected = 0, cases = 0;
  for (int trial = 0; trial < 2000; ++trial) {
    const double shift = trial % 4 == 0 ? 0.0 : (trial % 4 == 1 ? 1.0 : (trial % 4 == 2 ? 2.5 : 5.0));
    double a[3][3], b[3][3];
    for (int i = 0; i < 3; ++i)
      for (int k = 0; k < 3; ++k) {
        a[i][k] = U(rng);
        b[i][k] = U(rng) + (k == 0 ? shift : 0.0);
      }
    if (trial % 25 == 0)
      for (int k = 0; k < 3; ++k) b[0][k] = a[2][k];  // sharing a vertex: touching
    double m = 1e300;
    for (int i = 0; i < 3; ++i) {
      m = std::min(m, brute_point_triangle(a[i], b[0], b[1], b[2]));
      m = std::min(m, brute_point_triangle(b[i], a[0], a[1], a[2]));
      for (int j = 0; j < 3; ++j) m = std::min(m, brute_segment_segment(a[i], a[(i + 1) % 3], b[j], b[(j + 1) % 3]));
    }
    for (const double f : {0.0, 0.5, 0.9, 0.999, 1.001, 1.1, 2.0}) {
      ++cases;
      if (trial % 25 == 0 && triangles_farther_than(a[0], a[1], a[2], b[0], b[1], b[2], 1e-3 * (1 + f)))
        ADD_FAILURE() << "triangles sharing a vertex rejected, trial " << trial;
      if (triangles_farther_than(a[0], a[1], a[2], b[0], b[1], b[2], f * m)) {
        ++rejected;
        EXPECT_GE(m, f * m - 1e-9) << "triangle pair rejected above an element pair's distance, trial " << trial;
      }
    }
  }
  EXPECT_GT(rejected, cases / 10);  // it does reject
}

TEST(SelfCollisionBvh, ListsHoldExactlyThePairsWithinThicknessPlusReachesAfterRefreshesAndRebuilds) {
  // The same shaken sheet as above. After every step the lists must equal, pair for pair and
  // without duplicates, the non-adjacent pairs whose distance at the lists' reference positions
  // is below thickness + the largest reach of each element's vertices (brute force over all
  // pairs): refreshes (a traversal restricted to the refreshed triangles, which must find
  // exactly the pairs it dropped) and rebuilds alike.
  const Mesh mesh = make_grid(10, 10, 0.3, 0.3, GridPlane::XZ);
  const auto edges = mesh.edges();
  const double th = 0.006, h = 0.01;
  for (const double fraction : {1.0, 0.0}) {
    SelfCollision sc(shaken_sheet_options(th, fraction), mesh);
    State s = shaken_sheet_state(mesh);
    std::mt19937 rng(29);
    std::normal_distribution<double> N(0.0, 1.0);
    Index refreshed = 0;
    std::size_t checked = 0;
    std::vector<std::array<Index, 2>> vt, ee, bvt, bee;
    std::vector<double> X, reach;
    for (int step = 0; step < 120; ++step) {
      sc.begin_step(s);
      shake(s, rng, N, 13, h);
      sc.resolve(s, h);
      if (!sc.last_stats().rebuilt) continue;
      refreshed += sc.last_stats().refreshed;
      sc.candidate_lists(vt, ee);
      sc.list_reference(X, reach);
      brute_force_lists(mesh, edges, X, reach, th, bvt, bee);
      ASSERT_EQ(vt, bvt) << "step " << step << ", fraction " << fraction;
      ASSERT_EQ(ee, bee) << "step " << step << ", fraction " << fraction;
      checked += bvt.size() + bee.size();
    }
    EXPECT_GT(checked, 1000u) << fraction;
    if (fraction == 1.0) {
      EXPECT_GT(refreshed, 100) << "the refreshes were exercised";
    }
  }
}

TEST(SelfCollisionBvh, ReachOfAFastVertexAtARebuildGrowsUpToOneThicknessForSmallSteps) {
  // The reach set at a rebuild (list_reference): max(th/2, 2|d|) + min(16|d|, th) after an
  // explicit step (resolve() alone), max(th/2, |d|) + min(16|d|, th/4) once an integrator with
  // large steps has asked for proximity_pairs. A flat sheet translated by |d| = th/8 (first
  // step: a rebuild): th/2 + th = 1.5 th, and th/2 + th/4 = 0.75 th; by |d| = th/64: th/2 + th/4
  // both (16 |d| = th/4).
  const Mesh mesh = make_grid(6, 6, 0.2, 0.2, GridPlane::XZ);
  const double th = 0.006, h = 0.01;
  for (const double step : {th / 8, th / 64})
    for (const bool large : {false, true}) {
      SelfCollision sc(shaken_sheet_options(th, 1.0 / 256), mesh);
      State s = shaken_sheet_state(mesh);
      std::vector<double> d(s.x.size(), 0.0);
      for (Index i = 0; i < mesh.num_vertices(); ++i) d[3 * i + 1] = step;
      if (large) {
        std::vector<ProximityPair> out;
        sc.proximity_pairs(s.x.data(), d.data(), out);
      }
      sc.begin_step(s);
      for (std::size_t q = 0; q < s.x.size(); ++q) s.x[q] += d[q], s.v[q] = d[q] / h;
      sc.resolve(s, h);
      std::vector<double> X, reach;
      sc.list_reference(X, reach);
      const double expected = step == th / 8 ? (large ? 0.75 * th : 1.5 * th) : 0.5 * th + 16 * step;
      for (Index i = 0; i < mesh.num_vertices(); ++i)
        ASSERT_NEAR(reach[i], expected, 1e-12) << "vertex " << i << ", step " << step << ", large " << large;
    }
}

namespace {

// A grid sheet (XZ plane, n x n vertices over 1 m) folded into a U along x = 0.45: flat up to
// there, a half cylinder of radius rho, then flat again back over the first part, 2 rho above
// it; plus a small random jitter (no exact ties). In the crease, elements of triangles that
// share a vertex come close to each other (the pairs a rebuild takes from its neighbour lists);
// across the layers, elements far apart in the mesh do (the pairs its traversal finds).
std::vector<double> folded_sheet(const Mesh& mesh, double rho, unsigned seed) {
  std::mt19937 rng(seed);
  std::uniform_real_distribution<double> jitter(-1e-4, 1e-4);
  const double a = 0.45, bend = 3.14159265358979323846 * rho;
  std::vector<double> x(mesh.positions.size());
  for (Index v = 0; v < mesh.num_vertices(); ++v) {
    const double u = mesh.positions[3 * v], z = mesh.positions[3 * v + 2];
    double p[3];
    if (u <= a) {
      p[0] = u, p[1] = 0;
    } else if (u <= a + bend) {
      const double th = (u - a) / rho;
      p[0] = a + rho * std::sin(th), p[1] = rho * (1 - std::cos(th));
    } else {
      p[0] = a - (u - a - bend), p[1] = 2 * rho;
    }
    p[2] = z;
    for (int k = 0; k < 3; ++k) x[3 * v + k] = p[k] + jitter(rng);
  }
  return x;
}

}  // namespace

TEST(SelfCollisionBvh, PairsOnAFoldedClothEqualABruteForceEnumeration) {
  // Every non-adjacent vertex-triangle and edge-edge pair closer than `within` on a folded
  // cloth, through the broad phase of a rebuild (SelfCollision::proximity_pairs: hierarchy
  // traversal for triangles sharing no vertex, the fixed neighbour lists for triangles sharing
  // one), against all O(n^2) pairs with this file's own distances (projection and golden-section
  // search, not the library's). 13^2 runs on one thread, 66^2 (over kParallelMinVertices) in
  // the parallel tasks and neighbour chunks. Pairs within 1e-9 of the cut-off are not compared.
  for (const int n : {13, 66}) {
    const Mesh mesh = make_grid(n, n, 1.0, 1.0, GridPlane::XZ);
    const double edge = 1.0 / (n - 1);
    const double within = 0.8 * edge, rho = 0.3 * edge;  // layers 0.6 edge apart: every stacked pair is near
    const std::vector<double> x = folded_sheet(mesh, rho, 41u + static_cast<unsigned>(n));
    SelfCollision sc({0.25 * edge, 0.0}, mesh);
    std::vector<SelfCollision::Proximity> vt, ee;
    sc.proximity_pairs(x.data(), within, vt, ee);
    const Index nv = mesh.num_vertices(), nt = mesh.num_triangles();
    const auto edges = mesh.edges();
    // Box gap: a lower bound on the distance of two vertex sets, to skip most of the O(n^2) pairs.
    auto box_gap = [&](std::initializer_list<Index> a, std::initializer_list<Index> b) {
      double g = 0;
      for (int k = 0; k < 3; ++k) {
        double alo = 1e300, ahi = -1e300, blo = 1e300, bhi = -1e300;
        for (Index v : a) alo = std::min(alo, x[3 * v + k]), ahi = std::max(ahi, x[3 * v + k]);
        for (Index v : b) blo = std::min(blo, x[3 * v + k]), bhi = std::max(bhi, x[3 * v + k]);
        g = std::max({g, blo - ahi, alo - bhi});
      }
      return g;
    };
    // Which triangles share a vertex with which (for counting the neighbour pairs in the answer).
    std::vector<std::vector<Index>> tris_of(nv);
    for (Index t = 0; t < nt; ++t)
      for (int k = 0; k < 3; ++k) tris_of[mesh.triangles[3 * t + k]].push_back(t);
    auto near_in_mesh = [&](std::initializer_list<Index> a, std::initializer_list<Index> b) {
      for (Index va : a)
        for (Index t : tris_of[va])
          for (Index vb : b)
            for (Index s : tris_of[vb])
              if (s == t) return true;
      return false;
    };
    std::size_t neighbour_pairs = 0, far_pairs = 0, ambiguous = 0;
    // Reports the first few differences (ADD_FAILURE per pair would print thousands), counts all.
    auto check = [&](const char* kind, const std::vector<SelfCollision::Proximity>& got,
                     const std::vector<std::array<Index, 2>>& want, const std::vector<double>& want_dist) {
      std::size_t i = 0, j = 0, wrong = 0;
      auto report = [&](const std::string& what) {
        if (++wrong <= 5) ADD_FAILURE() << kind << " pair " << what << ", n = " << n;
      };
      while (i < got.size() || j < want.size()) {
        const bool take_got = j == want.size() || (i < got.size() && std::array<Index, 2>{got[i].a, got[i].b} < want[j]);
        const bool take_want = i == got.size() || (j < want.size() && want[j] < std::array<Index, 2>{got[i].a, got[i].b});
        if (take_got) {
          report(std::to_string(got[i].a) + ", " + std::to_string(got[i].b) + " listed but not closer than the cut-off by brute force");
          ++i;
        } else if (take_want) {
          if (std::abs(want_dist[j] - within) > 1e-9)
            report(std::to_string(want[j][0]) + ", " + std::to_string(want[j][1]) + " at " + std::to_string(want_dist[j]) + " missing");
          ++j;
        } else {
          if (std::abs(got[i].distance - want_dist[j]) > 1e-9)
            report(std::to_string(want[j][0]) + ", " + std::to_string(want[j][1]) + ": distance " +
                   std::to_string(got[i].distance) + " against " + std::to_string(want_dist[j]));
          ++i, ++j;
        }
      }
      EXPECT_EQ(wrong, 0u) << kind << " pairs that differ, n = " << n;
    };
    // Brute force: pairs below within + 1e-9 (those within 1e-9 above the cut-off may be absent).
    std::vector<std::array<Index, 2>> bvt, bee;
    std::vector<double> dvt, dee;
    for (Index v = 0; v < nv; ++v)
      for (Index t = 0; t < nt; ++t) {
        const Index* tv = &mesh.triangles[3 * t];
        if (v == tv[0] || v == tv[1] || v == tv[2]) continue;
        if (box_gap({v}, {tv[0], tv[1], tv[2]}) >= within + 1e-9) continue;
        const double d = brute_point_triangle(&x[3 * v], &x[3 * tv[0]], &x[3 * tv[1]], &x[3 * tv[2]]);
        if (d >= within + 1e-9) continue;
        if (std::abs(d - within) <= 1e-9) ++ambiguous;
        bvt.push_back({v, t});
        dvt.push_back(d);
        ++(near_in_mesh({v}, {tv[0], tv[1], tv[2]}) ? neighbour_pairs : far_pairs);
      }
    for (Index e = 0; e < static_cast<Index>(edges.size()); ++e)
      for (Index f = e + 1; f < static_cast<Index>(edges.size()); ++f) {
        const auto &E = edges[e], &F = edges[f];
        if (E[0] == F[0] || E[0] == F[1] || E[1] == F[0] || E[1] == F[1]) continue;
        if (box_gap({E[0], E[1]}, {F[0], F[1]}) >= within + 1e-9) continue;
        const double d = brute_segment_segment(&x[3 * E[0]], &x[3 * E[1]], &x[3 * F[0]], &x[3 * F[1]]);
        if (d >= within + 1e-9) continue;
        if (std::abs(d - within) <= 1e-9) ++ambiguous;
        bee.push_back({e, f});
        dee.push_back(d);
        ++(near_in_mesh({E[0], E[1]}, {F[0], F[1]}) ? neighbour_pairs : far_pairs);
      }
    check("vertex-triangle", vt, bvt, dvt);
    check("edge-edge", ee, bee, dee);
    // Both sources of pairs are exercised (dropping either would fail above).
    EXPECT_GT(neighbour_pairs, static_cast<std::size_t>(4 * n)) << n;
    EXPECT_GT(far_pairs, static_cast<std::size_t>(20 * n)) << n;
    EXPECT_EQ(ambiguous, 0u) << n;
  }
}

TEST(SelfCollisionBvh, ListsKeptByRefreshesOfManyVerticesOnAShakenFoldEqualTheBruteForcePairs) {
  // A refresh searches again the pairs of its refreshed vertices, triangles and edges (through
  // the hierarchy for triangles sharing no vertex, the neighbour lists for those sharing one):
  // it must list every dropped pair once, including the pairs of two refreshed triangles, and no
  // other. A 20 x 20 sheet folded into a U (layers 0.6 edge apart, so stacked pairs far apart in
  // the mesh are listed), shaken for 60 steps with refreshes only (refresh_fraction 1: one step
  // refreshes a single vertex, another over a third of them). After every refresh the lists must
  // equal, pair for pair and without duplicates, the non-adjacent pairs closer than th + r_a +
  // r_b at the reference positions (all pairs, brute force).
  const int n = 20;
  const Mesh mesh = make_grid(n, n, 1.0, 1.0, GridPlane::XZ);
  const Index nv = mesh.num_vertices();
  const auto edges = mesh.edges();
  const double edge = 1.0 / (n - 1), th = 0.25 * edge, h = 0.01;
  SelfCollision sc(shaken_sheet_options(th, 1.0), mesh);
  State s = shaken_sheet_state(mesh);
  s.x = folded_sheet(mesh, 0.3 * edge, 7u);
  std::mt19937 rng(31);
  std::normal_distribution<double> N(0.0, 1.0);
  Index refreshed = 0, most = 0, fewest = nv, refreshes = 0, rebuilds = 0;
  std::size_t checked = 0, far_in_mesh = 0;
  std::vector<std::array<Index, 2>> vt, ee, bvt, bee;
  std::vector<double> X, reach;
  // Rest-position distance of two vertices in edges (the fold brings far ones close).
  auto rest_apart = [&](Index a, Index b) {
    const double* p = &mesh.positions[3 * a];
    const double* q = &mesh.positions[3 * b];
    return std::hypot(p[0] - q[0], p[2] - q[2]) / edge;
  };
  for (int step = 0; step < 60; ++step) {
    sc.begin_step(s);
    // Every 5th step moves about half the vertices beyond their reach (a refresh of many);
    // the others move every 11th vertex fast and the rest slowly (a refresh of a few).
    const bool big = step % 5 == 4;
    for (Index i = 0; i < nv; ++i)
      for (int k = 0; k < 3; ++k) {
        const double dx = (big ? 0.5 * th : (i % 11 == 0 ? 0.3 * th : 0.03 * th)) * N(rng);
        s.x[3 * i + k] += dx;
        s.v[3 * i + k] = dx / h;
      }
    sc.resolve(s, h);
    rebuilds += sc.last_stats().rebuilds;
    const Index r = sc.last_stats().refreshed;
    if (r == 0) continue;
    ++refreshes;
    refreshed += r;
    most = std::max(most, r);
    fewest = std::min(fewest, r);
    sc.candidate_lists(vt, ee);
    sc.list_reference(X, reach);
    brute_force_lists(mesh, edges, X, reach, th, bvt, bee);
    for (const auto& p : bvt)
      if (rest_apart(p[0], mesh.triangles[3 * p[1]]) > 4) ++far_in_mesh;
    for (const auto& p : bee)
      if (rest_apart(edges[p[0]][0], edges[p[1]][0]) > 4) ++far_in_mesh;
    ASSERT_EQ(vt, bvt) << "step " << step << ", " << r << " vertices refreshed";
    ASSERT_EQ(ee, bee) << "step " << step << ", " << r << " vertices refreshed";
    checked += bvt.size() + bee.size();
  }
  EXPECT_EQ(rebuilds, 1);  // the first step only
  EXPECT_GE(refreshes, 40) << "the check ran after most steps";
  EXPECT_GT(most, nv / 3) << "a refresh of half the vertices (pairs of two refreshed triangles)";
  EXPECT_LT(fewest, nv / 10) << "a refresh of a few vertices";
  EXPECT_GT(refreshed, 2 * nv);
  EXPECT_GT(far_in_mesh, 1000u) << "stacked pairs (found through the hierarchy, not the neighbour lists)";
  EXPECT_GT(checked, 10000u);
}

namespace {

// One step of displacement d for a cloth that no pair brings within the thickness: with large
// (baraff_witkin's path) proximity_pairs first, which must find nothing; then resolve(), which
// must leave the step as proposed.
void step_expecting_no_contact(SelfCollision& sc, State& s, const std::vector<double>& d, double h, bool large, int step) {
  if (large) {
    std::vector<ProximityPair> out;
    sc.proximity_pairs(s.x.data(), d.data(), out);
    EXPECT_TRUE(out.empty()) << "step " << step;
  }
  sc.begin_step(s);
  for (std::size_t q = 0; q < s.x.size(); ++q) s.x[q] += d[q];
  const std::vector<double> expect = s.x;
  sc.resolve(s, h);
  EXPECT_EQ(s.x, expect) << "step " << step;
}

}  // namespace

TEST(SelfCollisionBvh, AClothMovingAsAWholeKeepsItsListsInTheFrameOfItsMeanMotion) {
  // A folded cloth (two layers 1.5 thicknesses apart) thrown sideways and falling: every vertex
  // has the same velocity v = (2, 1, 0) m/s + g t, so with h = 0.01 s it moves about 2.2 cm (1.3
  // thicknesses) per step along a path that bends with gravity. Distances between elements do
  // not change under a common motion, and the lists measure motion after the cloth's mean
  // motion is taken off (their frame): after the first step's build they are neither rebuilt
  // nor refreshed in 100 steps, and stay the same pairs. (A reach measured in absolute motion,
  // at most 2|d| + th for a vertex moving |d| per step, is used up within two steps here; the
  // lists were rebuilt every second step before the frame.) The cloth's motion is left as it is:
  // no pair comes within the thickness, so there is no impulse. Both the explicit path
  // (resolve() alone) and baraff_witkin's (proximity_pairs, then resolve()).
  const Mesh mesh = make_grid(16, 16, 1.0, 1.0, GridPlane::XZ);  // edge 1/15
  const double th = 0.25 / 15, h = 0.01, g = -9.81;
  for (const bool large : {false, true}) {
    SelfCollision sc(shaken_sheet_options(th, 1.0 / 256), mesh);
    State s = shaken_sheet_state(mesh);
    s.x = folded_sheet(mesh, 0.75 * th, 41);
    for (Index i = 0; i < s.size(); ++i) s.v[3 * i] = 2.0, s.v[3 * i + 1] = 1.0;
    std::vector<std::array<Index, 2>> vt0, ee0, vt, ee;
    std::vector<double> d(s.x.size());
    int rebuilds = 0;
    Index refreshed = 0, impulses = 0;
    for (int step = 0; step < 100; ++step) {
      for (Index i = 0; i < s.size(); ++i) {
        s.v[3 * i + 1] += g * h;
        for (int k = 0; k < 3; ++k) d[3 * i + k] = h * s.v[3 * i + k];
      }
      step_expecting_no_contact(sc, s, d, h, large, step);
      const SelfCollisionTotals& t = sc.totals();
      if (step == 0) {
        sc.candidate_lists(vt0, ee0);
        ASSERT_GT(vt0.size() + ee0.size(), 0u);
        rebuilds = static_cast<int>(t.rebuilds);
        refreshed = static_cast<Index>(t.refreshed);
      }
      impulses = static_cast<Index>(t.impulses());
    }
    EXPECT_EQ(rebuilds, 1) << "large " << large;
    EXPECT_EQ(sc.totals().rebuilds, rebuilds) << "no rebuild after the first step, large " << large;
    EXPECT_EQ(sc.totals().refreshed, refreshed) << "no refresh after the first step, large " << large;
    EXPECT_EQ(impulses, 0);
    sc.candidate_lists(vt, ee);
    EXPECT_EQ(vt, vt0);
    EXPECT_EQ(ee, ee0);
    EXPECT_EQ(sc.totals().steps, 100);
  }
}

TEST(SelfCollisionBvh, AClothTurningAsAWholeKeepsItsListsInTheFrameOfItsRotation) {
  // The same folded cloth turning as a rigid body at 3 rad/s about a tilted axis through its
  // centroid while it drifts at 0.5 m/s: each step moves every vertex along the chord of its
  // circle (0.03 rad per step, up to 2.2 cm or 1.3 thicknesses at the far corners), and over the
  // 100 steps the cloth turns by 3 rad, so motion measured after the mean motion only (the
  // frame before 2026-12-02) would renew the lists within a few steps. Distances do not change
  // under a rotation, and the lists' frame follows the cloth's mean rotation too: after the
  // first step's build they are neither rebuilt nor refreshed, and stay the same pairs, on the
  // explicit path and baraff_witkin's. No pair comes within the thickness, so no impulse.
  const Mesh mesh = make_grid(16, 16, 1.0, 1.0, GridPlane::XZ);
  const double th = 0.25 / 15, h = 0.01, omega = 3.0;
  const double len = std::sqrt(0.3 * 0.3 + 1.0 + 0.2 * 0.2);
  const double a[3] = {0.3 / len, 1.0 / len, 0.2 / len}, drift[3] = {0.5, 0.0, -0.1};
  // The rotation by omega h about a (Rodrigues), row-major.
  double Q[9];
  {
    const double t = omega * h, sn = std::sin(t), cs = 1 - std::cos(t);
    const double K[9] = {0, -a[2], a[1], a[2], 0, -a[0], -a[1], a[0], 0};
    for (int r = 0; r < 3; ++r)
      for (int c = 0; c < 3; ++c) {
        double k2 = 0;
        for (int m = 0; m < 3; ++m) k2 += K[3 * r + m] * K[3 * m + c];
        Q[3 * r + c] = (r == c ? 1.0 : 0.0) + sn * K[3 * r + c] + cs * k2;
      }
  }
  for (const bool large : {false, true}) {
    SelfCollision sc(shaken_sheet_options(th, 1.0 / 256), mesh);
    State s = shaken_sheet_state(mesh);
    s.x = folded_sheet(mesh, 0.75 * th, 41);
    const std::vector<double> start = s.x;
    std::vector<std::array<Index, 2>> vt0, ee0, vt, ee;
    std::vector<double> d(s.x.size());
    long long rebuilds = 0, refreshed = 0;
    for (int step = 0; step < 100; ++step) {
      double c[3] = {0, 0, 0};
      for (Index i = 0; i < s.size(); ++i)
        for (int k = 0; k < 3; ++k) c[k] += s.x[3 * i + k] / static_cast<double>(s.size());
      for (Index i = 0; i < s.size(); ++i) {
        const double r[3] = {s.x[3 * i] - c[0], s.x[3 * i + 1] - c[1], s.x[3 * i + 2] - c[2]};
        for (int k = 0; k < 3; ++k)
          d[3 * i + k] = Q[3 * k] * r[0] + Q[3 * k + 1] * r[1] + Q[3 * k + 2] * r[2] - r[k] + h * drift[k];
      }
      step_expecting_no_contact(sc, s, d, h, large, step);
      if (step == 0) {
        sc.candidate_lists(vt0, ee0);
        ASSERT_GT(vt0.size() + ee0.size(), 0u);
        rebuilds = sc.totals().rebuilds;
        refreshed = sc.totals().refreshed;
      }
    }
    EXPECT_EQ(rebuilds, 1) << "large " << large;
    EXPECT_EQ(sc.totals().rebuilds, rebuilds) << "no rebuild after the first step, large " << large;
    EXPECT_EQ(sc.totals().refreshed, refreshed) << "no refresh after the first step, large " << large;
    EXPECT_EQ(sc.totals().impulses(), 0);
    sc.candidate_lists(vt, ee);
    EXPECT_EQ(vt, vt0);
    EXPECT_EQ(ee, ee0);
    // Not vacuous: after the mean motion is taken off, vertices moved far beyond any reach.
    double mean[3] = {0, 0, 0}, far = 0;
    for (Index i = 0; i < s.size(); ++i)
      for (int k = 0; k < 3; ++k) mean[k] += (s.x[3 * i + k] - start[3 * i + k]) / static_cast<double>(s.size());
    for (Index i = 0; i < s.size(); ++i) {
      double m2 = 0;
      for (int k = 0; k < 3; ++k) m2 += std::pow(s.x[3 * i + k] - start[3 * i + k] - mean[k], 2);
      far = std::max(far, std::sqrt(m2));
    }
    EXPECT_GT(far, 20 * th);
  }
}

TEST(SelfCollisionResponse, AVertexTheFailSafeStopsInAClothFallingAsAWholeIsCheckedAgainstTheLayerAbove) {
  // The lists measure motion in their frame, which follows the cloth's mean motion: in a cloth
  // falling as a whole, a vertex has a reach of half a thickness although it falls 3 thicknesses
  // per step. When the fail-safe stops such a vertex, it moves by the frame's whole step
  // relative to the frame, far beyond its reach: the lists must be renewed for it before the
  // next pass, or the layer above, 2.2 thicknesses up (not in the lists: farther than th + the
  // two reaches), falls through it unchecked. Two 21 x 21 sheets U (above) and L fall together,
  // accelerating by 0.1 thickness per step for 30 steps, onto a small triangle C at rest: in the
  // last step L passes through C. Fail-safe alone, refreshes only (no rebuild resets reaches).
  // Without the renewal, 228 pairs of U's and L's triangles intersect after the last step.
  const double th = 0.0025, h = 0.01;  // edge 0.01
  const Mesh sheet = make_grid(21, 21, 0.2, 0.2, GridPlane::XZ);
  const Index ns = sheet.num_vertices(), ts = sheet.num_triangles();
  Mesh mesh;
  const double lower0 = 48 * th, gap = 2.2 * th;  // L falls 46.5 th in 31 steps, then 3 th onto C (1.5 th below)
  for (int layer = 0; layer < 2; ++layer) {
    for (Index i = 0; i < ns; ++i)
      mesh.positions.insert(mesh.positions.end(), {sheet.positions[3 * i], lower0 + (layer == 0 ? gap : 0.0),
                                                   sheet.positions[3 * i + 2]});
    for (Index k = 0; k < 3 * ts; ++k) mesh.triangles.push_back(sheet.triangles[k] + layer * ns);
  }
  const Index c0 = 2 * ns;  // C: under the middle of L, its corners clear of L's vertices' xz
  double x_lo = 1e300, z_lo = 1e300;
  for (Index i = 0; i < ns; ++i) x_lo = std::min(x_lo, sheet.positions[3 * i]), z_lo = std::min(z_lo, sheet.positions[3 * i + 2]);
  mesh.positions.insert(mesh.positions.end(), {x_lo + 0.0555, 0.0, z_lo + 0.0555, x_lo + 0.1455, 0.0, z_lo + 0.0555,
                                               x_lo + 0.0555, 0.0, z_lo + 0.1455});
  mesh.triangles.insert(mesh.triangles.end(), {c0, c0 + 1, c0 + 2});
  const Index nv = mesh.num_vertices();
  SelfCollision::Options o{th, 0.0};
  o.ccd_iterations = 0;
  o.repulsion = false;
  o.refresh_fraction = 1.0;
  SelfCollision sc(o, mesh);
  State s;
  s.resize(nv);
  for (Index i = 0; i < nv; ++i) s.mass[i] = 1e-4;
  s.update_inverse_masses();
  s.x = mesh.positions;
  ASSERT_EQ(loom::count_intersecting_pairs(mesh, s.x), 0u);
  for (int step = 0; step <= 31; ++step) {
    const double fall = std::min(step, 30) * 0.1 * th;
    if (step == 31) {
      // The layers are apart in the lists: no pair of a U vertex and an L triangle is listed.
      std::vector<std::array<Index, 2>> vt, ee;
      sc.candidate_lists(vt, ee);
      for (const auto& p : vt)
        ASSERT_FALSE(p[0] < ns && p[1] >= ts && p[1] < 2 * ts) << "U vertex " << p[0] << ", L triangle " << p[1];
    }
    sc.begin_step(s);
    for (Index i = 0; i < c0; ++i) s.x[3 * i + 1] -= fall, s.v[3 * i + 1] = -fall / h;
    sc.resolve(s, h);
    if (step < 31) ASSERT_EQ(sc.last_stats().frozen, 0) << "step " << step;
  }
  EXPECT_GT(sc.last_stats().frozen, 0);
  EXPECT_EQ(loom::count_intersecting_pairs(mesh, s.x), 0u);
  // Some of U stopped above the stopped part of L.
  Index u_stopped = 0;
  for (Index i = 0; i < ns; ++i) u_stopped += s.v[3 * i + 1] == 0 ? 1 : 0;
  EXPECT_GT(u_stopped, 0);
}

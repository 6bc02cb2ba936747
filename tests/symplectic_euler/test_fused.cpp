// The fused spring path of symplectic_euler (loom/explicit_springs.hpp: one pass over the
// springs that updates each vertex as soon as its force is complete) against the generic path
// (material forces, then the vertex loop).
#include <gtest/gtest.h>

#include <omp.h>

#include <algorithm>
#include <cmath>
#include <numeric>
#include <random>
#include <vector>

#include "loom/explicit_springs.hpp"
#include "loom/params.hpp"
#include "symplectic_euler.hpp"
#include "test_spring_material.hpp"

using namespace loom;
using loom::testing::make_scene;
using loom::testing::TestSpringMaterial;

// Equal to rounding, with dampers, fixed and moving pins; the same bits on 1 and 2 threads.
TEST(SymplecticEulerFused, MatchesGenericPathAndThreadCounts) {
  const int nx = 52;   // 52 x 52 vertices, ~10k springs: above kParallelMinSprings
  const loom::testing::TestCloth cloth = loom::testing::make_test_cloth(nx, true);
  const std::vector<double>&x = cloth.x, &v = cloth.v, &m = cloth.m;
  const SpringSet& s = cloth.springs;
  ASSERT_GE(s.size(), kParallelMinSprings);
  const Index fixed = nx * (nx - 1), moving = nx * nx - 1;
  std::vector<double> res[3];
  for (int run = 0; run < 3; ++run) {   // 0: generic, 1: fused 1 thread, 2: fused 2 threads
    omp_set_num_threads(run == 2 ? 2 : 1);
    auto scene = make_scene(x, v, m, {fixed, moving}, {0, -9.81, 0}, std::make_unique<TestSpringMaterial>(s, m, run > 0));
    for (int e = 0; e < 3; ++e) scene->state.v[3 * moving + e] = 0.1 * (e + 1);
    symplectic_euler::SymplecticEuler se{Params()};
    se.prepare(*scene, 1e-4);
    EXPECT_EQ(se.fused(), run > 0);
    for (int st = 0; st < 40; ++st) se.step(*scene, 1e-4);
    for (int e = 0; e < 3; ++e) {
      EXPECT_EQ(scene->state.x[3 * fixed + e], x[3 * fixed + e]);   // bit for bit
      EXPECT_EQ(scene->state.v[3 * moving + e], 0.1 * (e + 1));
    }
    res[run] = scene->state.x;
    res[run].insert(res[run].end(), scene->state.v.begin(), scene->state.v.end());
  }
  omp_set_num_threads(2);
  // The test material's force k (l - l0) d / l and the kernel's k (1 - l0/l) d round differently
  // near the rest length (the cancellation in 1 - l0/l costs about 1/strain ulps, strain ~ 1e-4
  // here), so the velocities agree to 1e-9 of their scale, the positions to 1e-12 of theirs.
  const std::size_t m3 = x.size();
  double sx = 0, sv = 0, moved = 0;
  for (std::size_t q = 0; q < m3; ++q) {
    sx = std::max(sx, std::abs(res[0][q]));
    sv = std::max(sv, std::abs(res[0][m3 + q]));
    moved = std::max(moved, std::abs(res[0][q] - x[q]));
  }
  EXPECT_GT(moved, 1e-5);
  for (std::size_t q = 0; q < res[0].size(); ++q) {
    ASSERT_NEAR(res[1][q], res[0][q], q < m3 ? 1e-12 * sx : 1e-9 * sv) << q;
    ASSERT_EQ(res[2][q], res[1][q]) << q;
  }
}

// The blocked sweep (forces of 128 springs by one vectorised loop, then scattered) and the
// one-spring-at-a-time sweep compute the same step up to rounding, damped and undamped, in double
// and float, on 1 and 2 threads.
template <class T>
void blocked_matches_plain(bool damped, double tol) {
  const int nx = 60;
  const Index n = nx * nx;
  std::vector<T> x0, v0, w;
  for (int r = 0; r < nx; ++r)
    for (int c = 0; c < nx; ++c) {
      x0.insert(x0.end(), {T(0.02 * c), T(0.001 * std::sin(0.7 * c + r)), T(0.02 * r)});
      v0.insert(v0.end(), {T(0.01 * std::sin(r + 2.0 * c)), T(0.02 * std::cos(3.0 * r - c)), T(0)});
      w.push_back(r == nx - 1 && (c == 0 || c == nx - 1) ? T(0) : T(1000.0 / (1 + 0.5 * ((r * 7 + c * 3) % 5))));
    }
  SpringSet s;
  for (int r = 0; r < nx; ++r)
    for (int c = 0; c < nx; ++c) {
      const int a = r * nx + c;
      const double cd = damped ? 0.02 : 0.0;
      if (c + 1 < nx) s.add(a, a + 1, 0.02, 2000, cd, SpringClass::Structural);
      if (r + 1 < nx) s.add(a + nx, a, 0.02, 2000, cd, SpringClass::Structural);
      if (c + 1 < nx && r + 1 < nx) s.add(a, a + nx + 1, 0.02 * std::sqrt(2.0), 500, 0.0, SpringClass::Shear);
      if (c + 2 < nx) s.add(a, a + 2, 0.04, 50, 0.0, SpringClass::Bend);
    }
  SpringSweep<double> base;
  base.build(n, s);
  std::vector<T> res[3];
  for (int run = 0; run < 3; ++run) {   // plain 1 thread, blocked 1 thread, blocked 2 threads
    omp_set_num_threads(run == 2 ? 2 : 1);
    SpringSweep<T> sw;
    sw.convert_from(base);
    sw.blocked = run > 0;
    std::vector<T> x = x0, v = v0, f(x.size(), T(0));
    const T g[3] = {T(0), T(-9.81), T(0)};
    for (int st = 0; st < 30; ++st) se_step_springs<T>(sw, x.data(), v.data(), w.data(), f.data(), T(1e-4), g);
    for (T e : f) ASSERT_EQ(e, T(0));   // f is zero again on return
    res[run] = x;
    res[run].insert(res[run].end(), v.begin(), v.end());
  }
  omp_set_num_threads(2);
  const std::size_t m3 = x0.size();
  double sx = 0, sv = 0;
  for (std::size_t q = 0; q < m3; ++q) {
    sx = std::max(sx, std::abs(double(res[0][q])));
    sv = std::max(sv, std::abs(double(res[0][m3 + q])));
  }
  for (std::size_t q = 0; q < res[0].size(); ++q) {
    ASSERT_NEAR(res[1][q], res[0][q], tol * (q < m3 ? sx : sv)) << q;
    ASSERT_EQ(res[2][q], res[1][q]) << q;
  }
}

TEST(SymplecticEulerFused, BlockedSweepMatchesPlainSweep) {
  for (bool damped : {false, true}) {
    blocked_matches_plain<double>(damped, 1e-9);
    blocked_matches_plain<float>(damped, 1e-3);
  }
}

// reorder: the fused step in the RCM order equals the step in the mesh's order to rounding,
// reported in the mesh's numbering (positions, velocities; the fixed pin bit for bit); auto
// reorders a large mesh numbered at random and leaves a row-by-row grid alone.
namespace {
struct Shuffled {
  std::vector<double> x, v, m;
  SpringSet s;
  std::vector<Index> pins;
  Shuffled(int nx, bool shuffle) {
    const int n = nx * nx;
    std::vector<Index> pi(n);
    std::iota(pi.begin(), pi.end(), 0);
    if (shuffle) std::shuffle(pi.begin(), pi.end(), std::mt19937(17));
    x.resize(3 * n);
    v.resize(3 * n);
    m.resize(n);
    for (int r = 0; r < nx; ++r)
      for (int c = 0; c < nx; ++c) {
        const Index u = pi[r * nx + c];
        x[3 * u] = 0.02 * c;
        x[3 * u + 1] = 0.001 * std::sin(0.7 * c + r);
        x[3 * u + 2] = 0.02 * r;
        v[3 * u] = 0.01 * std::sin(r + 2.0 * c);
        v[3 * u + 1] = 0.02 * std::cos(3.0 * r - c);
        m[u] = 1e-3 * (1 + 0.5 * ((r * 7 + c * 3) % 5));
      }
    for (int r = 0; r < nx; ++r)
      for (int c = 0; c < nx; ++c) {
        const int a = r * nx + c;
        if (c + 1 < nx) s.add(pi[a], pi[a + 1], 0.02, 2000, 0.02, SpringClass::Structural);
        if (r + 1 < nx) s.add(pi[a + nx], pi[a], 0.02, 2000, 0.0, SpringClass::Structural);
        if (c + 1 < nx && r + 1 < nx) s.add(pi[a], pi[a + nx + 1], 0.02 * std::sqrt(2.0), 500, 0.0, SpringClass::Shear);
        if (c + 2 < nx) s.add(pi[a], pi[a + 2], 0.04, 50, 0.0, SpringClass::Bend);
      }
    pins = {pi[nx * (nx - 1)], pi[nx * nx - 1]};
  }
};
}  // namespace

TEST(SymplecticEulerReorder, ReorderedRunEqualsUserOrderRun) {
  const Shuffled g(40, true);
  std::vector<double> res[2];
  for (int ro : {0, 1}) {
    auto scene = make_scene(g.x, g.v, g.m, g.pins, {0, -9.81, 0}, std::make_unique<TestSpringMaterial>(g.s, g.m));
    symplectic_euler::SymplecticEuler se{Params::from_string(ro ? "reorder: rcm\n" : "reorder: none\n")};
    se.prepare(*scene, 1e-4);
    EXPECT_TRUE(se.fused());
    EXPECT_EQ(se.reordered(), ro == 1);
    for (int st = 0; st < 60; ++st) se.step(*scene, 1e-4);
    for (int e = 0; e < 3; ++e) EXPECT_EQ(scene->state.x[3 * g.pins[0] + e], g.x[3 * g.pins[0] + e]);
    res[ro] = scene->state.x;
    res[ro].insert(res[ro].end(), scene->state.v.begin(), scene->state.v.end());
  }
  const std::size_t m3 = g.x.size();
  double sx = 0, sv = 0, moved = 0;
  for (std::size_t q = 0; q < m3; ++q) {
    sx = std::max(sx, std::abs(res[0][q]));
    sv = std::max(sv, std::abs(res[0][m3 + q]));
    moved = std::max(moved, std::abs(res[0][q] - g.x[q]));
  }
  EXPECT_GT(moved, 1e-6);
  for (std::size_t q = 0; q < m3; ++q) {
    ASSERT_NEAR(res[1][q], res[0][q], 1e-13 * sx) << "x " << q;
    ASSERT_NEAR(res[1][m3 + q], res[0][m3 + q], 1e-11 * sv) << "v " << q;
  }
}

TEST(SymplecticEulerReorder, AutoRuleAndParameter) {
  for (bool shuffle : {true, false}) {
    const Shuffled g(130, shuffle);   // 16900 vertices >= kReorderMinVertices
    auto scene = make_scene(g.x, g.v, g.m, g.pins, {0, -9.81, 0}, std::make_unique<TestSpringMaterial>(g.s, g.m));
    symplectic_euler::SymplecticEuler se{Params()};
    se.prepare(*scene, 1e-4);
    EXPECT_EQ(se.reordered(), shuffle);
  }
  EXPECT_EQ(symplectic_euler::SymplecticEuler(Params::from_string("reorder: rcm\n")).reorder_mode(), ReorderMode::Rcm);
  EXPECT_EQ(symplectic_euler::SymplecticEuler(Params()).reorder_mode(), ReorderMode::Auto);
  EXPECT_THROW(symplectic_euler::SymplecticEuler(Params::from_string("reorder: metis\n")), InputError);
}

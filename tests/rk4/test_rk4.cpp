// rk4: free fall exact, pins exact (fixed and moving), four force evaluations, order 4
// against the exact isolated spring.
#include <gtest/gtest.h>

#include <omp.h>

#include <algorithm>
#include <cmath>
#include <vector>

#include "exact_spring.hpp"
#include "rk4_integrator.hpp"
#include "test_spring_material.hpp"

using namespace loom;
using loom::testing::exact_axial;
using loom::testing::make_scene;
using loom::testing::TestSpringMaterial;

TEST(Rk4, FreeFallIsExact) {
  const std::vector<double> x{0.1, 2.0, -0.3, 1, 1, 1, -5, 3, 0.25};
  const std::vector<double> v{0.5, 3.0, -1.0, 0, 0, 0, 10, -2, 0.125};
  std::vector<double> m{1.0, 0.3, 2.0};
  auto scene = make_scene(x, v, m, {}, {0.2, -9.81, 0.7}, std::make_unique<TestSpringMaterial>(SpringSet{}, m));
  Rk4Integrator rk;
  const double h = 0.013;
  rk.prepare(*scene, h);
  const int N = 200;
  for (int s = 0; s < N; ++s) rk.step(*scene, h);
  const double t = N * h;
  for (int q = 0; q < 3; ++q)
    for (int e = 0; e < 3; ++e) {
      const double ex = x[3 * q + e] + v[3 * q + e] * t + 0.5 * scene->gravity[e] * t * t;
      EXPECT_NEAR(scene->state.x[3 * q + e], ex, 1e-12 * (1 + std::abs(ex)));
      EXPECT_NEAR(scene->state.v[3 * q + e], v[3 * q + e] + scene->gravity[e] * t, 1e-12 * (1 + std::abs(ex)));
    }
  EXPECT_NEAR(scene->state.time, t, 1e-12);
  EXPECT_EQ(scene->state.step, N);
}

// Four force evaluations per step through the material (a material that is no spring network:
// the generic path), pins exact on both paths (the fused spring path for a spring material).
TEST(Rk4, FourForceEvaluationsPerStepAndPinsExact) {
 for (bool expose : {false, true}) {
  const int nx = 5;
  std::vector<double> x, v, m;
  for (int r = 0; r < nx; ++r)
    for (int c = 0; c < nx; ++c) {
      x.insert(x.end(), {0.1 * c, 0.0, 0.1 * r});
      v.insert(v.end(), {0, 0, 0});
      m.push_back(0.01);
    }
  SpringSet s;
  for (int r = 0; r < nx; ++r)
    for (int c = 0; c < nx; ++c) {
      const int a = r * nx + c;
      if (c + 1 < nx) s.add(a, a + 1, 0.1, 2000, 0.05, SpringClass::Structural);
      if (r + 1 < nx) s.add(a, a + nx, 0.1, 2000, 0.05, SpringClass::Structural);
    }
  auto mat = std::make_unique<TestSpringMaterial>(s, m, expose);
  const TestSpringMaterial* raw = mat.get();
  auto scene = make_scene(x, v, m, {0, nx - 1, nx * nx - 1}, {0, -9.81, 0}, std::move(mat));
  // vertex nx*nx-1 is a moving pin: prescribed velocity
  const double pv[3] = {0.3, -0.2, 0.1};
  for (int e = 0; e < 3; ++e) scene->state.v[3 * (nx * nx - 1) + e] = pv[e];
  Rk4Integrator rk;
  const double h = 1e-4;
  rk.prepare(*scene, h);
  const int N = 100;
  for (int st = 0; st < N; ++st) rk.step(*scene, h);
  EXPECT_EQ(rk.fused(), expose);
  EXPECT_EQ(raw->evaluations, expose ? 0 : 4 * N);
  EXPECT_EQ(rk.last_step().force_evaluations, 4);
  for (Index p : {0, nx - 1})
    for (int e = 0; e < 3; ++e) {
      EXPECT_EQ(scene->state.x[3 * p + e], x[3 * p + e]);   // bit for bit
      EXPECT_EQ(scene->state.v[3 * p + e], 0.0);
    }
  const Index mp = nx * nx - 1;
  for (int e = 0; e < 3; ++e) {
    EXPECT_EQ(scene->state.v[3 * mp + e], pv[e]);
    EXPECT_NEAR(scene->state.x[3 * mp + e], x[3 * mp + e] + N * h * pv[e], 1e-14);
  }
  EXPECT_LT(scene->state.x[3 * (nx * nx - 2) + 1], -1e-5);   // a free vertex fell
 }
}

// Order 4 on an isolated spring (undamped and damped, equal and 1:5 masses).
TEST(Rk4, FourthOrderOnIsolatedSpring) {
  for (double zeta : {0.0, 0.3}) {
    for (double mj : {1.0, 5.0}) {
      const double k = 2000, l0 = 1, d0 = 0.05, mi = 1;
      const double W = 1 / mi + 1 / mj, omega = std::sqrt(k * W), beta = zeta * omega, c = 2 * beta / W;
      const double T = 0.5;
      std::vector<double> err;   // max over 50 common sample times (a single time can hit a node of the error)
      for (int N : {100, 200, 400}) {
        const double h = T / N;
        SpringSet s;
        s.add(0, 1, l0, k, c, SpringClass::Structural);
        std::vector<double> m{mi, mj};
        const double rate0 = 0.4 * omega * d0;
        auto scene = make_scene({0, 0, 0, l0 + d0, 0, 0}, {-(1 / mi) / W * rate0, 0, 0, (1 / mj) / W * rate0, 0, 0},
                                m, {}, {0, 0, 0}, std::make_unique<TestSpringMaterial>(s, m));
        Rk4Integrator rk;
        rk.prepare(*scene, h);
        double e = 0;
        for (int st = 1; st <= N; ++st) {
          rk.step(*scene, h);
          if (st % (N / 50)) continue;
          const auto ex = exact_axial(d0, rate0, (long double)k * W, beta, st * h);
          const double delta = scene->state.x[3] - scene->state.x[0] - l0;
          e = std::max(e, std::abs(delta - static_cast<double>(ex.delta)));
        }
        err.push_back(e);
      }
      for (std::size_t q = 0; q + 1 < err.size(); ++q) {
        const double p = std::log2(err[q] / err[q + 1]);
        EXPECT_GT(p, 3.8) << "zeta " << zeta << " mj " << mj << " errors " << err[q] << " " << err[q + 1];
        EXPECT_LT(p, 4.3) << "zeta " << zeta << " mj " << mj;
      }
    }
  }
}

// The fused spring path (forces and stage updates in one pass, loom/explicit_springs.hpp) equals
// the generic path (material forces, then the stage loops) to rounding, with dampers, fixed and
// moving pins; and it gives the same bits on 1 and 2 threads.
TEST(Rk4, FusedSpringPathMatchesGenericPath) {
  const int nx = 52;   // 52 x 52 vertices, ~10k springs: above kParallelMinSprings
  const loom::testing::TestCloth cloth = loom::testing::make_test_cloth(nx, false);
  const std::vector<double>&x = cloth.x, &v = cloth.v, &m = cloth.m;
  const SpringSet& s = cloth.springs;
  ASSERT_GE(s.size(), kParallelMinSprings);
  std::vector<double> res[3];
  for (int run = 0; run < 3; ++run) {   // 0: generic, 1: fused 1 thread, 2: fused 2 threads
    omp_set_num_threads(run == 2 ? 2 : 1);
    auto scene = make_scene(x, v, m, {nx * (nx - 1), nx * nx - 1}, {0, -9.81, 0},
                            std::make_unique<TestSpringMaterial>(s, m, run > 0));
    for (int e = 0; e < 3; ++e) scene->state.v[3 * (nx * nx - 1) + e] = 0.1 * (e + 1);   // a moving pin
    Rk4Integrator rk;
    rk.prepare(*scene, 1e-4);
    EXPECT_EQ(rk.fused(), run > 0);
    for (int st = 0; st < 40; ++st) rk.step(*scene, 1e-4);
    res[run] = scene->state.x;
    res[run].insert(res[run].end(), scene->state.v.begin(), scene->state.v.end());
  }
  omp_set_num_threads(2);
  double scale = 0, moved = 0;
  for (std::size_t q = 0; q < res[0].size(); ++q) scale = std::max(scale, std::abs(res[0][q]));
  for (std::size_t q = 0; q < x.size(); ++q) moved = std::max(moved, std::abs(res[0][q] - x[q]));
  EXPECT_GT(moved, 1e-5);
  for (std::size_t q = 0; q < res[0].size(); ++q) {
    ASSERT_NEAR(res[1][q], res[0][q], 1e-12 * scale) << q;
    ASSERT_EQ(res[2][q], res[1][q]) << q;
  }
}

// The key merge_springs (default true): doubled springs (each duplicate with its own constants,
// endpoints swapped) are merged for the fused path, and 40 steps equal merge_springs: false to
// rounding.
TEST(Rk4, MergeSpringsKeyAgreesWithEverySpring) {
  const int nx = 52;
  const loom::testing::TestCloth cloth = loom::testing::make_test_cloth(nx, true);
  SpringSet s = cloth.springs;
  const Index base = s.size();
  Index dups = 0;
  for (Index q = 0; q < base; q += 2) {
    s.add(s.j[q], s.i[q], s.rest_length[q] * 0.99, 0.3 * s.stiffness[q], 0.01, s.kind[q]);
    ++dups;
  }
  std::vector<double> res[2];
  for (int merge : {0, 1}) {
    auto scene = make_scene(cloth.x, cloth.v, cloth.m, {nx * (nx - 1), nx * nx - 1}, {0, -9.81, 0},
                            std::make_unique<TestSpringMaterial>(s, cloth.m, true));
    Rk4Integrator rk{merge ? Params() : Params::from_string("merge_springs: false\n")};
    rk.prepare(*scene, 1e-4);
    ASSERT_TRUE(rk.fused());
    EXPECT_EQ(rk.merged_springs(), merge ? dups : 0);
    for (int st = 0; st < 40; ++st) rk.step(*scene, 1e-4);
    res[merge] = scene->state.x;
    res[merge].insert(res[merge].end(), scene->state.v.begin(), scene->state.v.end());
  }
  double scale = 0, moved = 0;
  for (std::size_t q = 0; q < res[0].size(); ++q) scale = std::max(scale, std::abs(res[0][q]));
  for (std::size_t q = 0; q < cloth.x.size(); ++q) moved = std::max(moved, std::abs(res[0][q] - cloth.x[q]));
  EXPECT_GT(moved, 1e-5);
  for (std::size_t q = 0; q < res[0].size(); ++q) ASSERT_NEAR(res[1][q], res[0][q], 1e-12 * scale) << q;
  EXPECT_THROW(Rk4Integrator(Params::from_string("merge_springs: 3\n")), InputError);
}

// The shipped scenes that use mass_spring + symplectic_euler: they load through the real
// plugin modules, their dt satisfies the linear stability bound sqrt(lambda_max) dt < 2, and
// a short run stays bounded.
#include <gtest/gtest.h>

#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <memory>
#include <string>
#include <vector>

#include "loom/bsr.hpp"
#include "loom/registry.hpp"
#include "loom/simulation.hpp"

#include <omp.h>

using namespace loom;

namespace {

struct Bounds {
  double power = 0;      // power-iteration estimate (a lower bound)
  double gershgorin = 0; // an upper bound
};

// lambda_max of W^1/2 K W^1/2 (W = inverse masses, 0 for pins; K = -df/dx at the current x).
Bounds lambda_bounds(Scene& sc, int iterations) {
  Material& m = *sc.material;
  std::vector<std::array<Index, 2>> pairs;
  m.jacobian_pairs(pairs);
  BsrPattern pat = BsrPattern::from_pairs(sc.state.size(), pairs);
  m.bind_pattern(pat);
  BsrMatrix J(&pat);
  m.compute_jacobians(sc.state.x, sc.state.v, J, nullptr);
  const Index n = sc.state.size();
  std::vector<double> sw(3 * n);
  for (Index i = 0; i < n; ++i)
    for (int c = 0; c < 3; ++c) sw[3 * i + c] = std::sqrt(sc.state.inv_mass[i]);
  Bounds b;
  for (Index i = 0; i < n; ++i)
    for (int r = 0; r < 3; ++r) {
      double s = 0;
      for (Index k = pat.row_ptr[i]; k < pat.row_ptr[i + 1]; ++k)
        for (int c = 0; c < 3; ++c) s += std::abs(J.block(k)[3 * r + c]) * sw[3 * pat.col[k] + c];
      b.gershgorin = std::max(b.gershgorin, sw[3 * i + r] * s);
    }
  // Power iteration on A = S K S, S = W^1/2: u <- A u / |A u|, Rayleigh quotient u . A u.
  std::vector<double> u(3 * n), t(3 * n), y(3 * n);
  for (Index q = 0; q < 3 * n; ++q) u[q] = 1.0 + 0.37 * std::sin(1.3 * q) + ((q / 3 + q) % 2 ? 1 : -1);
  for (int it = 0; it < iterations; ++it) {
    double nu = 0;
    for (double v : u) nu += v * v;
    nu = std::sqrt(nu);
    for (Index q = 0; q < 3 * n; ++q) t[q] = sw[q] * u[q] / nu;
    J.multiply(t, y);
    double ray = 0;
    for (Index q = 0; q < 3 * n; ++q) {
      y[q] = -sw[q] * y[q];
      ray += u[q] / nu * y[q];
    }
    b.power = ray;
    u.swap(y);
  }
  return b;
}

struct SceneCase {
  const char* file;
  int steps;
};

}  // namespace

TEST(Scenes, DtIsLinearlyStableAndShortRunIsBounded) {
  Registry reg;
  PluginLoader loader(reg, {std::string(LOOM_BINARY_DIR) + "/lib/loom/plugins"});
  const int saved_threads = omp_get_max_threads();
  for (const SceneCase& sc_case : {SceneCase{"hanging_cloth.yaml", 10020}, SceneCase{"kang_cho_fig7_se_k2000.yaml", 20},
                                   SceneCase{"kang_cho_fig7_se_k1e6.yaml", 20}}) {
    const std::string path = std::string(LOOM_SOURCE_DIR) + "/scenes/" + sc_case.file;
    // One thread: on a shared, oversubscribed machine every parallel region's barrier can
    // cost milliseconds, and these runs are about stability, not speed.
    Simulation sim(path, {"threads=1"}, loader);
    sim.output().dir.clear();  // no files
    EXPECT_EQ(sim.material_name(), "mass_spring");
    EXPECT_EQ(sim.integrator_name(), "symplectic_euler");
    const Bounds b = lambda_bounds(sim.scene(), 100);
    const double dt = sim.dt();
    std::printf("[ scene    ] %s: lambda_max in [%.4g, %.4g], dt %.3g, sqrt(lambda) dt in [%.3f, %.3f]\n", sc_case.file,
                b.power, b.gershgorin, dt, std::sqrt(b.power) * dt, std::sqrt(b.gershgorin) * dt);
    EXPECT_LE(b.power, b.gershgorin * (1 + 1e-12));
    EXPECT_LT(std::sqrt(b.gershgorin) * dt, 2.0) << sc_case.file;
    const auto t0 = std::chrono::steady_clock::now();
    for (int k = 0; k < sc_case.steps; ++k) sim.step();  // throws DivergenceError if it blows up (hanging_cloth: all 60 frames)
    std::printf("[ scene    ] %s: %d steps, %.3f ms/step\n", sc_case.file, sc_case.steps,
                1e3 * std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count() / sc_case.steps);
    const auto st = sim.measure(0);
    EXPECT_TRUE(std::isfinite(st.kinetic));
    EXPECT_LT(st.max_strain, 0.5) << sc_case.file;
  }
  omp_set_num_threads(saved_threads);
}

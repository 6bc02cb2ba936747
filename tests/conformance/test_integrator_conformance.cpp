// Every integrator plugin of the build, on a cloth whose internal forces vanish (a mass-spring
// grid moving rigidly), must
//  * follow free fall: x(T) = x0 + v0 T + g T^2 / 2, v(T) = v0 + g T (the exact solution).
//    A method of order >= 2 reproduces this quadratic to rounding; a first-order method's error
//    is O(h) and halves when h halves. The order each shipped method has is in kOrder (from
//    docs/NUMERICS.md); an integrator not listed there is held to "exact, or first order at
//    least", and the test prints a line asking to list it;
//  * keep a pinned vertex exactly where it was, at zero velocity, under gravity and the pull of
//    the cloth.
// The integrators come from the loader (conformance.hpp): a new one is covered without an edit.
#include <gtest/gtest.h>

#include <cmath>
#include <map>

#include "conformance.hpp"
#include "loom/simulation.hpp"

namespace {

namespace lc = loom::conformance;
using loom::Index;

// Order of accuracy of the shipped methods (docs/NUMERICS.md sec. 1.5: observed orders 1 for
// symplectic Euler, HO and Baraff-Witkin's backward Euler, 4 for RK4).
const std::map<std::string, int> kOrder = {
    {"symplectic_euler", 1}, {"harmonic_oscillation", 1}, {"baraff_witkin", 1}, {"rk4", 4}};

struct IntegratorConformance : testing::TestWithParam<std::string> {
  std::string solver_section;

  void SetUp() override {
    const std::string& name = GetParam();
    auto& l = lc::plugins();
    if (!l.reg.has(loom::PluginKind::Integrator, name))
      GTEST_SKIP() << "integrator plugin '" << name << "' is not built here (no loom_integrator_" << name
                   << ".so in " << LOOM_PLUGIN_DIR << ")";
    if (!l.reg.has(loom::PluginKind::Material, "mass_spring"))
      GTEST_SKIP() << "the integrator conformance cloth needs the mass_spring material, not built here";
    const auto integ = l.reg.make_integrator(name, "cpu", loom::Params::from_string("{}"));
    if (integ->needs().linear_solver) {
      if (!l.reg.has(loom::PluginKind::Solver, "eigen_ldlt"))
        GTEST_SKIP() << name << " needs a linear solver; eigen_ldlt is not built here";
      solver_section = "solver: {type: eigen_ldlt}\n";
    }
  }

  std::unique_ptr<loom::Simulation> make(const std::string& extra, double dt, int substeps) const {
    char integ[160];
    std::snprintf(integ, sizeof(integ), "integrator: {type: %s, dt: %.17g, substeps: %d}\n", GetParam().c_str(), dt,
                  substeps);
    const std::string yaml = "mesh: {grid: {nx: 4, ny: 4, width: 0.3, height: 0.3, plane: xy}}\n"
                             "material: {type: mass_spring, stiffness: 5, density: 1.0}\n"
                             "gravity: [0, -9.81, 0]\n" +
                             std::string(integ) + solver_section + extra;
    auto sim = loom::Simulation::from_string(yaml, "conformance.yaml", LOOM_SOURCE_DIR, {}, *lc::plugins().loader);
    return sim;
  }
};

TEST_P(IntegratorConformance, FreeFallFollowsTheExactParabola) {
  const double v0[3] = {0.4, 2.0, -0.3}, g[3] = {0, -9.81, 0};
  const double T = 0.2;
  // Largest error over vertices and components, of x and of v, after T with step T/steps.
  auto error = [&](int steps, double& ex, double& ev) {
    auto sim = make("initial_velocity: [0.4, 2.0, -0.3]\n", T / steps, steps);
    const auto x0 = sim->scene().state.x;
    sim->advance_frame();
    const auto& st = sim->scene().state;
    EXPECT_NEAR(st.time, T, 1e-14);
    ex = ev = 0;
    for (Index i = 0; i < st.size(); ++i)
      for (int e = 0; e < 3; ++e) {
        ex = std::max(ex, std::abs(st.x[3 * i + e] - (x0[3 * i + e] + v0[e] * T + 0.5 * g[e] * T * T)));
        ev = std::max(ev, std::abs(st.v[3 * i + e] - (v0[e] + g[e] * T)));
      }
  };
  double ex1, ev1, ex2, ev2;
  error(40, ex1, ev1);
  error(80, ex2, ev2);
  std::printf("%s: free fall errors at h = %.3g: x %.3e v %.3e; at h/2: x %.3e v %.3e\n", GetParam().c_str(),
              T / 40, ex1, ev1, ex2, ev2);
  // Rounding over 80 steps of quantities of size ~1: well below 1e-12.
  const double exact = 1e-12;
  const auto it = kOrder.find(GetParam());
  if (it == kOrder.end()) {
    std::printf("note: %s is not in kOrder (tests/conformance/test_integrator_conformance.cpp); held to "
                "'exact or at least first order'\n", GetParam().c_str());
    EXPECT_TRUE(ex2 <= exact || ex1 / ex2 > 1.9) << ex1 << " " << ex2;
    return;
  }
  if (it->second >= 2) {
    // g is constant: x is a quadratic in t, which every method of order >= 2 integrates exactly.
    EXPECT_LE(ex1, exact);
    EXPECT_LE(ev1, exact);
    EXPECT_LE(ex2, exact);
  } else {
    // First order: the velocity is exact (g constant) and the position error is g h T / 2 for
    // any one-step method that updates x with one velocity per step; it halves with h.
    EXPECT_LE(ev1, exact);
    EXPECT_NEAR(ex1 / ex2, 2.0, 0.02);
    EXPECT_NEAR(ex1, 0.5 * 9.81 * (T / 40) * T, 1e-3 * ex1);
  }
}

TEST_P(IntegratorConformance, APinnedVertexStaysPut) {
  auto sim = make("pins: [{vertices: [0, 3]}]\ninitial_velocity: [0, 0, 1.0]\n", 1e-3, 10);
  const auto x0 = sim->scene().state.x;
  for (int f = 0; f < 5; ++f) sim->advance_frame();
  const auto& st = sim->scene().state;
  ASSERT_EQ(st.pin_list.size(), 2u);
  bool moved = false;
  for (Index i = 0; i < st.size(); ++i)
    for (int e = 0; e < 3; ++e) {
      if (st.pinned[i]) {
        EXPECT_EQ(st.x[3 * i + e], x0[3 * i + e]) << "pinned vertex " << i;
        EXPECT_EQ(st.v[3 * i + e], 0.0) << "pinned vertex " << i;
      } else if (st.x[3 * i + e] != x0[3 * i + e]) {
        moved = true;
      }
    }
  EXPECT_TRUE(moved) << "the free vertices did not move: the test would see nothing";
}

INSTANTIATE_TEST_SUITE_P(EveryIntegrator, IntegratorConformance,
                         testing::ValuesIn(lc::plugin_names(loom::PluginKind::Integrator)),
                         [](const testing::TestParamInfo<std::string>& i) { return i.param; });

}  // namespace

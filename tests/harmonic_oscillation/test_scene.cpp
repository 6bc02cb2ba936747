// The shipped HO scene loads through the real plugin modules (dlopen) and a short run stays
// bounded; the variants and rk4 load through --set overrides.
#include <gtest/gtest.h>

#include <cmath>
#include <string>
#include <vector>

#include "loom/registry.hpp"
#include "loom/simulation.hpp"

using namespace loom;

TEST(HoScene, Fig7SceneLoadsThroughModulesAndStaysBounded) {
  Registry reg;
  PluginLoader loader(reg, {std::string(LOOM_BINARY_DIR) + "/lib/loom/plugins"});
  const std::string path = std::string(LOOM_SOURCE_DIR) + "/scenes/kang_cho_fig7_ho_k2000.yaml";
  for (const char* variant : {"velocity", "analytic_position", "kang_cho_2011"}) {
    // 32 x 32 instead of 128 x 128 (heavier vertices: the scene's dt stays stable) for speed
    Simulation sim(path,
                   {"threads=1", "mesh.grid.nx=32", "mesh.grid.ny=32", std::string("integrator.variant=") + variant},
                   loader);
    EXPECT_EQ(sim.integrator_name(), "harmonic_oscillation");
    for (int s = 0; s < 400; ++s) sim.step();
    const auto st = sim.measure(0);
    EXPECT_TRUE(std::isfinite(st.kinetic)) << variant;
    EXPECT_LT(st.max_strain, 0.2) << variant;
    EXPECT_GT(st.kinetic, 0.0) << variant;
  }
  Simulation rk(std::string(LOOM_SOURCE_DIR) + "/scenes/hanging_10x10_k2000.yaml",
                {"threads=1", "integrator.type=rk4", "integrator.dt=5e-4"}, loader);
  EXPECT_EQ(rk.integrator_name(), "rk4");
  for (int s = 0; s < 100; ++s) rk.step();
  EXPECT_TRUE(std::isfinite(rk.measure(0).kinetic));
  // an unknown variant is refused with the file position
  EXPECT_THROW(Simulation(path, {"integrator.variant=fast"}, loader), InputError);
}

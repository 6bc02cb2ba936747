// The shipped HO scene loads through the real plugin modules (dlopen) and a short run stays
// bounded; the variants and rk4 load through --set overrides.
#include <gtest/gtest.h>

#include <unistd.h>

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <filesystem>
#include <fstream>
#include <sstream>
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

// reorder: rcm through the real module and the scene file: the OBJ frames a run writes are in
// the mesh's numbering and equal the frames of the run in the mesh's order to rounding.
TEST(HoScene, ReorderedRunWritesTheSameFrames) {
  Registry reg;
  PluginLoader loader(reg, {std::string(LOOM_BINARY_DIR) + "/lib/loom/plugins"});
  const std::string path = std::string(LOOM_SOURCE_DIR) + "/scenes/kang_cho_fig7_ho_k2000.yaml";
  const std::filesystem::path base =
      std::filesystem::temp_directory_path() / ("loom_ho_reorder_" + std::to_string(::getpid()));
  std::vector<std::vector<double>> frames[2];
  for (int ro : {0, 1}) {
    const std::string dir = (base / (ro ? "rcm" : "none")).string();
    std::filesystem::remove_all(dir);
    Simulation sim(path,
                   {"threads=1", "mesh.grid.nx=32", "mesh.grid.ny=32", "integrator.substeps=200", "frames=2",
                    std::string("integrator.reorder=") + (ro ? "rcm" : "none"), "output.dir=" + dir, "output.stats=false", "output.lossless=true"},
                   loader);
    sim.run();
    for (int f = 0; f <= 2; ++f) {
      char name[32];
      std::snprintf(name, sizeof name, "frame_%05d.obj", f);
      std::ifstream in(std::filesystem::path(dir) / name);
      ASSERT_TRUE(in) << dir << "/" << name;
      std::vector<double> xs;
      std::string line;
      while (std::getline(in, line))
        if (line.rfind("v ", 0) == 0) {
          std::istringstream ss(line.substr(2));
          double a, b, c;
          ss >> a >> b >> c;
          xs.insert(xs.end(), {a, b, c});
        }
      frames[ro].push_back(xs);
    }
  }
  std::filesystem::remove_all(base);
  ASSERT_EQ(frames[0].size(), frames[1].size());
  double moved = 0;
  for (std::size_t f = 0; f < frames[0].size(); ++f) {
    ASSERT_EQ(frames[0][f].size(), 3u * 32 * 32);
    ASSERT_EQ(frames[0][f].size(), frames[1][f].size());
    for (std::size_t q = 0; q < frames[0][f].size(); ++q) {
      EXPECT_NEAR(frames[1][f][q], frames[0][f][q], 1e-13) << "frame " << f << " entry " << q;
      moved = std::max(moved, std::abs(frames[0][f][q] - frames[0][0][q]));
    }
  }
  EXPECT_GT(moved, 1e-4);   // the cloth fell: the frames differ from the first
}

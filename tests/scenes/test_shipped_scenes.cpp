// Every scene in scenes/ builds through the real plugin modules (as `loom validate` does) and,
// up to 20,000 vertices, takes a few steps without diverging. Scenes that name a solver list
// use the first one this build has.
#include <gtest/gtest.h>

#include <cmath>
#include <filesystem>

#include "loom/simulation.hpp"

namespace fs = std::filesystem;

TEST(ShippedScenes, EverySceneBuildsAndSteps) {
  loom::Registry registry;
  loom::PluginLoader loader(registry);
  loom::Simulation::set_notes(false);
  int count = 0;
  for (const auto& e : fs::directory_iterator(fs::path(LOOM_SOURCE_DIR) / "scenes")) {
    if (e.path().extension() != ".yaml") continue;
    SCOPED_TRACE(e.path().filename().string());
    std::unique_ptr<loom::Simulation> sim;
    ASSERT_NO_THROW(sim = std::make_unique<loom::Simulation>(e.path().string(), std::vector<std::string>{}, loader));
    ++count;
    if (sim->scene().state.size() > 20000) continue;
    for (int k = 0; k < 5; ++k) ASSERT_NO_THROW(sim->step());
    for (double c : sim->scene().state.x) ASSERT_TRUE(std::isfinite(c));
  }
  EXPECT_GE(count, 10);
}

// Scenes with `material: {..., bending: {...}}` through the plugin loader: a cloth clamped along
// one edge (two pinned columns) sags less with more bending rigidity, under baraff_witkin at h = 1/60 s with both
// Jacobians (Gauss-Newton and exact); key errors inside the block; combos that would ignore
// the hinges are refused.
#include <gtest/gtest.h>

#include <cmath>
#include <string>

#include "loom/registry.hpp"
#include "loom/simulation.hpp"

namespace {

std::string scene(const std::string& material, const std::string& integrator = "baraff_witkin") {
  return "mesh:\n  grid: {nx: 9, ny: 9, width: 0.3, height: 0.3, plane: xz}\n"
         "material:\n" + material +
         "integrator: {type: " + integrator + ", dt: 0.0166666666666667, substeps: 6}\n"
         "solver: {type: eigen_ldlt}\n"
         "pins: [left_edge, {vertices: [1, 10, 19, 28, 37, 46, 55, 64, 73]}]\n"  // two columns: clamped

         "gravity: [0, -9.81, 0]\n"
         "threads: 1\n"
         "frames: 5\n";
}

std::string wool(const std::string& bending) {
  return "  type: gnatv\n  material_file: " + std::string(LOOM_SOURCE_DIR) + "/materials/wool.yaml\n" + bending;
}

// Mean drop of the free edge (the column farthest from the pinned edge) after `frames` frames.
double sag(const std::string& yaml, int frames, loom::PluginLoader& loader) {
  auto sim = loom::Simulation::from_string(yaml, "bending_scene.yaml", ".", {}, loader);
  for (int f = 0; f < frames; ++f) sim->advance_frame();
  const auto& st = sim->scene().state;
  const auto& mesh = sim->scene().mesh;
  double drop = 0;
  int n = 0;
  for (loom::Index i = 0; i < mesh.num_vertices(); ++i)
    if (mesh.positions[3 * i] > 0.29) {
      EXPECT_TRUE(std::isfinite(st.x[3 * i + 1]));
      drop += -st.x[3 * i + 1];
      ++n;
    }
  return drop / n;
}

std::string error_of(const std::string& yaml, loom::PluginLoader& loader) {
  try {
    loom::Simulation::from_string(yaml, "bending_scene.yaml", ".", {}, loader);
  } catch (const loom::InputError& e) {
    return e.what();
  }
  return "";
}

}  // namespace

TEST(BendingScenes, StifferBendingSagsLessUnderBaraffWitkinWithBothJacobians) {
  loom::Registry reg;
  loom::PluginLoader loader(reg);
  const int frames = 20;  // 2 s at h = 1/60
  const double none = sag(scene(wool("")), frames, loader);
  const double weak = sag(scene(wool("  bending: {stiffness: 3.0e-3}\n")), frames, loader);
  const double stiff = sag(scene(wool("  bending: {stiffness: 3.0e-2}\n")), frames, loader);
  const double stiff_exact = sag(scene(wool("  bending: {stiffness: 3.0e-2, jacobian: exact}\n")), frames, loader);
  std::printf("free-edge sag after %d frames: no bending %.5f m, B = 3e-3: %.5f m, B = 3e-2: %.5f m (exact Jacobian "
              "%.5f m)\n", frames, none, weak, stiff, stiff_exact);
  EXPECT_GT(none, weak);
  EXPECT_GT(weak, stiff);
  EXPECT_GT(stiff, 0);
  // Both Jacobians step the same equations; settled, they agree.
  EXPECT_NEAR(stiff_exact, stiff, 0.02 * stiff);
}

TEST(BendingScenes, KeyErrorsAndCombosThatWouldIgnoreTheHinges) {
  loom::Registry reg;
  loom::PluginLoader loader(reg);
  std::string e = error_of(scene(wool("  bending: {stiffness: 1.0e-5, jacobain: exact}\n")), loader);
  EXPECT_NE(e.find("bending_scene.yaml"), std::string::npos) << e;
  EXPECT_NE(e.find("jacobian"), std::string::npos) << e;
  e = error_of(scene(wool("  bending: {stiffness: -1.0}\n")), loader);
  EXPECT_NE(e.find(">= 0"), std::string::npos) << e;
  // A per-spring integrator would skip the hinges: refused (the wrapped material has no springs).
  e = error_of(scene("  type: mass_spring\n  bending: {stiffness: 1.0e-5}\n", "harmonic_oscillation"), loader);
  EXPECT_NE(e.find("no springs"), std::string::npos) << e;
  // Any membrane: mass_spring on the mesh edges with bending runs.
  auto sim = loom::Simulation::from_string(scene("  type: mass_spring\n  stencil: mesh_edges\n  bending: {stiffness: 1.0e-4}\n"),
                                           "bending_scene.yaml", ".", {}, loader);
  sim->advance_frame();
  bool found = false;
  for (const auto& line : sim->describe()) found = found || line.find("bending hinges") != std::string::npos;
  EXPECT_TRUE(found);
}

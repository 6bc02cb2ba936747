// End to end: a short hanging-cloth run (mass_spring + baraff_witkin) through the plugin
// loader gives the same trajectory on every solver backend, within the solver tolerance.
#include <gtest/gtest.h>

#include <cmath>
#include <memory>
#include <chrono>
#include <cstdio>
#include <string>

#include "loom/registry.hpp"
#include "loom/simulation.hpp"

using namespace loom;

namespace {

const char* kScene = R"(
mesh:
  grid: {nx: 12, ny: 12, width: 1.0, height: 1.0, plane: xy}
material:
  type: mass_spring
  stiffness: {structural: 200, shear: 200, bend: 10}
  density: 0.1
integrator:
  type: baraff_witkin
  dt: 0.01
  substeps: 3
solver:
  type: [eigen_ldlt]
backend: cpu
threads: 2
pins: [top_corners]
gravity: [0, -9.81, 0]
frames: 6
)";

/// Positions after each frame.
std::vector<std::vector<double>> run(const std::string& solver, const std::vector<std::string>& extra = {}) {
  Registry registry;
  PluginLoader loader(registry);
  std::vector<std::string> overrides{"solver.type=" + solver};
  overrides.insert(overrides.end(), extra.begin(), extra.end());
  const auto t0 = std::chrono::steady_clock::now();
  auto sim = Simulation::from_string(kScene, "<trajectory test>", ".", overrides, loader);
  EXPECT_EQ(sim->solver_name(), solver);
  std::vector<std::vector<double>> frames{sim->scene().state.x};
  for (int f = 0; f < sim->frames(); ++f) {
    sim->advance_frame();
    frames.push_back(sim->scene().state.x);
  }
  std::printf("%-10s %zu frames in %.3f s\n", solver.c_str(), frames.size() - 1,
              std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count());
  return frames;
}

double max_diff(const std::vector<std::vector<double>>& a, const std::vector<std::vector<double>>& b) {
  double m = 0;
  for (std::size_t f = 0; f < a.size(); ++f)
    for (std::size_t i = 0; i < a[f].size(); ++i) m = std::max(m, std::abs(a[f][i] - b[f][i]));
  std::printf("  max |x - x_eigen_ldlt| over the run: %.3e m\n", m);
  return m;
}

}  // namespace

TEST(Trajectories, EveryBackendFollowsTheEigenLdltTrajectory) {
  const auto ref = run("eigen_ldlt");
  // The cloth moved (the comparison is not between two resting states).
  double moved = 0;
  for (std::size_t i = 0; i < ref.back().size(); ++i) moved = std::max(moved, std::abs(ref.back()[i] - ref.front()[i]));
  EXPECT_GT(moved, 1e-3);

  const auto chol = run("cholmod");
  EXPECT_LT(max_diff(chol, ref), 1e-10);
  const auto chol_reuse =
      run("cholmod", {"solver.cholmod.reuse_factorization_steps=4", "solver.cholmod.tolerance=1.0e-12"});
  EXPECT_LT(max_diff(chol_reuse, ref), 1e-9);
  const auto pets = run("petsc", {"solver.petsc.pc=gamg", "solver.petsc.tolerance=1.0e-12"});
  EXPECT_LT(max_diff(pets, ref), 1e-9);
  const auto pets_bj = run("petsc", {"solver.petsc.pc=bjacobi", "solver.petsc.tolerance=1.0e-12"});
  EXPECT_LT(max_diff(pets_bj, ref), 1e-9);
  // A loose tolerance gives a visibly different trajectory: the comparison can fail.
  const auto loose = run("petsc", {"solver.petsc.tolerance=1.0e-2", "solver.petsc.pc=jacobi"});
  EXPECT_GT(max_diff(loose, ref), 1e-9);
}

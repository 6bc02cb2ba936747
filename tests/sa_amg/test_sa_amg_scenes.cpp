// eigen_pcg with preconditioner: sa_amg in a whole Baraff-Witkin scene, through the plugin
// loader: a cloth pinned at two corners draped over a ball (pins and contact constraints that
// appear and go from step to step, so S changes and the hierarchy refreshes) follows the
// same trajectory as the projected direct solve (eigen_ldlt).
#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>

#include "loom/simulation.hpp"

namespace {

struct AmgScenes : ::testing::Test {
  loom::Registry registry;
  loom::PluginLoader loader{registry};
  std::unique_ptr<loom::Simulation> make(const std::string& yaml) {
    return loom::Simulation::from_string(yaml, "sa_amg_scene.yaml", ".", {}, loader);
  }
};

}  // namespace

TEST_F(AmgScenes, DrapeOverBallMatchesDirectSolveWithPinsAndContacts) {
  const std::string base = R"(
mesh: {grid: {nx: 12, ny: 12, width: 1.0, height: 1.0, plane: xz}}
material: {type: mass_spring, stencil: structural_shear_bend, stiffness: 2000, density: 0.1}
integrator: {type: baraff_witkin, dt: 0.005}
threads: 1
pins: [top_corners]
colliders: [{type: sphere, center: [0.5, -0.3, -0.5], radius: 0.32, friction: 0.3}]
)";
  auto a = make(base +
                "solver: {type: eigen_pcg, eigen_pcg: {preconditioner: sa_amg, tolerance: 1.0e-12, "
                "max_iterations: 1000, sa_amg: {coarse_dofs: 24}}}\n");
  auto b = make(base + "solver: {type: eigen_ldlt}\n");
  // Drape with the direct solver, then continue from the same state with both.
  for (int k = 0; k < 40; ++k) b->step();
  a->scene().state = b->scene().state;
  // The integrator's restart state too: the friction dampers of a step start from the
  // responses the contacts showed in the step before (docs/CONTACT.md, "Corrections that stop").
  ASSERT_TRUE(a->integrator().set_restart_state(b->integrator().restart_state()));
  const long long it0 = a->linear_iterations();
  for (int k = 0; k < 10; ++k) {
    a->step();
    b->step();
  }
  const long long iterations = a->linear_iterations() - it0;
  double diff = 0, scale = 0;
  for (std::size_t i = 0; i < a->scene().state.v.size(); ++i) {
    diff = std::max(diff, std::abs(a->scene().state.v[i] - b->scene().state.v[i]));
    scale = std::max(scale, std::abs(b->scene().state.v[i]));
  }
  EXPECT_LT(diff, 1e-7 * scale) << "max |v_amg - v_ldlt| = " << diff << " of " << scale;
  EXPECT_GT(iterations, 10);
  // the ball holds the cloth, and the pins stay put
  const auto& st = a->scene().state;
  int touching = 0;
  for (loom::Index i = 0; i < st.size(); ++i) {
    const double dx = st.x[3 * i] - 0.5, dy = st.x[3 * i + 1] + 0.3, dz = st.x[3 * i + 2] + 0.5;
    const double r = std::sqrt(dx * dx + dy * dy + dz * dz);
    EXPECT_GE(r, 0.32 - 1e-9);
    if (r < 0.32 + 1e-3) ++touching;
  }
  EXPECT_GT(touching, 0) << "the scene must have contacts";
  for (loom::Index i : st.pin_list) EXPECT_EQ(st.v[3 * i + 1], 0.0);
}

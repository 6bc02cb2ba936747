// Colliders in whole scenes: every integrator keeps the cloth out of the ground and the ball,
// Baraff-Witkin's contact constraints agree between the filtered PCG and the projected direct
// solve, release when the cloth is lifted, and carry friction.
#include <gtest/gtest.h>

#include <cmath>

#include "loom/simulation.hpp"

namespace {

struct ContactScenes : ::testing::Test {
  loom::Registry registry;
  loom::PluginLoader loader{registry};
  std::unique_ptr<loom::Simulation> make(const std::string& yaml) {
    return loom::Simulation::from_string(yaml, "contact.yaml", ".", {}, loader);
  }
};

// A 10 x 10 cloth, 0.5 m, lying flat 5 cm above the ground plane y = 0, no pins.
std::string falling_cloth(const std::string& integrator, const std::string& collider_extra = "") {
  return R"(
mesh: {grid: {nx: 10, ny: 10, width: 0.5, height: 0.5, plane: xz}}
material: {type: mass_spring, stencil: structural_shear_bend, stiffness: 500, damping: 0.01, density: 0.2}
integrator: )" + integrator + R"(
solver: {type: eigen_ldlt}
threads: 1
initial_velocity: [0, 0, 0]
colliders:
  - {type: plane, point: [0, -0.05, 0], normal: [0, 1, 0], thickness: 0.002)" + collider_extra + R"(}
)";
}

double min_y(const loom::Simulation& sim) {
  double m = 1e300;
  for (loom::Index i = 0; i < sim.scene().state.size(); ++i) m = std::min(m, sim.scene().state.x[3 * i + 1]);
  return m;
}

double max_speed(const loom::Simulation& sim) {
  double m = 0;
  const auto& v = sim.scene().state.v;
  for (std::size_t i = 0; i < v.size(); i += 3) m = std::max(m, std::sqrt(v[i] * v[i] + v[i + 1] * v[i + 1] + v[i + 2] * v[i + 2]));
  return m;
}

}  // namespace

TEST_F(ContactScenes, ClothFallingOnTheGroundComesToRestOnItWithEveryIntegrator) {
  for (const std::string integ : {"{type: symplectic_euler, dt: 2.0e-4, substeps: 50}",
                                  "{type: harmonic_oscillation, dt: 2.0e-4, substeps: 50}",
                                  "{type: rk4, dt: 2.0e-4, substeps: 50}", "{type: baraff_witkin, dt: 2.0e-3, substeps: 5}"}) {
    auto sim = make(falling_cloth(integ, ", friction: 0.5"));
    for (int f = 0; f < 60; ++f) {
      sim->advance_frame();
      EXPECT_GE(min_y(*sim), -0.05 + 0.002 - 1e-9) << integ << " frame " << f;
    }
    EXPECT_LT(max_speed(*sim), 0.05) << integ;                 // at rest after 0.6 s
    EXPECT_NEAR(min_y(*sim), -0.048, 2e-3) << integ;           // on the ground, not hovering
  }
}

TEST_F(ContactScenes, FilteredPcgAndProjectedDirectSolveAgreeWithContactsAndPins) {
  // Cloth pinned at two corners draped over a ball: contacts and pins in one system.
  const std::string base = R"(
mesh: {grid: {nx: 12, ny: 12, width: 1.0, height: 1.0, plane: xz}}
material: {type: mass_spring, stencil: structural_shear_bend, stiffness: 2000, density: 0.1}
integrator: {type: baraff_witkin, dt: 0.005}
threads: 1
pins: [top_corners]
colliders: [{type: sphere, center: [0.5, -0.3, -0.5], radius: 0.32, friction: 0.3}]
)";
  auto a = make(base + "solver: {type: eigen_pcg, eigen_pcg: {tolerance: 1.0e-13, max_iterations: 10000}}\n");
  auto b = make(base + "solver: {type: eigen_ldlt}\n");
  // Drape the cloth with one solver, then take the same step from the same state with both.
  for (int k = 0; k < 60; ++k) b->step();
  a->scene().state = b->scene().state;
  // The integrator's restart state too: the friction dampers of a step start from the
  // responses the contacts showed in the step before (docs/CONTACT.md, "Corrections that stop").
  ASSERT_TRUE(a->integrator().set_restart_state(b->integrator().restart_state()));
  a->step();
  b->step();
  double diff = 0, scale = 0;
  for (std::size_t i = 0; i < a->scene().state.v.size(); ++i) {
    diff = std::max(diff, std::abs(a->scene().state.v[i] - b->scene().state.v[i]));
    scale = std::max(scale, std::abs(b->scene().state.v[i]));
  }
  EXPECT_LT(diff, 1e-8 * scale) << "max |v_pcg - v_ldlt| = " << diff << " of " << scale;
  // the ball really held the cloth: the vertex above its top stays outside it
  const auto& st = b->scene().state;
  for (loom::Index i = 0; i < st.size(); ++i) {
    const double dx = st.x[3 * i] - 0.5, dy = st.x[3 * i + 1] + 0.3, dz = st.x[3 * i + 2] + 0.5;
    EXPECT_GE(std::sqrt(dx * dx + dy * dy + dz * dz), 0.32 - 1e-9);
  }
  for (loom::Index i : st.pin_list) EXPECT_EQ(st.v[3 * i + 1], 0.0);
}

TEST_F(ContactScenes, ContactsReleaseWhenTheClothIsLifted) {
  // At rest on the ground, then gravity reverses: the constraints must let go.
  auto sim = make(falling_cloth("{type: baraff_witkin, dt: 2.0e-3, substeps: 5}"));
  for (int f = 0; f < 30; ++f) sim->advance_frame();
  EXPECT_NEAR(min_y(*sim), -0.048, 2e-3);
  sim->scene().gravity = {0, 9.81, 0};
  for (int f = 0; f < 10; ++f) sim->advance_frame();  // 0.1 s: y ~ g t^2 / 2 = 4.9 cm up
  EXPECT_GT(min_y(*sim), -0.048 + 0.03);
}

TEST_F(ContactScenes, FrictionlessSlopeAndFrictionOnTheImplicitPath) {
  const double th = M_PI / 6;
  auto slope = [&](const std::string& fr) {
    return R"(
mesh: {grid: {nx: 3, ny: 3, width: 0.02, height: 0.02, plane: xz}}
material: {type: mass_spring, stiffness: 100, density: 1.0}
integrator: {type: baraff_witkin, dt: 1.0e-3}
solver: {type: eigen_ldlt}
threads: 1
colliders: [{type: plane, point: [0, -0.001, 0], normal: [)" +
           std::to_string(std::sin(th)) + ", " + std::to_string(std::cos(th)) + ", 0]" + fr + "}]\n";
  };
  auto sim = make(slope(""));
  const double x0 = sim->scene().state.x[0];
  for (int k = 0; k < 500; ++k) sim->step();
  // distance along the slope after T = 0.5 s: g sin(theta) T^2 / 2 (to first order in h)
  const double dx = sim->scene().state.x[0] - x0;
  const double s = dx / std::cos(th);
  EXPECT_NEAR(2 * s / 0.25 / (9.81 * std::sin(th)), 1.0, 0.01);
  auto stuck = make(slope(", friction: 0.8"));  // mu > tan(30 deg): static friction holds it
  // Land on the slope (t ~ 0.045 s), then slide (the impact makes no friction) until kinetic
  // friction stops it: decelerating at g (mu cos(theta) - sin(theta)) = 1.9 m/s^2 from the
  // landing speed (~0.12 m/s), it stops before t = 0.11 s; then static friction holds it.
  for (int k = 0; k < 200; ++k) stuck->step();
  const auto landed = stuck->scene().state.x;
  for (int k = 0; k < 300; ++k) stuck->step();
  for (std::size_t i = 0; i < landed.size(); ++i) EXPECT_NEAR(stuck->scene().state.x[i], landed[i], 1e-9);
}

TEST_F(ContactScenes, RotatingBallDragsTheDrapedClothByFriction) {
  // Kang & Cho Fig. 9 in small: a cloth draped on a ball spinning about the vertical axis is
  // twisted along with it (positive angular velocity about +y).
  const std::string yaml = R"(
mesh: {grid: {nx: 10, ny: 10, width: 0.6, height: 0.6, plane: xz}}
material: {type: mass_spring, stencil: structural_shear_bend, stiffness: 300, damping: 0.01, density: 0.1}
integrator: {type: baraff_witkin, dt: 2.0e-3}
solver: {type: eigen_ldlt}
threads: 1
colliders:
  - {type: sphere, center: [0.3, -0.21, -0.3], radius: 0.2, friction: 0.9,
     motion: {type: rotate, axis: [0, 1, 0], angular_velocity: 3.0}}
)";
  auto sim = make(yaml);
  for (int k = 0; k < 300; ++k) sim->step();
  // angular momentum of the cloth about the ball's vertical axis: positive, like the ball
  const auto& st = sim->scene().state;
  double L = 0;
  for (loom::Index i = 0; i < st.size(); ++i) {
    const double rx = st.x[3 * i] - 0.3, rz = st.x[3 * i + 2] + 0.3;
    L += st.mass[i] * (rz * st.v[3 * i] - rx * st.v[3 * i + 2]);
  }
  EXPECT_GT(L, 0.0);
}

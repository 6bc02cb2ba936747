// Reaction forces of pin groups (issue 13): a static hanging cloth's pins carry its weight;
// a stretched chain of linear springs pulls on its clamps with k times each spring's extension;
// the reaction columns of stats.csv.
#include <gtest/gtest.h>

#include <array>
#include <cmath>
#include <filesystem>
#include <fstream>
#include <memory>
#include <sstream>
#include <string>
#include <vector>

#include "baraff_witkin.hpp"
#include "eigen_ldlt.hpp"
#include "loom/registry.hpp"
#include "loom/scene.hpp"
#include "loom/simulation.hpp"
#include "rk4_integrator.hpp"
#include "symplectic_euler.hpp"
#include "test_materials.hpp"

using namespace loom;

namespace {

std::vector<std::string> split(const std::string& line) {
  std::vector<std::string> out;
  std::stringstream ss(line);
  std::string c;
  while (std::getline(ss, c, ',')) out.push_back(c);
  return out;
}

// A chain of n springs (stiffness k, rest length l0) along x, unit masses m, no gravity;
// vertex 0 in group "left" (fixed), vertex n in group "right" with the given motion.
std::unique_ptr<Scene> chain(int n, double k, double l0, double m, const RigidMotion& motion) {
  auto sc = std::make_unique<Scene>();
  sc->gravity = {0, 0, 0};
  std::vector<loom::testing::SpringMaterial::Spring> springs;
  for (int q = 0; q < n; ++q) springs.push_back({q, q + 1, l0, k});
  sc->material = std::make_unique<loom::testing::SpringMaterial>(std::vector<double>(n + 1, m), springs, false);
  State& s = sc->state;
  s.resize(n + 1);
  for (int i = 0; i <= n; ++i) s.x[3 * i] = l0 * i;
  sc->material->compute_masses(s.mass);
  s.update_inverse_masses();
  PinGroup left;
  left.name = "left";
  left.vertices = {0};
  sc->pins.add(left, s);
  PinGroup right;
  right.name = "right";
  right.vertices = {static_cast<Index>(n)};
  right.motion = motion;
  right.center = {l0 * n, 0, 0};
  sc->pins.add(right, s);
  return sc;
}

RigidMotion stretch_to(double d, double t_end) {
  RigidMotion mo;
  mo.type = RigidMotion::Type::Keyframes;
  mo.keys = {{0.0, {0, 0, 0}, 0.0}, {t_end, {d, 0, 0}, 0.0}};
  return mo;
}

}  // namespace

// Quasi-static uniaxial stretch of a chain of 5 linear springs by D: at rest each spring is
// extended by D/5 and carries the tension k D/5; the clamps pull with exactly that force
// (left: -x, right: +x). Baraff-Witkin's constraint forces and the explicit definition
// m a - f - m g at the same state agree.
TEST(PinReactions, StretchedSpringChainPullsWithKTimesExtension) {
  const int n = 5;
  const double k = 100, l0 = 0.2, m = 0.01, D = 0.1;
  auto sc = chain(n, k, l0, m, stretch_to(D, 0.5));
  BaraffWitkinOptions o;
  o.rayleigh_alpha = 20;
  BaraffWitkin bw(o);
  sc->solver = std::make_unique<EigenLdlt>();
  bw.prepare(*sc, 0.01);
  for (int s = 0; s < 400; ++s) bw.step(*sc, 0.01);
  const double tension = k * D / n;
  std::vector<double> work, r;
  sc->pins.reactions(sc->state, *sc->material, sc->gravity, work, r);  // recorded by the solve
  ASSERT_EQ(r.size(), 6u);
  EXPECT_NEAR(r[0], -tension, 1e-9 * tension);
  EXPECT_NEAR(r[3], tension, 1e-9 * tension);
  for (int c : {1, 2, 4, 5}) EXPECT_NEAR(r[c], 0.0, 1e-12);
  // every free vertex at the uniform stretch
  for (int i = 0; i <= n; ++i) EXPECT_NEAR(sc->state.x[3 * i], (l0 + D / n) * i, 1e-10);
  // the explicit definition at the same state (a fresh set of groups records no solve)
  PinSet fresh;
  State copy = sc->state;
  PinGroup left;
  left.name = "left";
  left.vertices = {0};
  fresh.add(left, copy);
  std::vector<double> r2;
  fresh.reactions(copy, *sc->material, sc->gravity, work, r2);
  EXPECT_NEAR(r2[0], -tension, 1e-8 * tension);
}

// One spring between two pins, the right one translating at constant speed: the reaction is
// k times the current extension at every step, in each integrator (explicit ones by the
// definition m a - f - m g, Baraff-Witkin by its constraint force).
TEST(PinReactions, SpringBetweenMovingPinsInEveryIntegrator) {
  const double k = 250, l0 = 0.3, m = 0.02, speed = 0.4, h = 1e-3;
  RigidMotion mo;
  mo.type = RigidMotion::Type::Translate;
  mo.velocity = {speed, 0, 0};
  std::vector<std::unique_ptr<Integrator>> integrators;
  integrators.push_back(std::make_unique<symplectic_euler::SymplecticEuler>(Params()));
  integrators.push_back(std::make_unique<Rk4Integrator>());
  integrators.push_back(std::make_unique<BaraffWitkin>());
  for (auto& integ : integrators) {
    auto sc = chain(1, k, l0, m, mo);
    sc->solver = std::make_unique<EigenLdlt>();
    integ->prepare(*sc, h);
    std::vector<double> work, r;
    for (int s = 1; s <= 50; ++s) {
      integ->step(*sc, h);
      const double ext = sc->state.x[3] - sc->state.x[0] - l0;
      EXPECT_NEAR(ext, speed * sc->state.time, 1e-15) << integ->name();
      sc->pins.reactions(sc->state, *sc->material, sc->gravity, work, r);
      EXPECT_NEAR(r[3], k * ext, 1e-9 * k * ext) << integ->name() << " step " << s;
      EXPECT_NEAR(r[0], -k * ext, 1e-9 * k * ext) << integ->name() << " step " << s;
    }
  }
}

// A cloth hanging at rest from two pin groups: their reactions add up to its weight.
// Through `loom run`'s stats.csv (Baraff-Witkin's constraint forces), and by the explicit
// definition on the same state.
TEST(PinReactions, StaticHangingClothReactionEqualsItsWeight) {
  Registry reg;
  PluginLoader loader(reg, {std::string(LOOM_BINARY_DIR) + "/lib/loom/plugins"});
  Simulation::set_notes(false);
  const std::string out = std::string(LOOM_BINARY_DIR) + "/tests/pins/out_hanging";
  std::filesystem::remove_all(out);
  const std::string yaml =
      "mesh: {grid: {nx: 8, ny: 8, width: 1.0, height: 1.0, plane: xy}}\n"
      "material: {type: mass_spring, stiffness: 500, density: 0.1}\n"
      "integrator: {type: baraff_witkin, dt: 0.02, substeps: 25, rayleigh: {alpha: 5.0}}\n"
      "solver: {type: eigen_ldlt}\n"
      "gravity: [0, -9.81, 0]\n"
      "threads: 1\n"
      "pins: [{name: left, vertices: [56, 57]}, {name: right, box: {min: [0.7, 0.99, -1], max: [1.1, 1.1, 1]}}]\n"
      "frames: 16\n"
      "output: {dir: " + out + ", obj: false, stats: true}\n";
  auto sim = Simulation::from_string(yaml, "hanging.yaml", ".", {}, loader);
  sim->run();
  double M = 0;
  for (double mi : sim->scene().state.mass) M += mi;
  const double W = 9.81 * M;
  std::ifstream f(out + "/stats.csv");
  std::string header, line, last;
  std::getline(f, header);
  while (std::getline(f, line)) last = line;
  const auto cols = split(header), vals = split(last);
  ASSERT_EQ(cols.size(), vals.size());
  double sum[3] = {0, 0, 0};
  int found = 0;
  for (std::size_t c = 0; c < cols.size(); ++c)
    for (int a = 0; a < 3; ++a)
      for (const char* g : {"left", "right"})
        if (cols[c] == std::string("pin_") + g + "_f" + "xyz"[a]) {
          sum[a] += std::stod(vals[c]);
          ++found;
        }
  ASSERT_EQ(found, 6) << header;
  EXPECT_NEAR(sum[1], W, 1e-6 * W) << last;
  EXPECT_NEAR(sum[0], 0.0, 1e-6 * W);
  EXPECT_NEAR(sum[2], 0.0, 1e-6 * W);
  // explicit definition on the settled state: a symplectic-Euler copy of the scene
  auto se = Simulation::from_string(yaml, "hanging.yaml", ".",
                                    {"integrator={type: symplectic_euler, dt: 0.0001}", "solver=null"}, loader);
  se->scene().state.x = sim->scene().state.x;
  std::vector<double> work, r;
  se->scene().pins.reactions(se->scene().state, *se->scene().material, se->scene().gravity, work, r);
  EXPECT_NEAR(r[1] + r[4], W, 1e-5 * W);
  EXPECT_NEAR(r[0] + r[3], 0.0, 1e-5 * W);
}

// RK4 places moving pins at every stage (t, t + h/2, t + h/2, t + h): a free mass on a spring
// whose other end is a pin circling an axis keeps RK4's fourth order. (Extrapolating the pin
// linearly from the step start, x0 + c h v0, would miss the circle by O(h^2) at the stages and
// drop the method to second order.)
TEST(MovingPins, Rk4KeepsFourthOrderWithARotatingPin) {
  RigidMotion spin;
  spin.type = RigidMotion::Type::Rotate;
  spin.axis = {0, 0, 1};
  spin.angular_velocity = 3.0;
  auto run = [&](double h) {
    auto sc = std::make_unique<Scene>();
    sc->gravity = {0, 0, 0};
    std::vector<loom::testing::SpringMaterial::Spring> springs = {{0, 1, 0.2, 50.0}};
    sc->material = std::make_unique<loom::testing::SpringMaterial>(std::vector<double>{0.05, 0.05}, springs, false);
    State& s = sc->state;
    s.resize(2);
    s.x = {0.3, 0, 0, 0.3, -0.25, 0};
    sc->material->compute_masses(s.mass);
    s.update_inverse_masses();
    PinGroup g;
    g.name = "crank";
    g.vertices = {0};
    g.motion = spin;
    g.center = {0, 0, 0};
    sc->pins.add(g, s);
    Rk4Integrator rk;
    rk.prepare(*sc, h);
    const int n = static_cast<int>(std::lround(0.5 / h));
    for (int k = 0; k < n; ++k) rk.step(*sc, h);
    return std::array<double, 3>{s.x[3], s.x[4], s.x[5]};
  };
  const auto ref = run(0.01 / 64);
  double err[3];
  for (int q = 0; q < 3; ++q) {
    const auto x = run(0.01 / (1 << q));
    err[q] = std::hypot(x[0] - ref[0], x[1] - ref[1]);
  }
  const double order1 = std::log2(err[0] / err[1]), order2 = std::log2(err[1] / err[2]);
  EXPECT_GT(order1, 3.7) << err[0] << " " << err[1];
  EXPECT_GT(order2, 3.7) << err[1] << " " << err[2];
  std::printf("rk4 with a rotating pin: errors %.3g %.3g %.3g, orders %.2f %.2f\n", err[0], err[1], err[2], order1, order2);
}

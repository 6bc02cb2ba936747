// Implicit contact that lands: a wool cloth thrown at 50 m/s at a plane 0.3 m below lands
// within one step of the exact (free-flight) contact time, keeps its tangential velocity on a
// frictionless plane and loses exactly mu g t once it rests on a rough one; a tilted plane
// does not tear it. Baraff-Witkin at h = 0.01 and 0.001, and the explicit integrators
// (ColliderSet::resolve_contacts) for comparison.
#include <gtest/gtest.h>

#include <cmath>
#include <sstream>

#include "loom/material.hpp"
#include "loom/simulation.hpp"

namespace {

constexpr double kG = 9.81;
constexpr double kV0 = 50.0;     // thrown down at 50 m/s
constexpr double kVt = 4.0;      // and sideways (+x) at 4 m/s
constexpr double kDrop = 0.3;    // plane 0.3 m below the cloth
constexpr double kThick = 0.005;

struct Landing : ::testing::Test {
  loom::Registry registry;
  loom::PluginLoader loader{registry};
  std::unique_ptr<loom::Simulation> make(const std::string& integrator, const std::string& collider) {
    std::ostringstream y;
    y << "mesh: {grid: {nx: 6, ny: 6, width: 1.0, height: 1.0, plane: xz}}\n"
      << "material: {type: gnatv, material_file: " LOOM_SOURCE_DIR "/materials/wool.yaml}\n"
      << "integrator: " << integrator << "\n"
      << "solver: {type: eigen_ldlt}\n"
      << "threads: 1\n"
      << "initial_velocity: [" << kVt << ", " << -kV0 << ", 0]\n"
      << "colliders: [" << collider << "]\n";
    return loom::Simulation::from_string(y.str(), "landing.yaml", LOOM_SOURCE_DIR, {}, loader);
  }
};

std::string flat_plane(double mu) {
  std::ostringstream c;
  c << "{type: plane, point: [0, " << -kDrop << ", 0], normal: [0, 1, 0], thickness: " << kThick
    << ", friction: " << mu << "}";
  return c.str();
}

// Exact contact time of free flight: kV0 t + g t^2 / 2 = kDrop - kThick.
double exact_contact_time() {
  const double d = kDrop - kThick;
  return (-kV0 + std::sqrt(kV0 * kV0 + 2 * kG * d)) / kG;
}

struct Extremes {
  double min_y = 1e300, max_y = -1e300;
};
Extremes extremes(const loom::State& s) {
  Extremes e;
  for (loom::Index i = 0; i < s.size(); ++i) {
    e.min_y = std::min(e.min_y, s.x[3 * i + 1]);
    e.max_y = std::max(e.max_y, s.x[3 * i + 1]);
  }
  return e;
}

// Steps to time T; checks no vertex goes through the surface; returns the landing time (all
// vertices on the offset surface) and checks the velocities after it against
// v_x = kVt - mu g (t - t_land) (Coulomb friction with the normal force m g per vertex).
// tol: velocity tolerance (the explicit integrators see the rest-shape forces' rounding,
// ~1e-8 m/s here, where the implicit step's are below 1e-9).
void throw_and_check(loom::Simulation& sim, double h, double mu, double T, const std::string& what,
                     double tol = 1e-9) {
  const double surface = -kDrop + kThick;
  const double t_star = exact_contact_time();
  double t_land = -1;
  const int steps = static_cast<int>(std::lround(T / h));
  for (int k = 0; k < steps; ++k) {
    sim.step();
    const loom::State& s = sim.scene().state;
    const Extremes e = extremes(s);
    ASSERT_GE(e.min_y, surface - 1e-9) << what << ": through the plane at t = " << s.time;
    if (t_land < 0) {
      if (e.max_y <= surface + 1e-9) {
        t_land = s.time;
      } else {
        // Still in the air: free flight, nothing touched the tangential velocity.
        for (loom::Index i = 0; i < s.size(); ++i) ASSERT_NEAR(s.v[3 * i], kVt, tol) << what << " t = " << s.time;
      }
      continue;
    }
    // Resting: on the surface, no normal velocity, tangential velocity from Coulomb.
    const double vx = std::max(0.0, kVt - mu * kG * (s.time - t_land));
    for (loom::Index i = 0; i < s.size(); ++i) {
      ASSERT_NEAR(s.x[3 * i + 1], surface, 1e-9) << what << " t = " << s.time;
      ASSERT_NEAR(s.v[3 * i + 1], 0.0, tol) << what << " t = " << s.time;
      ASSERT_NEAR(s.v[3 * i], vx, 10 * tol) << what << " vertex " << i << " t = " << s.time;
      ASSERT_NEAR(s.v[3 * i + 2], 0.0, tol) << what << " t = " << s.time;
    }
  }
  ASSERT_GT(t_land, 0) << what << ": never landed";
  // Lands at the end of the step in which the exact contact time falls (within one step).
  EXPECT_GE(t_land, t_star - 1e-12) << what;
  EXPECT_LE(t_land, t_star + h + 1e-12) << what;
}

}  // namespace

TEST_F(Landing, BaraffWitkinLandsOnTimeAndKeepsTangentialVelocityFrictionless) {
  for (const double h : {0.01, 0.001}) {
    auto sim = make("{type: baraff_witkin, dt: " + std::to_string(h) + "}", flat_plane(0.0));
    throw_and_check(*sim, h, 0.0, 0.2, "baraff_witkin h = " + std::to_string(h));
  }
}

TEST_F(Landing, BaraffWitkinFrictionTakesExactlyMuGT) {
  // Friction inside the solve (the default) and as a velocity correction after it.
  for (const bool implicit : {true, false})
    for (const double h : {0.01, 0.001}) {
      auto sim = make("{type: baraff_witkin, dt: " + std::to_string(h) +
                          ", implicit_friction: " + (implicit ? "true" : "false") + "}",
                      flat_plane(0.3));
      throw_and_check(*sim, h, 0.3, 0.3,
                      "baraff_witkin mu = 0.3 h = " + std::to_string(h) + (implicit ? " implicit" : " after the solve"));
    }
}

// A strip lying on a rough plane (mu 0.4), dragged along +x at 0.2 m/s by its pinned end
// column: once it slides as one, the pull the pins record is the kinetic friction on the free
// vertices, mu g (their mass), whatever makes the friction (Coulomb: the force does not depend
// on how the strip is pulled). The friction inside the solve first sizes each vertex's damper
// for a vertex alone; the strip's springs make the pulled vertices answer stiffer than that,
// so without the corrections (ImplicitSelfContact::kCoulombTolerance) the dampers would hold
// more than mu g m. Checked at h = 0.005 over the last 0.2 s of 1 s. (The velocity correction
// after the solve, implicit_friction: false, pulls with 6.3 times mu g m here: the solve moves
// the neighbours of a vertex that friction then stops; docs/CONTACT.md.)
TEST_F(Landing, DraggedStripPullsWithTheKineticFrictionForce) {
  const double mu = 0.4, U = 0.2, h = 0.005;
  std::ostringstream y;
  y << "mesh: {grid: {nx: 9, ny: 3, width: 0.4, height: 0.1, plane: xz}}\n"
    << "material: {type: mass_spring, stiffness: 200, density: 0.2}\n"
    << "integrator: {type: baraff_witkin, dt: " << h << "}\n"
    << "solver: {type: eigen_ldlt}\n"
    << "threads: 1\n"
    << "pins: [{name: end, box: {min: [0.39, -1, -1], max: [0.41, 1, 1]}, motion: {type: translate, velocity: ["
    << U << ", 0, 0]}}]\n"
    << "colliders: [{type: plane, point: [0, -0.002, 0], normal: [0, 1, 0], thickness: 0.002, friction: " << mu
    << "}]\n";
  auto sim = loom::Simulation::from_string(y.str(), "drag.yaml", LOOM_SOURCE_DIR, {}, loader);
  loom::Scene& sc = sim->scene();
  const loom::State& s = sc.state;
  ASSERT_EQ(s.pin_list.size(), 3u);
  double free_mass = 0;
  for (loom::Index i = 0; i < s.size(); ++i)
    if (!s.pinned[i]) free_mass += s.mass[i];
  const double expected = mu * kG * free_mass;
  const int steps = static_cast<int>(std::lround(1.0 / h));
  for (int k = 0; k < steps; ++k) {
    sim->step();
    if (k < steps - static_cast<int>(std::lround(0.2 / h))) continue;
    const std::vector<double>& f = sc.pins.constraint_forces();
    double fx = 0;
    for (std::size_t p = 0; p < s.pin_list.size(); ++p) fx += f[3 * p];
    EXPECT_NEAR(fx, expected, 0.02 * expected) << "t = " << s.time;
    for (loom::Index i = 0; i < s.size(); ++i) {
      ASSERT_NEAR(s.x[3 * i + 1], 0.0, 1e-9) << "vertex " << i << " left the plane";
      EXPECT_NEAR(s.v[3 * i], U, 0.01 * U) << "vertex " << i << " t = " << s.time;
    }
  }
}

// A patch resting on a rough plane (mu 0.5), its vertices thrown sideways with random
// velocities (up to 1 m/s): the total energy (kinetic + gravitational + elastic) never grows
// from one step to the next; friction inside the solve is a damper, which only takes energy
// out, and the patch comes to rest (kinetic energy below 1e-6 of the start within 1 s).
TEST_F(Landing, FrictionInsideTheSolveOnlyTakesEnergyOut) {
  const double h = 0.005;
  const std::string yaml =
      "mesh: {grid: {nx: 7, ny: 7, width: 0.3, height: 0.3, plane: xz}}\n"
      "material: {type: mass_spring, stiffness: 50, density: 0.2}\n"
      "integrator: {type: baraff_witkin, dt: 0.005}\n"
      "solver: {type: eigen_ldlt}\n"
      "threads: 1\n"
      "colliders: [{type: plane, point: [0, -0.002, 0], normal: [0, 1, 0], thickness: 0.002, friction: 0.5}]\n";
  auto sim = loom::Simulation::from_string(yaml, "patch.yaml", LOOM_SOURCE_DIR, {}, loader);
  loom::Scene& sc = sim->scene();
  loom::State& s = sc.state;
  std::uint32_t r = 12345;
  auto uniform = [&] {  // in [-1, 1)
    r = r * 1664525u + 1013904223u;
    return static_cast<double>(r >> 8) / static_cast<double>(1u << 23) - 1.0;
  };
  for (loom::Index i = 0; i < s.size(); ++i) {
    s.v[3 * i] = uniform();
    s.v[3 * i + 2] = uniform();
  }
  auto energy = [&] {
    return loom::kinetic_energy(s) + loom::gravitational_energy(s, sc.gravity.data()) +
           sc.material->elastic_energy(s.x);
  };
  const double k0 = loom::kinetic_energy(s);
  double e = energy();
  for (int k = 0; k < static_cast<int>(std::lround(1.0 / h)); ++k) {
    sim->step();
    const double next = energy();
    ASSERT_LE(next, e + 1e-12 * std::abs(e)) << "t = " << s.time;
    e = next;
  }
  EXPECT_LT(loom::kinetic_energy(s), 1e-6 * k0);
}

TEST_F(Landing, ExplicitIntegratorsLandOnTimeToo) {
  for (const std::string integ : {"symplectic_euler", "rk4"}) {
    auto sim = make("{type: " + integ + ", dt: 1.0e-4}", flat_plane(0.0));
    throw_and_check(*sim, 1e-4, 0.0, 0.05, integ, 1e-6);
  }
}

TEST_F(Landing, TiltedPlaneDoesNotTearTheCloth) {
  // A 30 degree slope under the cloth (0.3 m below its x = 0 edge, falling away along +x):
  // the cloth lands edge first and slides. Total energy (kinetic + gravitational + elastic)
  // never exceeds its initial value (impacts, friction and backward Euler only dissipate),
  // and the cloth's strain energy stays a small part of it.
  const double th = M_PI / 6;
  for (const double h : {0.01, 0.001}) {
    for (const double mu : {0.0, 0.3}) {
      std::ostringstream c;
      c.precision(17);
      c << "{type: plane, point: [0, " << -kDrop << ", 0], normal: [" << std::sin(th) << ", " << std::cos(th)
        << ", 0], friction: " << mu << "}";
      auto sim = make("{type: baraff_witkin, dt: " + std::to_string(h) + "}", c.str());
      const loom::Scene& sc = sim->scene();
      auto energy = [&](double* elastic) {
        *elastic = sc.material->elastic_energy(sc.state.x);
        return loom::kinetic_energy(sc.state) + loom::gravitational_energy(sc.state, sc.gravity.data()) + *elastic;
      };
      double el = 0;
      const double e0 = energy(&el);
      double max_el = 0;
      const int steps = static_cast<int>(std::lround(0.3 / h));
      for (int k = 0; k < steps; ++k) {
        sim->step();
        const double e = energy(&el);
        max_el = std::max(max_el, el);
        ASSERT_LE(e, e0 + 1e-6 * std::abs(e0)) << "h = " << h << " mu = " << mu << " t = " << sc.state.time;
      }
      EXPECT_LT(max_el, 0.1 * e0) << "h = " << h << " mu = " << mu;
      // It is on the slope, below where it started.
      for (loom::Index i = 0; i < sc.state.size(); ++i) {
        const double* x = &sc.state.x[3 * i];
        EXPECT_GE(std::sin(th) * x[0] + std::cos(th) * (x[1] + kDrop), -1e-9);
      }
    }
  }
}

TEST_F(Landing, FrictionKeepsActingOnAVertexSlidingOverACurvedSurface) {
  // A 2 cm patch resting on top of a ball of radius 0.3 spinning about z at 2 rad/s: the top
  // moves along +x at 0.6 m/s. The vertices are in contact at every step (not landing), so
  // friction (mu 0.9 > the slope they reach) drags the patch until it moves with the surface
  // and then carries it around the ball against the pull of gravity along the slope.
  const std::string yaml = R"(
mesh: {grid: {nx: 3, ny: 3, width: 0.02, height: 0.02, plane: xz}}
material: {type: mass_spring, stiffness: 100, density: 1.0}
integrator: {type: baraff_witkin, dt: 2.0e-3}
solver: {type: eigen_ldlt}
threads: 1
colliders: [{type: sphere, center: [0.01, -0.3, -0.01], radius: 0.3, friction: 0.9,
             motion: {type: rotate, axis: [0, 0, 1], angular_velocity: -2.0}}]
)";
  auto sim = loom::Simulation::from_string(yaml, "ball.yaml", LOOM_SOURCE_DIR, {}, loader);
  for (int k = 0; k < 100; ++k) sim->step();  // 0.2 s
  const loom::State& s = sim->scene().state;
  const auto& col = sim->scene().colliders.colliders()[0];
  double rel = 0;
  for (loom::Index i = 0; i < s.size(); ++i) {
    const auto ct = col.query(&s.x[3 * i], s.time);
    ASSERT_LT(std::abs(ct.distance), 1e-4) << "vertex " << i << " left the ball";
    double d2 = 0;
    for (int k = 0; k < 3; ++k) d2 += (s.v[3 * i + k] - ct.velocity[k]) * (s.v[3 * i + k] - ct.velocity[k]);
    rel = std::max(rel, std::sqrt(d2));
  }
  EXPECT_LT(rel, 0.01) << "the patch slides on the ball instead of being carried (surface speed 0.6 m/s)";
}

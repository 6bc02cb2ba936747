// Pins with prescribed motion (issue 13): selection (names, vertex lists, boxes), bad input,
// keyframed pins exact to rounding in every integrator, a rotating clamp turning a strip.
#include <gtest/gtest.h>

#include <cmath>
#include <filesystem>
#include <fstream>
#include <memory>
#include <string>
#include <vector>

#include <algorithm>

#include "loom/pins.hpp"
#include "loom/registry.hpp"
#include "loom/simulation.hpp"

using namespace loom;

namespace {

struct Loader {
  Registry reg;
  PluginLoader loader{reg, {std::string(LOOM_BINARY_DIR) + "/lib/loom/plugins"}};
};

std::unique_ptr<Simulation> make(Loader& L, const std::string& yaml, const std::vector<std::string>& sets = {}) {
  Simulation::set_notes(false);
  return Simulation::from_string(yaml, "pins_test.yaml", ".", sets, L.loader);
}

std::string error_of(Loader& L, const std::string& yaml) {
  try {
    make(L, yaml);
  } catch (const InputError& e) {
    return e.what();
  }
  return "(no error)";
}

const std::string kGrid =
    "mesh: {grid: {nx: 6, ny: 6, width: 1.0, height: 1.0, plane: xy}}\n"
    "material: {type: mass_spring, stiffness: 500, density: 0.1}\n"
    "integrator: {type: symplectic_euler, dt: 0.001}\n"
    "gravity: [0, -9.81, 0]\n"
    "threads: 1\n";

// Independent reference for a keyframed rigid motion: the keys' translation and angle,
// interpolated linearly or with the quintic ease 6w^5 - 15w^4 + 10w^3, rotation by a unit
// quaternion about axis through center (not the Rodrigues matrix the code uses).
struct Key {
  double t, tx, ty, tz, angle;
};
std::array<double, 3> keyed(const std::vector<Key>& keys, bool smooth, const double axis[3], const double c[3],
                            const double X[3], double t) {
  double tr[3], th;
  if (t <= keys.front().t) {
    tr[0] = keys.front().tx, tr[1] = keys.front().ty, tr[2] = keys.front().tz, th = keys.front().angle;
  } else if (t >= keys.back().t) {
    tr[0] = keys.back().tx, tr[1] = keys.back().ty, tr[2] = keys.back().tz, th = keys.back().angle;
  } else {
    std::size_t k = 0;
    while (keys[k + 1].t <= t) ++k;
    double w = (t - keys[k].t) / (keys[k + 1].t - keys[k].t);
    if (smooth) w = ((6 * w - 15) * w + 10) * w * w * w;
    const Key &a = keys[k], &b = keys[k + 1];
    tr[0] = a.tx + w * (b.tx - a.tx);
    tr[1] = a.ty + w * (b.ty - a.ty);
    tr[2] = a.tz + w * (b.tz - a.tz);
    th = a.angle + w * (b.angle - a.angle);
  }
  const double s = std::sin(th / 2), qw = std::cos(th / 2);
  const double u[3] = {s * axis[0], s * axis[1], s * axis[2]};
  const double r[3] = {X[0] - c[0], X[1] - c[1], X[2] - c[2]};
  const double uxr[3] = {u[1] * r[2] - u[2] * r[1], u[2] * r[0] - u[0] * r[2], u[0] * r[1] - u[1] * r[0]};
  const double uxuxr[3] = {u[1] * uxr[2] - u[2] * uxr[1], u[2] * uxr[0] - u[0] * uxr[2], u[0] * uxr[1] - u[1] * uxr[0]};
  std::array<double, 3> out;
  for (int k = 0; k < 3; ++k) out[k] = c[k] + tr[k] + r[k] + 2 * qw * uxr[k] + 2 * uxuxr[k];
  return out;
}

}  // namespace

TEST(PinSelection, BoxNamesAndVertexListsSelectTheSameVertices) {
  Loader L;
  auto a = make(L, kGrid + "pins: [{name: edge, box: {min: [-0.01, -0.01, -0.01], max: [0.01, 1.01, 0.01]}}]\n");
  auto b = make(L, kGrid + "pins: [left_edge]\n");
  auto c = make(L, kGrid + "pins: [{name: edge, vertices: [0, 6, 12, 18, 24, 30]}]\n");
  EXPECT_EQ(a->scene().state.pin_list, b->scene().state.pin_list);
  EXPECT_EQ(a->scene().state.pin_list, c->scene().state.pin_list);
  ASSERT_EQ(a->scene().pins.groups().size(), 1u);
  EXPECT_EQ(a->scene().pins.groups()[0].name, "edge");
  EXPECT_EQ(b->scene().pins.groups()[0].name, "left_edge");
  EXPECT_FALSE(a->scene().pins.moving());
  // mass_scale shares the selection: a box doubles the masses of the left edge only
  auto m = make(L, kGrid + "mass_scale: [{box: {min: [-0.01, -0.01, -0.01], max: [0.01, 1.01, 0.01]}, factor: 2}]\n");
  for (Index i = 0; i < 36; ++i)
    EXPECT_DOUBLE_EQ(m->scene().state.mass[i], (i % 6 == 0 ? 2.0 : 1.0) * b->scene().state.mass[i]) << i;
}

// An OBJ mesh (no grid structure, vertices in file order) clamped along an edge by a box.
TEST(PinSelection, BoxClampsAnObjMeshAlongAnEdge) {
  Loader L;
  const std::string dir = std::string(LOOM_BINARY_DIR) + "/tests/pins";
  std::filesystem::create_directories(dir);
  {
    // a 3 x 3 vertex square in the xz plane, vertices listed column by column (x = 0 first)
    std::ofstream f(dir + "/square.obj");
    for (int i = 0; i < 3; ++i)
      for (int j = 0; j < 3; ++j) f << "v " << 0.5 * i << " 0 " << 0.5 * j << "\n";
    for (int i = 0; i < 2; ++i)
      for (int j = 0; j < 2; ++j) {
        const int a = 3 * i + j + 1, b = a + 3, c = a + 4, d = a + 1;
        f << "f " << a << " " << b << " " << c << "\nf " << a << " " << c << " " << d << "\n";
      }
  }
  const std::string yaml =
      "mesh: {obj: square.obj}\n"
      "material: {type: mass_spring, stiffness: 500, density: 0.1}\n"
      "integrator: {type: symplectic_euler, dt: 0.0001}\n"
      "pins: [{name: clamp, box: {min: [-0.01, -0.01, -0.01], max: [0.01, 0.01, 1.01]}, motion: {type: translate, "
      "velocity: [0, 0.5, 0]}}]\n";
  Simulation::set_notes(false);
  auto sim = Simulation::from_string(yaml, dir + "/square.yaml", dir, {}, L.loader);
  EXPECT_EQ(sim->scene().state.pin_list, (std::vector<Index>{0, 1, 2}));
  for (int k = 0; k < 100; ++k) sim->step();
  for (Index i : {0, 1, 2}) {
    EXPECT_NEAR(sim->scene().state.x[3 * i + 1], 0.5 * sim->scene().state.time, 1e-15);
    EXPECT_EQ(sim->scene().state.v[3 * i + 1], 0.5);  // the prescribed velocity, exactly
  }
}

TEST(PinSelection, BadInputGetsOneClearError) {
  Loader L;
  std::string e = error_of(L, kGrid + "pins: [{name: c, box: {min: [2, 2, -1], max: [3, 3, 1]}}]\n");
  EXPECT_NE(e.find("pins_test.yaml:6"), std::string::npos) << e;
  EXPECT_NE(e.find("selects no vertex"), std::string::npos) << e;
  EXPECT_NE(e.find("Fix"), std::string::npos) << e;
  e = error_of(L, kGrid + "pins: [{name: c, vertices: [0], motion: {type: keyframes, keys: [{t: 0.5}, {t: 0.2}]}}]\n");
  EXPECT_NE(e.find("keyframe times must increase"), std::string::npos) << e;
  EXPECT_NE(e.find("pins_test.yaml:6"), std::string::npos) << e;
  e = error_of(L, kGrid + "pins: [left_edge, {name: m, vertices: [0], motion: {type: translate, velocity: [1, 0, 0]}}]\n");
  EXPECT_NE(e.find("a vertex follows one motion"), std::string::npos) << e;
  e = error_of(L, kGrid + "pins: [{name: a, vertices: [0]}, {name: a, vertices: [1]}]\n");
  EXPECT_NE(e.find("two pin groups are named 'a'"), std::string::npos) << e;
  e = error_of(L, kGrid + "pins: [{name: 'a b', vertices: [0]}]\n");
  EXPECT_NE(e.find("not usable as a stats.csv column"), std::string::npos) << e;
  e = error_of(L, kGrid + "pins: [{name: a, vertices: [0], motion: {type: spin}}]\n");
  EXPECT_NE(e.find("spin"), std::string::npos) << e;
  e = error_of(L, kGrid + "pins: [{name: a, vertices: [0], motion: {type: rotate, angular_velocity: 1, centre: [0, 0, 0]}}]\n");
  EXPECT_NE(e.find("did you mean 'center'"), std::string::npos) << e;
  e = error_of(L, kGrid + "pins: [{name: a, vertices: [0], motion: {type: keyframes, interpolation: cubic, keys: [{t: 0}]}}]\n");
  EXPECT_NE(e.find("interpolation"), std::string::npos) << e;
  e = error_of(L, kGrid + "pins: [{name: a, bx: {min: [0, 0, 0], max: [1, 1, 1]}}]\n");
  EXPECT_NE(e.find("selects no vertex"), std::string::npos) << e;
  e = error_of(L, kGrid + "pins: [top_egde]\n");
  EXPECT_NE(e.find("did you mean 'top_edge'"), std::string::npos) << e;
}

// A pinned corner following keyframes (translation and rotation about an axis through a
// point, linear and smooth) is where the keys say, to rounding, after every step of every
// integrator; the rest of the cloth stays finite.
TEST(MovingPins, KeyframedCornerIsExactInEveryIntegrator) {
  Loader L;
  const std::vector<Key> keys = {{0.0, 0, 0, 0, 0}, {0.04, 0.02, 0.01, 0.03, 0.3}, {0.09, 0.0, 0.04, 0.0, -0.2}};
  const double axis[3] = {0.0, 0.6, 0.8}, center[3] = {0.5, 0.5, 0.0};
  const std::string motion =
      "motion: {type: keyframes, axis: [0, 3, 4], center: [0.5, 0.5, 0], interpolation: INTERP, keys: ["
      "{t: 0, translate: [0, 0, 0], angle: 0}, {t: 0.04, translate: [0.02, 0.01, 0.03], angle: 0.3}, "
      "{t: 0.09, translate: [0, 0.04, 0], angle: -0.2}]}";
  for (const char* integ : {"symplectic_euler", "rk4", "harmonic_oscillation", "baraff_witkin"}) {
    for (const bool smooth : {false, true}) {
      std::string m = motion;
      m.replace(m.find("INTERP"), 6, smooth ? "smooth" : "linear");
      std::vector<std::string> sets = {std::string("integrator.type=") + integ, "integrator.dt=0.0002"};
      if (std::string(integ) == "baraff_witkin") sets.push_back("solver={type: eigen_ldlt}");
      auto sim = make(L, kGrid + "pins: [top_edge, {name: corner, vertices: [0, 1], " + m + "}]\n", sets);
      const State& s = sim->scene().state;
      const auto& mp = sim->scene().mesh.positions;
      const double X0[3] = {mp[0], mp[1], mp[2]}, X1[3] = {mp[3], mp[4], mp[5]};
      const std::vector<double> start = s.x;
      double worst = 0;
      for (int k = 0; k < 500; ++k) {
        sim->step();
        const auto p0 = keyed(keys, smooth, axis, center, X0, s.time);
        const auto p1 = keyed(keys, smooth, axis, center, X1, s.time);
        for (int c = 0; c < 3; ++c) {
          worst = std::max(worst, std::abs(s.x[c] - p0[c]));
          worst = std::max(worst, std::abs(s.x[3 + c] - p1[c]));
        }
      }
      EXPECT_LT(worst, 1e-15) << integ << (smooth ? " smooth" : " linear");
      EXPECT_GT(s.time, 0.09);  // past the last key: held there
      for (double x : s.x) ASSERT_TRUE(std::isfinite(x)) << integ;
      // fixed pins did not move, bit for bit
      for (Index i = 30; i < 36; ++i)
        for (int c = 0; c < 3; ++c) EXPECT_EQ(s.x[3 * i + c], start[3 * i + c]) << integ;
    }
  }
}

// A clamp rotating about its own centre line turns a strip (no gravity) by the prescribed
// angle: the clamp is exact, and the free far end follows it quasi-statically.
TEST(MovingPins, RotatingClampTurnsAStripByThePrescribedAngle) {
  Loader L;
  const double turn = 1.2;  // rad, reached at t = 1 s (smooth), then held
  const std::string yaml =
      "mesh: {grid: {nx: 13, ny: 3, width: 1.2, height: 0.2, plane: xy}}\n"
      "material: {type: mass_spring, stiffness: 500, density: 0.1}\n"
      "integrator: {type: baraff_witkin, dt: 0.01, rayleigh: {alpha: 4.0}}\n"
      "solver: {type: eigen_ldlt}\n"
      "gravity: [0, 0, 0]\n"
      "threads: 1\n"
      "pins: [{name: clamp, group: left_edge, motion: {type: keyframes, axis: [0, 0, 1], interpolation: smooth, "
      "keys: [{t: 0, angle: 0}, {t: 1, angle: 1.2}]}}]\n";
  auto sim = make(L, yaml);
  const State& s = sim->scene().state;
  const double c[3] = {0.0, 0.1, 0.0};  // default centre: the clamp's centroid
  for (int k = 0; k < 400; ++k) sim->step();
  // the clamp vertices (x = 0, y = 0, 0.1, 0.2) are rotated exactly
  for (int r = 0; r < 3; ++r) {
    const Index i = r * 13;
    const double y0 = 0.1 * r - c[1];
    EXPECT_NEAR(s.x[3 * i], c[0] - std::sin(turn) * y0, 1e-15);
    EXPECT_NEAR(s.x[3 * i + 1], c[1] + std::cos(turn) * y0, 1e-15);
  }
  // the free end (x = 1.2) turned by the same angle about the clamp centre
  double tip[3] = {0, 0, 0};
  for (int r = 0; r < 3; ++r)
    for (int q = 0; q < 3; ++q) tip[q] += s.x[3 * (r * 13 + 12) + q] / 3;
  const double angle = std::atan2(tip[1] - c[1], tip[0] - c[0]);
  EXPECT_NEAR(angle, turn, 1e-4);
  EXPECT_NEAR(std::hypot(tip[0] - c[0], tip[1] - c[1]), 1.2, 1e-3);
  EXPECT_NEAR(tip[2], 0.0, 1e-12);
}

// Named groups on a mesh without grid structure (an OBJ) follow the grid's conventions: the
// same grid with its structure dropped selects the same vertices as the grid itself, standing
// (xy) and lying flat (xz, where "top" is the smallest z). A flat OBJ once pinned every vertex
// with top_edge (its y extent is zero).
TEST(PinSelection, NamedGroupsOnMeshesWithoutGridFollowTheGridConventions) {
  const std::vector<std::string> groups = {"top_corners", "top_edge",  "left_corners", "left_edge",
                                           "bottom_corners", "bottom_edge", "right_edge", "corners"};
  for (GridPlane plane : {GridPlane::XY, GridPlane::XZ}) {
    const Mesh grid = make_grid(7, 5, 1.2, 0.8, plane);
    Mesh obj = grid;
    obj.grid.reset();
    for (const auto& g : groups) {
      const Params p = Params::from_string(g, "t.yaml");
      std::vector<Index> want = select_vertices(grid, p), got = select_vertices(obj, p);
      std::sort(want.begin(), want.end());
      std::sort(got.begin(), got.end());
      EXPECT_EQ(got, want) << g << (plane == GridPlane::XY ? " on xy" : " on xz");
      EXPECT_LT(got.size(), std::size_t(7 * 5)) << g;
    }
  }
}

// symplectic_euler on the CUDA backend (issue 17), through the Thrust-OpenMP stand-in (and on a
// GPU as test_cuda_gpu): the shipped draped_ball_symplectic_euler set-up (its 128 x 128
// mass-spring cloth, material, step and spinning ball with friction; self_collision off) run on
// the device against the CPU plugin followed by ColliderSet::resolve_contacts (what
// Simulation::step does), in double and in float; the device description's other materials
// (GNATV wool, a bent cloth) against the CPU plugin's generic path; the one parameter spec;
// the refusals that name the fix.
#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <memory>
#include <string>
#include <vector>

#include "cuda_integrators.hpp"
#include "cuda_test_compare.hpp"
#include "cuda_test_state.hpp"
#include "gnatv_material.hpp"
#include "loom/bending.hpp"
#include "loom/mesh.hpp"
#include "loom/scene.hpp"
#include "mass_spring.hpp"
#include "symplectic_euler.hpp"

using namespace loom;
namespace lc = loom::cuda;
using loom::symplectic_euler::SymplecticEuler;

namespace {

using loom_cuda_test::rel_diff;

const std::string kScene = "draped_ball_symplectic_euler.yaml";

Params shipped() { return Params::from_file(std::string(LOOM_SOURCE_DIR) + "/scenes/" + kScene); }

/// The shipped scene's cloth, material, gravity and colliders (self_collision left out), with the
/// cloth moved down from its release height to `gap` above the ball's offset surface and given
/// the speed of that fall, sqrt(2 g drop), so that contacts start within a few steps instead of
/// after the ~1900 steps of free fall.
std::unique_ptr<Scene> shipped_scene(double gap) {
  const Params root = shipped();
  const Params grid = root.child("mesh").child("grid");
  EXPECT_EQ(grid.get("plane", std::string()), "xz");
  auto sc = std::make_unique<Scene>();
  sc->source = kScene;
  sc->mesh = make_grid(static_cast<Index>(grid.get("nx", 0)), static_cast<Index>(grid.get("ny", 0)),
                       grid.get("width", 0.0), grid.get("height", 0.0), GridPlane::XZ);
  sc->material = std::make_unique<mass_spring::MassSpringMaterial>(root.child("material"), sc->mesh);
  sc->colliders = ColliderSet::parse(root.child("colliders"));
  EXPECT_EQ(sc->colliders.size(), 1u);
  const Collider& ball = sc->colliders.colliders()[0];
  EXPECT_EQ(ball.shape, Collider::Shape::Sphere);
  EXPECT_NE(ball.motion.type, RigidMotion::Type::Fixed);
  const std::vector<double> g = root.child("gravity").as_doubles();
  sc->gravity = {g[0], g[1], g[2]};
  const Params c = root.child("colliders").at(0);
  const double top = c.child("center").as_doubles()[1] + c.get("radius", 0.0) + c.get("thickness", 0.0);
  const double y0 = sc->mesh.positions[1];  // the flat cloth's height
  const double drop = y0 - (top + gap);
  EXPECT_GT(drop, 0.0);
  const double speed = std::sqrt(2.0 * -sc->gravity[1] * drop);
  loom_test::init_state(*sc);
  State& st = sc->state;
  for (Index i = 0; i < st.size(); ++i) {
    st.x[3 * i + 1] -= drop;
    st.v[3 * i + 1] = -speed;
  }
  return sc;
}

constexpr int kSteps = 40;

double shipped_dt() { return shipped().child("integrator").get("dt", 0.0); }

struct Compared {
  double err = 0;    // max of the relative x and v differences
  double ex = 0, ev = 0;
  int contacts = 0;  // vertex contacts the CPU saw, summed over the steps
};

/// The shipped set-up on both backends for `steps` steps; the device integrator comes from the
/// scene's own integrator section plus `device_keys` (the one spec), the CPU plugin from the same.
Compared compare_shipped(int steps, const std::string& device_keys) {
  auto cpu = shipped_scene(1e-4);
  auto dev = shipped_scene(1e-4);
  const Params integ = shipped().child("integrator");
  SymplecticEuler ci(integ);
  auto di = lc::make_cuda_symplectic_euler(Params::from_string(device_keys, "<test>"));
  EXPECT_FALSE(ci.handles_contacts());
  EXPECT_TRUE(di->handles_contacts());  // the framework must not resolve them again on the host
  const double h = shipped_dt();
  ci.prepare(*cpu, h);
  di->prepare(*dev, h);
  Compared r;
  for (int k = 0; k < steps; ++k) {
    ci.step(*cpu, h);
    r.contacts += cpu->colliders.resolve_contacts(cpu->state, cpu->state.time, h);
    di->step(*dev, h);
  }
  di->sync_to_host(*dev);  // host_sync_every: 0 (the spec's default) copies only when asked
  EXPECT_EQ(di->last_step().force_evaluations, 1);
  EXPECT_DOUBLE_EQ(dev->state.time, cpu->state.time);
  r.ex = rel_diff(dev->state.x, cpu->state.x);
  r.ev = rel_diff(dev->state.v, cpu->state.v);
  r.err = std::max(r.ex, r.ev);
  std::printf("%s: %d steps, %d vertex contacts, x %.3g, v %.3g relative\n", device_keys.c_str(), steps, r.contacts,
              r.ex, r.ev);
  // Nothing left inside the ball (both backends resolve after the step).
  const bool single = device_keys.find("float") != std::string::npos;
  const Collider& ball = dev->colliders.colliders()[0];
  const Collider::Frame f = ball.frame_at(dev->state.time);
  for (Index i = 0; i < dev->state.size(); ++i)
    EXPECT_GE(ball.query(f, &dev->state.x[3 * i]).distance, single ? -1e-6 : -1e-12) << "vertex " << i;
  return r;
}

}  // namespace

// The shipped set-up, double: 40 steps of the shipped 5e-5 s, the cloth landing on the spinning
// ball (static and kinetic friction on a moving surface). The CPU sums each vertex's springs in
// its fused layout order and the device in its incidence order, so they differ by rounding only
// (measured: x 2e-32, v 4e-17 relative).
TEST(CudaSymplecticEuler, ShippedDrapedBallMatchesTheCpuBackend) {
  const Compared r = compare_shipped(kSteps, "{}");
  EXPECT_LE(r.err, 1e-10);
  EXPECT_GT(r.contacts, 500);  // measured 796: the patch under the ball top, growing from step 3
}

// Float on the device against the double CPU run, same set-up and horizon. Measured: x 2.1e-7
// relative (float's epsilon is 1.2e-7), v 3.2e-3 relative to the largest speed (about 1 m/s; 3.7e-3
// after 80 steps). v is the loose one: a float position is rounded by ~6e-8 m, which a 200 N/m
// spring on a 6.2e-6 kg particle turns into ~2 m/s^2, ~1e-4 m/s per step of 5e-5 s. Bounds:
// x 1e-6, v 1e-2.
TEST(CudaSymplecticEuler, ShippedDrapedBallFloatTracksDouble) {
  const Compared r = compare_shipped(kSteps, "{precision: float}");
  EXPECT_LE(r.ex, 1e-6);
  EXPECT_LE(r.ev, 1e-2);
  EXPECT_GT(r.err, 1e-12);  // it really ran in float
}

// Any material with a device description: GNATV wool (triangles, no springs: the CPU plugin's
// generic path), GNATV wool with hinge bending (BentMaterial: triangles plus a Hinge block) and a
// damped mass-spring cloth (the CPU plugin's fused path), two pinned corners.
TEST(CudaSymplecticEuler, DeviceDescribedMaterialsMatchTheCpuBackend) {
  struct Case {
    const char* what;
    bool wool, bent;
    double h;
    int steps;
  };
  std::vector<double> unbent_wool_x;  // the first case's CPU result
  for (const Case& c : {Case{"gnatv wool", true, false, 2e-5, 60}, Case{"bent gnatv wool", true, true, 2e-5, 60},
                        Case{"damped mass_spring", false, false, 1e-4, 100}}) {
    auto make = [&] {
      auto sc = std::make_unique<Scene>();
      sc->source = "<test>";
      sc->mesh = make_grid(9, 8, 1.0, 1.0, GridPlane::XZ);
      if (c.wool)
        sc->material = std::make_unique<gnatv::GnatvMaterial>(
            Params::from_string("material_file: " + std::string(LOOM_SOURCE_DIR) + "/materials/wool.yaml\n", "<test>"),
            sc->mesh);
      if (c.bent)
        sc->material = std::make_unique<BentMaterial>(std::move(sc->material), sc->mesh,
                                                      read_bending_options(Params::from_string("stiffness: 0.02\n")));
      if (!c.wool)
        sc->material = std::make_unique<mass_spring::MassSpringMaterial>(
            Params::from_string("stiffness: {structural: 2000, shear: 1500, bend: 100}\ndamping: 0.2\ndensity: 0.1\n",
                                "<test>"),
            sc->mesh);
      loom_cuda_test::init_perturbed_state(*sc, 9, 11, 0.002, 0.2);
      return sc;
    };
    auto cpu = make();
    auto dev = make();
    SymplecticEuler ci{Params()};
    auto di = lc::make_cuda_symplectic_euler(lc::Precision::Double);
    loom_cuda_test::run(ci, *cpu, c.h, c.steps);
    loom_cuda_test::run(*di, *dev, c.h, c.steps);
    EXPECT_EQ(ci.fused(), !c.wool) << c.what;
    if (c.wool && !c.bent) unbent_wool_x = cpu->state.x;
    if (c.bent) {  // the hinges matter over this run, so a device run without them would fail below
      const double bending = rel_diff(cpu->state.x, unbent_wool_x);
      std::printf("bending changes x by %.3g relative\n", bending);
      EXPECT_GT(bending, 1e-9);
    }
    EXPECT_GT(rel_diff(cpu->state.x, cpu->mesh.positions), 1e-5) << c.what;  // it moved
    EXPECT_LE(rel_diff(dev->state.x, cpu->state.x), 1e-12) << c.what;
    EXPECT_LE(rel_diff(dev->state.v, cpu->state.v), 1e-10) << c.what;
    // Fixed pins stay exactly where they are.
    for (Index p : {Index(0), Index(8)})
      for (int a = 0; a < 3; ++a) EXPECT_EQ(dev->state.x[3 * p + a], dev->mesh.positions[3 * p + a]) << c.what;
  }
}

// One spec for both backends: the device keys are declared by the cpu plugin's spec (honoured
// by cuda only), `reorder` by cpu only; the device factory reads them through it.
TEST(CudaSymplecticEuler, SharesTheCpuPluginSpec) {
  const ParamSpec& s = symplectic_euler::spec();
  ASSERT_NE(s.find("precision"), nullptr);
  ASSERT_NE(s.find("host_sync_every"), nullptr);
  ASSERT_NE(s.find("reorder"), nullptr);
  EXPECT_TRUE(s.find("precision")->honoured_by("cuda"));
  EXPECT_FALSE(s.find("precision")->honoured_by("cpu"));
  EXPECT_FALSE(s.find("reorder")->honoured_by("cuda"));
  EXPECT_NO_THROW(lc::make_cuda_symplectic_euler(Params::from_string("{precision: float, host_sync_every: 4}")));
  EXPECT_THROW(lc::make_cuda_symplectic_euler(Params::from_string("{precision: half}")), InputError);
  EXPECT_NO_THROW(lc::make_cuda_symplectic_euler(Params::from_string("{host_sync_every: 0}")));  // lazy, the default
  EXPECT_THROW(lc::make_cuda_symplectic_euler(Params::from_string("{host_sync_every: -1}")), InputError);
}

// Refused with the existing message naming the fix: self-collision. (Mesh colliders run on the
// device: tests/cuda/test_cuda_mesh_colliders.cpp.)
TEST(CudaSymplecticEuler, RefusalsNameTheFix) {
  auto expect_refusal = [](Scene& sc, const std::string& what) {
    auto di = lc::make_cuda_symplectic_euler(lc::Precision::Double);
    try {
      di->prepare(sc, 1e-4);
      ADD_FAILURE() << "expected InputError containing " << what;
    } catch (const InputError& e) {
      EXPECT_NE(std::string(e.what()).find(what), std::string::npos) << e.what();
      EXPECT_NE(std::string(e.what()).find("Fix:"), std::string::npos) << e.what();
    }
  };
  auto small = [] {
    auto sc = std::make_unique<Scene>();
    sc->source = "<test>";
    sc->mesh = make_grid(4, 4, 1.0, 1.0, GridPlane::XZ);
    sc->material = std::make_unique<mass_spring::MassSpringMaterial>(
        Params::from_string("stiffness: 100\ndensity: 0.1\n", "<test>"), sc->mesh);
    loom_cuda_test::init_perturbed_state(*sc, 4, 1, 0.0, 0.0);
    return sc;
  };
  {
    auto sc = small();
    SelfCollision::Options so;
    so.thickness = 0.002;
    sc->self_collision = std::make_unique<SelfCollision>(so, sc->mesh);
    expect_refusal(*sc, "does not handle self_collision");
  }
}

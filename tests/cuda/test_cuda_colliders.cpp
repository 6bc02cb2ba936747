// Sphere and plane colliders on the CUDA backend (issue 17), through the Thrust-OpenMP
// stand-in (and on a GPU as test_cuda_gpu): HO and RK4 runs with contacts against the CPU
// backend, whose ColliderSet::resolve_contacts runs after each step exactly as
// Simulation::step calls it; the shipped draped-ball ball (spinning, with friction); moving
// planes and spheres; the refusal of more colliders than the kernels carry. (Mesh colliders:
// test_cuda_mesh_colliders.cpp.)
#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <memory>
#include <string>
#include <vector>

#include "cuda_integrators.hpp"
#include "cuda_test_compare.hpp"
#include "cuda_test_scenes.hpp"
#include "ho_integrator.hpp"
#include "loom/scene.hpp"
#include "rk4_integrator.hpp"

using namespace loom;
namespace lc = loom::cuda;

namespace {

using loom_cuda_test::rel_diff;

/// The colliders of a shipped scene file.
ColliderSet shipped_colliders(const std::string& scene) {
  const Params root = Params::from_file(std::string(LOOM_SOURCE_DIR) + "/scenes/" + scene);
  return ColliderSet::parse(root.child("colliders"));
}

ColliderSet parse_colliders(const std::string& yaml) {
  return ColliderSet::parse(Params::from_string(yaml, "<test>").child("colliders"));
}

/// The falling cloth of cuda_test_scenes.hpp centred over (cx, cz), its plane at y0, falling at
/// `vy`, drifting along x at 0.3 m/s, seed 5.
std::unique_ptr<Scene> make_scene(const ColliderSet& colliders, Index nx, double cx, double y0, double cz, double vy) {
  return loom_cuda_test::falling_cloth(colliders, nx, cx, y0, cz, 0.3, vy, 5);
}

/// The CPU backend's step: the integrator, then the contacts (Simulation::step).
int cpu_step(Integrator& integ, Scene& sc, double h) {
  integ.step(sc, h);
  return sc.colliders.resolve_contacts(sc.state, sc.state.time, h);
}

/// Runs the same scene on both backends; returns the number of vertex contacts the CPU saw.
int compare(const ColliderSet& cols, const std::string& which, double y0, double vy, int steps, double tol,
            lc::Precision prec = lc::Precision::Double, double* err = nullptr) {
  auto cpu = make_scene(cols, 10, 0.5, y0, -0.5, vy);
  auto dev = make_scene(cols, 10, 0.5, y0, -0.5, vy);
  std::unique_ptr<Integrator> ci, di;
  if (which == "ho") {
    ci = std::make_unique<HoIntegrator>(HoVariant::Velocity);
    di = lc::make_cuda_ho(lc::HoVariantD::Velocity, prec);
  } else {
    ci = std::make_unique<Rk4Integrator>();
    di = lc::make_cuda_rk4(prec);
  }
  EXPECT_FALSE(ci->handles_contacts());
  EXPECT_TRUE(di->handles_contacts());  // the framework must not resolve them again on the host
  const double h = 2e-4;
  ci->prepare(*cpu, h);
  di->prepare(*dev, h);
  int contacts = 0;
  for (int k = 0; k < steps; ++k) {
    contacts += cpu_step(*ci, *cpu, h);
    di->step(*dev, h);
  }
  EXPECT_DOUBLE_EQ(dev->state.time, cpu->state.time);
  const double e = std::max(rel_diff(dev->state.x, cpu->state.x), rel_diff(dev->state.v, cpu->state.v));
  if (err) *err = e;
  EXPECT_LE(e, tol) << which;
  // Nothing left inside a collider (both backends resolve after the step).
  const double slack = prec == lc::Precision::Float ? 1e-6 : 1e-12;  // rounding of the projection
  for (const Collider& c : cols.colliders()) {
    const Collider::Frame f = c.frame_at(dev->state.time);
    for (Index i = 1; i < dev->state.size(); ++i)
      EXPECT_GE(c.query(f, &dev->state.x[3 * i]).distance, -slack) << c.name << " vertex " << i;
  }
  return contacts;
}

}  // namespace

class CudaColliders : public ::testing::TestWithParam<std::string> {};

// The shipped draped-ball ball: radius 0.3 m, spinning at 2 rad/s, friction 0.5 / 0.4. The
// cloth starts 2 mm into its offset surface, falling, so contacts (with sticking and
// sliding friction on a moving surface) start at the first step.
TEST_P(CudaColliders, ShippedSpinningBallMatchesTheCpuBackend) {
  const ColliderSet ball = shipped_colliders(GetParam() == "ho" ? "draped_ball_harmonic_oscillation.yaml"
                                                                : "draped_ball_rk4.yaml");
  ASSERT_EQ(ball.size(), 1u);
  ASSERT_EQ(ball.colliders()[0].shape, Collider::Shape::Sphere);
  ASSERT_NE(ball.colliders()[0].motion.type, RigidMotion::Type::Fixed);
  const double top = -0.35 + 0.3 + 0.004;
  const int contacts = compare(ball, GetParam(), top - 0.002, -0.5, 150, 1e-10);
  EXPECT_GT(contacts, 150);  // a patch of vertices in contact over the run
}

// A plane that tilts (keyframed rotation) and a sphere that translates through the cloth,
// a low friction on the sphere (sliding), a higher one on the plane.
TEST_P(CudaColliders, MovingPlaneAndSphereMatchTheCpuBackend) {
  const ColliderSet cols = parse_colliders(R"(colliders:
  - {type: plane, name: floor, point: [0.5, -0.02, -0.5], normal: [0.1, 1, 0], thickness: 0.001,
     friction: {static: 0.3, kinetic: 0.2},
     motion: {type: keyframes, axis: [0, 0, 1], keys: [{t: 0, angle: 0}, {t: 0.05, angle: 0.2, translate: [0, 0.01, 0]}]}}
  - {type: sphere, name: ball, center: [0.45, -0.1, -0.5], radius: 0.1, thickness: 0.002,
     friction: {static: 0.05, kinetic: 0.05}, motion: {type: translate, velocity: [0, 1.5, 0]}}
)");
  const int contacts = compare(cols, GetParam(), 0.0, -0.8, 200, 1e-10);
  EXPECT_GT(contacts, 200);
}

// Float on the device: the same contacts, to float rounding.
TEST_P(CudaColliders, FloatTracksDouble) {
  const ColliderSet ball = shipped_colliders("draped_ball_rk4.yaml");
  double err = 0;
  compare(ball, GetParam(), -0.35 + 0.3 + 0.002, -0.5, 100, 1e-3, lc::Precision::Float, &err);
  EXPECT_GT(err, 1e-12);  // it really ran in float
}

INSTANTIATE_TEST_SUITE_P(Integrators, CudaColliders, ::testing::Values("ho", "rk4"));

TEST(CudaColliders, RefusalsNameTheFix) {
  auto expect_refusal = [](Integrator& integ, Scene& sc, const std::string& what) {
    try {
      integ.prepare(sc, 1e-3);
      ADD_FAILURE() << "expected InputError containing " << what;
    } catch (const InputError& e) {
      EXPECT_NE(std::string(e.what()).find(what), std::string::npos) << e.what();
      EXPECT_NE(std::string(e.what()).find("Fix:"), std::string::npos) << e.what();
    }
  };
  // (Baraff-Witkin with colliders runs on the device: tests/cuda/test_cuda_bw_colliders.cpp;
  // mesh colliders: tests/cuda/test_cuda_mesh_colliders.cpp.)
  // More colliders than the kernels carry (kMaxDeviceColliders = 8): refused for every integrator.
  ColliderSet cols;
  for (int c = 0; c < 9; ++c) {
    Collider plane;
    plane.name = "floor" + std::to_string(c);
    plane.point = {0.0, -1.0 - c, 0.0};
    cols.add(plane);
  }
  for (const char* which : {"ho", "rk4", "se"}) {
    auto sc = make_scene(cols, 5, 0.5, 0.0, -0.5, 0.0);
    auto di = std::string(which) == "ho"    ? lc::make_cuda_ho(lc::HoVariantD::Velocity, lc::Precision::Double)
              : std::string(which) == "rk4" ? lc::make_cuda_rk4(lc::Precision::Double)
                                            : lc::make_cuda_symplectic_euler(lc::Precision::Double);
    expect_refusal(*di, *sc, "handles at most 8 colliders, the scene has 9");
  }
}

// The measurements of the PCG-tolerance study on contact scenes (bench/baraff_witkin/
// contact_tolerance.hpp, NUMERICS.md 3.6): the distance and penetration helpers against hand
// computations, and on a small wool drape onto a ball the one-step solve error of a tolerance
// against the one-step time-discretisation error (h vs two h/2 steps): at the default tolerance
// the solve error is at least 100 times below it (the criterion of the study), it grows as the
// tolerance is loosened, and no vertex ends inside the ball.
#include <gtest/gtest.h>

#include <cmath>
#include <vector>

#include "contact_tolerance.hpp"
#include "loom/filtered_pcg.hpp"

namespace ts = loom::tolerance_study;

// Two vertices, one moved by (3, 4, 0) (distance 5) and one not: RMS sqrt(25 / 2), largest 5,
// both over the width.
TEST(BwTolerance, DistanceIsRmsAndLargestVertexDistanceOverWidth) {
  const std::vector<double> a{0, 0, 0, 1, 1, 1}, b{3, 4, 0, 1, 1, 1};
  const ts::Distance d = ts::distance(a, b, 2.0);
  EXPECT_DOUBLE_EQ(d.rms, std::sqrt(12.5) / 2.0);
  EXPECT_DOUBLE_EQ(d.max, 2.5);
}

// Sphere of radius 0.3 at the drape's centre: a vertex 0.25 from the centre is 0.05 inside, one
// on the surface and one outside are not; the plane y = -0.01: a vertex at y = -0.03 is 0.02 below.
TEST(BwTolerance, PenetrationDepthOfSphereAndPlane) {
  ts::ContactScene sc = ts::drape(4, "type: gnatv, fabric: 11oz-black-denim", "d", 1);
  const double* c = sc.sphere_center;
  const std::vector<double> x{c[0], c[1] + 0.25, c[2], c[0] + 0.3, c[1], c[2], c[0], c[1] + 1.0, c[2]};
  EXPECT_NEAR(ts::depth_inside(sc, x), 0.05, 1e-15);
  ts::ContactScene pl = ts::fold(4, 1);
  const std::vector<double> y{0, -0.03, 0, 0, 0.5, 0};
  EXPECT_NEAR(ts::depth_inside(pl, y), 0.02, 1e-15);
}

// The wool drape at 16^2, 40 steps of 2 ms from the flat start on the ball (sa_amg).
TEST(BwTolerance, DefaultToleranceKeepsTheDrapeSolveErrorFarBelowTheSteppingError) {
  loom::Simulation::set_notes(false);
  const ts::ContactScene sc =
      ts::drape(16, "type: gnatv, material_file: " LOOM_SOURCE_DIR "/materials/wool.yaml", "drape16", 40);
  const ts::LocalErrors def = ts::local_errors(sc, loom::pcg::kDefaultTolerance, "sa_amg", sc.steps);
  const ts::LocalErrors loose = ts::local_errors(sc, 1e-2, "sa_amg", sc.steps);
  EXPECT_GT(def.mean_time, 0.0);
  EXPECT_LE(def.mean_solve, 1e-2 * def.mean_time);
  EXPECT_GT(loose.mean_solve, 10 * def.mean_solve);
  EXPECT_LT(loose.iterations_per_step, def.iterations_per_step);
  const ts::RunResult r = ts::run(sc, loom::pcg::kDefaultTolerance, "sa_amg", sc.dt, sc.steps);
  EXPECT_EQ(r.max_penetration, 0.0);
}

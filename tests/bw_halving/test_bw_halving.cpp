// on_solver_failure: halve_step replaces a failed step of h by two steps of h/2. Those must be
// the same two steps a run with dt = h/2 takes, also with moving colliders: the second half
// starts at t + h/2, so its contacts are found and projected with the colliders at t + h/2 and
// t + h (before the fix it used the first half's times, t and t + h/2).
#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <memory>
#include <string>
#include <vector>

#include "baraff_witkin.hpp"
#include "common/scene_state.hpp"
#include "eigen_ldlt.hpp"
#include "loom/mesh.hpp"
#include "loom/scene.hpp"
#include "mass_spring.hpp"

using namespace loom;

namespace {

/// EigenLdlt that refuses the next factorization when told to (a failed solve on demand).
class FailOnce final : public LinearSolver {
 public:
  bool fail_next = false;
  int failures = 0;
  std::string name() const override { return "fail_once"; }
  void analyze_pattern(const BsrMatrix& A, const Filter& S) override { inner_.analyze_pattern(A, S); }
  bool factorize(const BsrMatrix& A, const Filter& S, SolveReport& report) override {
    if (fail_next) {
      fail_next = false;
      ++failures;
      report.message = "refused on purpose (test)";
      return false;
    }
    return inner_.factorize(A, S, report);
  }
  SolveReport solve(const BsrMatrix& A, const Filter& S, std::span<const double> b, std::span<const double> z,
                    std::span<double> dv) override {
    return inner_.solve(A, S, b, z, dv);
  }

 private:
  EigenLdlt inner_;
};

/// A 9 x 9 cloth falling onto a floor that rises at 0.5 m/s and a sphere that slides sideways,
/// both with friction; the cloth starts 1 mm above the floor, so contacts start at once.
std::unique_ptr<Scene> make_scene() {
  auto sc = std::make_unique<Scene>();
  sc->source = "<test>";
  sc->mesh = make_grid(9, 9, 0.5, 0.5, GridPlane::XZ);
  sc->material = std::make_unique<mass_spring::MassSpringMaterial>(
      Params::from_string("stiffness: {structural: 300, shear: 300, bend: 30}\ndamping: 0.01\ndensity: 0.1\n", "<test>"),
      sc->mesh);
  loom_test::init_state(*sc);
  State& st = sc->state;
  for (Index i = 0; i < st.size(); ++i) {
    st.x[3 * i + 1] += 0.001;
    st.v[3 * i + 1] = -0.4;
    st.v[3 * i] = 0.2;
  }
  sc->colliders = ColliderSet::parse(Params::from_string(R"(colliders:
  - {type: plane, point: [0, 0, 0], normal: [0, 1, 0], friction: {static: 0.4, kinetic: 0.3},
     motion: {type: translate, velocity: [0, 0.5, 0]}}
  - {type: sphere, center: [0.25, 0.05, -0.25], radius: 0.06, friction: 0.2,
     motion: {type: translate, velocity: [1.0, 0, 0]}}
)", "<test>").child("colliders"));
  sc->solver = std::make_unique<FailOnce>();
  return sc;
}

double rel_diff(const std::vector<double>& a, const std::vector<double>& b) {
  double num = 0, den = 0;
  for (std::size_t k = 0; k < a.size(); ++k) {
    num = std::max(num, std::fabs(a[k] - b[k]));
    den = std::max(den, std::fabs(b[k]));
  }
  return num / den;
}

}  // namespace

TEST(BaraffWitkinHalving, HalvedStepEqualsTwoHalfStepsWithMovingColliders) {
  BaraffWitkinOptions o;
  o.on_failure = BaraffWitkinOptions::OnFailure::HalveStep;
  const double h = 0.01;
  // A: two steps of h, the second fails once and is halved.
  auto a = make_scene();
  BaraffWitkin ia(o);
  ia.prepare(*a, h);
  ia.step(*a, h);
  static_cast<FailOnce&>(*a->solver).fail_next = true;
  ia.step(*a, h);
  EXPECT_EQ(static_cast<FailOnce&>(*a->solver).failures, 1);
  EXPECT_EQ(ia.last_step().retries, 1);
  // B: one step of h, then two of h/2.
  auto b = make_scene();
  BaraffWitkin ib(o);
  ib.prepare(*b, h);
  ib.step(*b, h);
  ib.step(*b, 0.5 * h);
  ib.step(*b, 0.5 * h);
  EXPECT_DOUBLE_EQ(a->state.time, b->state.time);
  // The colliders moved the cloth: a corner (far from the sphere) rides the floor, which rose
  // 1 cm in the run.
  EXPECT_GT(a->state.x[1], 0.005);
  EXPECT_LE(rel_diff(a->state.x, b->state.x), 1e-13);
  EXPECT_LE(rel_diff(a->state.v, b->state.v), 1e-12);
}

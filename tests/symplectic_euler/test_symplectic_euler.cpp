// symplectic_euler with the mass_spring material: exact free-fall recurrence and its O(h)
// error, pins, energy behaviour, the linear stability limit, convergence order on a cloth.
#include <gtest/gtest.h>

#include <Eigen/Dense>
#include <algorithm>
#include <cmath>
#include <cstdio>
#include <cstring>
#include <memory>
#include <random>
#include <string>
#include <vector>

#include "loom/bsr.hpp"
#include "loom/mesh.hpp"
#include "loom/params.hpp"
#include "loom/scene.hpp"
#include "loom/state.hpp"
#include "mass_spring.hpp"
#include "symplectic_euler.hpp"
#include "common/scene_state.hpp"

using namespace loom;
using loom::mass_spring::MassSpringMaterial;
using loom::symplectic_euler::SymplecticEuler;

namespace {

std::unique_ptr<Scene> make_scene(const Mesh& mesh, const std::string& material_yaml, const std::vector<Index>& pins,
                                  std::array<double, 3> gravity) {
  auto sc = std::make_unique<Scene>();
  sc->source = "test";
  sc->mesh = mesh;
  Params p = Params::from_string(material_yaml, "material.yaml");
  sc->material = std::make_unique<MassSpringMaterial>(p, sc->mesh);
  p.check_unused();
  loom_test::init_state(*sc);
  for (Index i : pins) sc->state.pin(i);
  sc->gravity = gravity;
  return sc;
}

SymplecticEuler make_integrator() { return SymplecticEuler(Params::from_string("{}", "integrator.yaml")); }

// Serial (the test meshes are tiny; a parallel region per call only costs time).
double total_energy(const Scene& sc) {
  const State& s = sc.state;
  double e = sc.material->elastic_energy(s.x);
  for (Index i = 0; i < s.size(); ++i)
    for (int c = 0; c < 3; ++c)
      e += 0.5 * s.mass[i] * s.v[3 * i + c] * s.v[3 * i + c] - s.mass[i] * sc.gravity[c] * s.x[3 * i + c];
  return e;
}

// max |a - b|, NaN-aware (a NaN gives +inf).
double max_diff(const std::vector<double>& a, const std::vector<double>& b) {
  double m = 0;
  for (std::size_t q = 0; q < a.size(); ++q) {
    const double d = std::abs(a[q] - b[q]);
    if (!(d <= m)) m = std::isnan(d) ? INFINITY : d;
  }
  return m;
}

void perturb(std::vector<double>& x, double amplitude, unsigned seed) {
  std::mt19937 rng(seed);
  std::uniform_real_distribution<double> u(-amplitude, amplitude);
  for (double& c : x) c += u(rng);
}

// Largest eigenvalue of M^-1 K over the free vertices, K = -df/dx at the current state.
double lambda_max(Scene& sc) {
  auto& m = static_cast<MassSpringMaterial&>(*sc.material);
  std::vector<std::array<Index, 2>> pairs;
  m.jacobian_pairs(pairs);
  BsrPattern pat = BsrPattern::from_pairs(m.num_vertices(), pairs);
  m.bind_pattern(pat);
  BsrMatrix J(&pat);
  m.compute_jacobians(sc.state.x, sc.state.v, J, nullptr);
  const std::vector<double> d = J.to_dense();
  std::vector<Index> dofs;
  for (Index i = 0; i < sc.state.size(); ++i)
    if (sc.state.inv_mass[i] > 0)
      for (int c = 0; c < 3; ++c) dofs.push_back(3 * i + c);
  const Index n = static_cast<Index>(dofs.size()), N = 3 * sc.state.size();
  Eigen::MatrixXd A(n, n);
  for (Index r = 0; r < n; ++r)
    for (Index c = 0; c < n; ++c)
      A(r, c) = -d[static_cast<std::size_t>(dofs[r]) * N + dofs[c]] *
                std::sqrt(sc.state.inv_mass[dofs[r] / 3] * sc.state.inv_mass[dofs[c] / 3]);
  Eigen::SelfAdjointEigenSolver<Eigen::MatrixXd> es(A);
  return es.eigenvalues().maxCoeff();
}

}  // namespace

TEST(SymplecticEuler, FreeFallExactRecurrenceAndFirstOrderError) {
  const Mesh mesh = make_grid(4, 4, 1.0, 1.0, GridPlane::XZ);
  const double g = 9.81, T = 0.2;
  const double v0[3] = {0.3, 2.0, -0.1};
  double err[3];
  int r = 0;
  for (double h : {1e-3, 5e-4, 2.5e-4}) {
    auto sc = make_scene(mesh, "stiffness: 1000\ndensity: 0.1", {}, {0, -g, 0});
    for (Index i = 0; i < sc->state.size(); ++i)
      for (int c = 0; c < 3; ++c) sc->state.v[3 * i + c] = v0[c];
    SymplecticEuler se = make_integrator();
    se.prepare(*sc, h);
    const int n = static_cast<int>(std::lround(T / h));
    for (int k = 0; k < n; ++k) se.step(*sc, h);
    EXPECT_EQ(sc->state.step, n);
    EXPECT_NEAR(sc->state.time, T, 1e-12);
    EXPECT_EQ(se.last_step().force_evaluations, 1);
    const double t = n * h;
    double e = 0;
    for (Index i = 0; i < sc->state.size(); ++i) {
      for (int c = 0; c < 3; ++c) {
        const double x0 = mesh.positions[3 * i + c];
        // Symplectic Euler's exact recurrence: x_n = x_0 + v0 t - g h^2 n (n+1) / 2.
        const double rec = x0 + v0[c] * t - (c == 1 ? g * h * h * n * (n + 1) / 2.0 : 0.0);
        ASSERT_NEAR(sc->state.x[3 * i + c], rec, 1e-11) << "h " << h << " vertex " << i;
        const double exact = x0 + v0[c] * t - (c == 1 ? g * t * t / 2 : 0.0);
        e = std::max(e, std::abs(sc->state.x[3 * i + c] - exact));
      }
    }
    EXPECT_NEAR(e, g * h * t / 2, 1e-10);  // the error is exactly g h t / 2
    err[r++] = e;
  }
  std::printf("[ measured ] free fall: error %.3e %.3e %.3e (h = 1e-3, 5e-4, 2.5e-4), orders %.4f %.4f\n", err[0],
              err[1], err[2], std::log2(err[0] / err[1]), std::log2(err[1] / err[2]));
  EXPECT_NEAR(std::log2(err[0] / err[1]), 1.0, 0.01);
  EXPECT_NEAR(std::log2(err[1] / err[2]), 1.0, 0.01);
}

TEST(SymplecticEuler, PinnedVerticesStayFixedBitForBit) {
  const Mesh mesh = make_grid(8, 8, 1.0, 1.0, GridPlane::XZ);  // released flat: it falls and swings
  const std::vector<Index> pins = {mesh.grid->index(0, 7), mesh.grid->index(7, 7)};
  auto sc = make_scene(mesh, "stencil: structural_shear_bend\nstiffness: 2000", pins, {0, -9.81, 0});
  std::vector<double> before = sc->state.x;
  SymplecticEuler se = make_integrator();
  const double h = 2e-4;
  se.prepare(*sc, h);
  for (int k = 0; k < 3000; ++k) se.step(*sc, h);
  for (Index p : pins) {
    EXPECT_EQ(std::memcmp(&before[3 * p], &sc->state.x[3 * p], 3 * sizeof(double)), 0);
    EXPECT_EQ(sc->state.v[3 * p], 0.0);
  }
  // The cloth did move.
  EXPECT_LT(sc->state.x[3 * mesh.grid->index(3, 0) + 1], before[3 * mesh.grid->index(3, 0) + 1] - 0.3);
  EXPECT_TRUE(std::isfinite(sc->state.x[0]));
  EXPECT_LT(sc->material->max_strain(sc->state.x), 0.2);
}

TEST(SymplecticEuler, PinWithPrescribedVelocityMovesWithIt) {
  const Mesh mesh = make_grid(4, 4, 1.0, 1.0, GridPlane::XY);
  auto sc = make_scene(mesh, "stiffness: 500", {15}, {0, -9.81, 0});
  sc->state.v[3 * 15 + 0] = 0.5;  // prescribed pin velocity
  const double x0 = sc->state.x[3 * 15];
  SymplecticEuler se = make_integrator();
  se.prepare(*sc, 1e-3);
  for (int k = 0; k < 100; ++k) se.step(*sc, 1e-3);
  EXPECT_NEAR(sc->state.x[3 * 15], x0 + 0.05, 1e-13);
  EXPECT_EQ(sc->state.v[3 * 15], 0.5);
  EXPECT_EQ(sc->state.x[3 * 15 + 1], mesh.positions[3 * 15 + 1]);
}

TEST(SymplecticEuler, UndampedEnergyBoundedDampedDecays) {
  const Mesh mesh = make_grid(6, 6, 0.5, 0.5, GridPlane::XZ);
  double final_ratio[2];
  for (int damped = 0; damped < 2; ++damped) {
    auto sc = make_scene(mesh, std::string("stencil: radius_sqrt5\nstiffness: 1000\n") + (damped ? "damping: 0.05" : ""),
                         {}, {0, 0, 0});
    perturb(sc->state.x, 0.005, 17);  // small amplitude: 5% of the spacing
    const double theta = 0.2;  // h sqrt(lambda_max)
    const double h = theta / std::sqrt(lambda_max(*sc));
    SymplecticEuler se = make_integrator();
    se.prepare(*sc, h);
    const double e0 = total_energy(*sc);
    ASSERT_GT(e0, 0.0);
    double emax = e0, emin = e0, first = 0, last = 0;
    const int steps = 10000, window = 1000;
    for (int k = 0; k < steps; ++k) {
      se.step(*sc, h);
      const double e = total_energy(*sc);
      emax = std::max(emax, e);
      emin = std::min(emin, e);
      if (k < window) first += e / window;
      if (k >= steps - window) last += e / window;
    }
    final_ratio[damped] = last / e0;
    std::printf("[ measured ] %s: energy range %.4f of E0, mean last/first window %.5f, final/E0 %.4f\n",
                damped ? "damped" : "undamped", (emax - emin) / e0, last / first, last / e0);
    if (!damped) {
      // Symplectic: the energy error oscillates with O(h) amplitude (per mode, peak to peak at
      // most h omega) and does not drift.
      EXPECT_LT((emax - emin) / e0, theta);
      EXPECT_NEAR(last / first, 1.0, 0.02);
    } else {
      EXPECT_LT(emax, 1.01 * e0);
    }
  }
  EXPECT_LT(final_ratio[1], 0.5 * final_ratio[0]);
}

TEST(SymplecticEuler, StabilityLimitMatchesLinearAnalysis) {
  // At rest the springs' transverse stiffness vanishes, so K is exactly the linearisation.
  const Mesh mesh = make_grid(6, 6, 1.0, 1.0, GridPlane::XZ);
  const std::vector<Index> pins = {0, 5};
  for (double factor : {0.95, 1.05}) {
    auto sc = make_scene(mesh, "stencil: kang_cho_table1\nstiffness: 2000", pins, {0, 0, 0});
    const double hstar = 2.0 / std::sqrt(lambda_max(*sc));
    const double h = factor * hstar;
    std::vector<double> rest = sc->state.x;
    perturb(sc->state.x, 1e-7, 5);
    for (Index p : pins)
      for (int c = 0; c < 3; ++c) sc->state.x[3 * p + c] = rest[3 * p + c];
    SymplecticEuler se = make_integrator();
    se.prepare(*sc, h);
    for (int k = 0; k < 2000; ++k) se.step(*sc, h);
    const double amp = max_diff(sc->state.x, rest);
    std::printf("[ measured ] h* = %.4e, h = %.3f h*: amplitude after 2000 steps %.3e (from 1e-7)\n", hstar, factor, amp);
    if (factor < 1) EXPECT_LT(amp, 1e-5) << "h = " << h << " should be stable";
    else EXPECT_FALSE(amp < 1e-2) << "h = " << h << " should be unstable, amplitude " << amp;
  }
}

TEST(SymplecticEuler, FirstOrderOnHangingCloth) {
  const Mesh mesh = make_grid(5, 5, 1.0, 1.0, GridPlane::XZ);  // released flat, two corners pinned
  const std::vector<Index> pins = {mesh.grid->index(0, 4), mesh.grid->index(4, 4)};
  const double T = 0.1;
  auto run = [&](double h) {
    auto sc = make_scene(mesh, "stencil: structural_shear_bend\nstiffness: 500", pins, {0, -9.81, 0});
    SymplecticEuler se = make_integrator();
    se.prepare(*sc, h);
    const int n = static_cast<int>(std::lround(T / h));
    for (int k = 0; k < n; ++k) se.step(*sc, h);
    return sc->state.x;
  };
  const std::vector<double> ref = run(T / 12800);
  double err[3];
  int r = 0;
  for (int n : {200, 400, 800}) {
    const std::vector<double> x = run(T / n);
    double s = 0;
    for (std::size_t q = 0; q < x.size(); ++q) s += (x[q] - ref[q]) * (x[q] - ref[q]);
    err[r++] = std::sqrt(s / (x.size() / 3));
  }
  std::printf("[ measured ] pinned 5x5 cloth, t = 0.1 s: RMS error %.3e %.3e %.3e (h = T/200, /400, /800), orders %.3f %.3f\n",
              err[0], err[1], err[2], std::log2(err[0] / err[1]), std::log2(err[1] / err[2]));
  EXPECT_GT(err[0], 1e-6);  // a real error to measure
  EXPECT_NEAR(std::log2(err[0] / err[1]), 1.0, 0.15);
  EXPECT_NEAR(std::log2(err[1] / err[2]), 1.0, 0.15);
}

TEST(SymplecticEuler, StepBeforePrepareIsAnError) {
  const Mesh mesh = make_grid(3, 3, 1.0, 1.0);
  auto sc = make_scene(mesh, "{}", {}, {0, -9.81, 0});
  SymplecticEuler se = make_integrator();
  EXPECT_THROW(se.step(*sc, 1e-3), std::logic_error);
  Scene empty;
  EXPECT_THROW(se.prepare(empty, 1e-3), InputError);
}

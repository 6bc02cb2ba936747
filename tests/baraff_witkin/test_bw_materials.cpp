// baraff_witkin with the real materials: mass_spring at k = 1e6 and h = 0.01, the hanging
// 32x32 GNATV wool cloth of Strohkorb 2019 (settles; its sag converges as h halves), and a
// scene run through the plugin loader (the modules the CLI loads).
#include <gtest/gtest.h>
#include <omp.h>

#include <cmath>
#include <cstdio>
#include <memory>
#include <string>
#include <vector>

#include "baraff_witkin.hpp"
#include "eigen_ldlt.hpp"
#include "eigen_pcg.hpp"
#include "gnatv_material.hpp"
#include "loom/mesh.hpp"
#include "loom/params.hpp"
#include "loom/registry.hpp"
#include "loom/scene.hpp"
#include "loom/simulation.hpp"
#include "mass_spring.hpp"

namespace {

using loom::BaraffWitkin;
using loom::BaraffWitkinOptions;
using loom::Index;
using loom::Scene;

void init_state(Scene& sc, const std::vector<Index>& pins) {
  loom::State& s = sc.state;
  s.resize(sc.mesh.num_vertices());
  std::copy(sc.mesh.positions.begin(), sc.mesh.positions.end(), s.x.begin());
  sc.material->compute_masses(s.mass);
  for (Index p : pins) s.pin(p);
  s.update_inverse_masses();
}

std::unique_ptr<loom::LinearSolver> pcg(double tol) {
  loom::PcgOptions o;
  o.tolerance = tol;
  return std::make_unique<loom::EigenPcg>(o);
}

// The hanging wool cloth of scenes/wool_hanging_32.yaml: 10 m x 10 m, 32 x 32, top corners.
void wool_scene(Scene& sc, int n = 32) {
  sc.mesh = loom::make_grid(n, n, 10.0, 10.0, loom::GridPlane::XY);
  const loom::Params p = loom::Params::from_string(
      "material_file: " + std::string(LOOM_SOURCE_DIR) + "/materials/wool.yaml\n", "<test>");
  sc.material = std::make_unique<loom::gnatv::GnatvMaterial>(p, sc.mesh);
  init_state(sc, {(n - 1) * n, n * n - 1});
  sc.gravity = {0, -9.81, 0};
}

// The 32x32 wool runs below are serial: on the shared 2-core machine, with other builds
// running, every OpenMP barrier can cost a scheduler time slice and the test would take
// minutes instead of seconds. The threaded paths are covered by test_eigen_solvers (1 vs 2
// threads) and by the materials' own tests.
struct SerialScope {
  int saved = omp_get_max_threads();
  SerialScope() { omp_set_num_threads(1); }
  ~SerialScope() { omp_set_num_threads(saved); }
};

double kinetic(const loom::State& s) {  // serial (small; avoids OpenMP start-up on a loaded machine)
  double e = 0;
  for (Index i = 0; i < s.size(); ++i)
    for (int c = 0; c < 3; ++c) e += 0.5 * s.mass[i] * s.v[3 * i + c] * s.v[3 * i + c];
  return e;
}

}  // namespace

// mass_spring, NUMERICS.md 1.5 grid (10 x 10 over 0.9 m, 0.01 kg per vertex, structural +
// shear + bend springs) with k = 1e6, released flat, at h = 0.01: more than 100 times the
// explicit stability limit (7.2e-5 s). Bounded, no energy gain, the cloth falls and swings.
TEST(BaraffWitkinMaterials, MassSpringStiffnessOneMillionStaysBounded) {
  SerialScope serial;
  for (bool ldlt : {false, true}) {
    Scene sc;
    sc.mesh = loom::make_grid(10, 10, 0.9, 0.9, loom::GridPlane::XZ);
    const loom::Params p = loom::Params::from_string(
        "{stencil: structural_shear_bend, stiffness: 1.0e6, vertex_mass: 0.01, clamp_compressed: true}", "<test>");
    sc.material = std::make_unique<loom::mass_spring::MassSpringMaterial>(p, sc.mesh);
    init_state(sc, {90, 99});
    sc.gravity = {0, -9.81, 0};
    if (ldlt)
      sc.solver = std::make_unique<loom::EigenLdlt>();
    else
      sc.solver = pcg(1e-6);
    BaraffWitkin bw;
    const double h = 0.01;
    bw.prepare(sc, h);
    auto energy = [&] {
      double e = kinetic(sc.state) + sc.material->elastic_energy(sc.state.x);
      for (Index i = 0; i < sc.state.size(); ++i) e += sc.state.mass[i] * 9.81 * sc.state.x[3 * i + 1];
      return e;
    };
    const double e0 = energy();
    double emax = e0, strain = 0;
    for (int k = 0; k < 100; ++k) {
      bw.step(sc, h);
      emax = std::max(emax, energy());
      strain = std::max(strain, sc.material->max_strain(sc.state.x));
    }
    for (double v : sc.state.x) ASSERT_TRUE(std::isfinite(v));
    EXPECT_LE(emax, e0 + 1e-9) << (ldlt ? "eigen_ldlt" : "eigen_pcg");
    EXPECT_LT(strain, 0.01);
    EXPECT_LT(sc.state.x[1], -0.3);  // the free corner fell
  }
}

// The hanging wool cloth settles: kinetic energy in the second second is far below its
// first-half-second peak (scene parameters: h = 0.01, eigen_pcg 1e-5, Kang-Cho 0.01).
TEST(BaraffWitkinMaterials, HangingWoolClothSettles) {
  SerialScope serial;
  Scene sc;
  wool_scene(sc);
  sc.solver = pcg(1e-5);
  BaraffWitkinOptions o;
  o.kang_cho_damping = 0.01;
  BaraffWitkin bw(o);
  const double h = 0.01;
  bw.prepare(sc, h);
  double peak_early = 0, peak_late = 0;
  long iterations = 0;
  for (int k = 1; k <= 200; ++k) {
    bw.step(sc, h);
    iterations += bw.last_step().linear_iterations;
    EXPECT_LE(bw.last_step().linear_residual, 1e-5);
    const double ke = kinetic(sc.state);
    if (k <= 50) peak_early = std::max(peak_early, ke);
    if (k > 150) peak_late = std::max(peak_late, ke);
  }
  std::printf("kinetic energy: peak in [0, 0.5] s %.3g J, in [1.5, 2] s %.3g J; %.1f PCG iterations per step\n",
              peak_early, peak_late, iterations / 200.0);
  EXPECT_GT(peak_early, 1.0);                 // it really moved
  EXPECT_LT(peak_late, 0.3 * peak_early);     // and is settling
  // pins held, and the cloth hangs below them
  EXPECT_EQ(sc.state.x[3 * (31 * 32) + 1], 10.0);
  EXPECT_LT(sc.state.x[3 * 16 + 1], 0.0);
}

// Sag of the hanging wool cloth at t = 0.32 s converges as h halves (first order: the
// differences between successive halvings shrink by about 2). Exact solves (eigen_ldlt).
TEST(BaraffWitkinMaterials, WoolSagConvergesAsStepHalves) {
  SerialScope serial;
  const double T = 0.32;
  std::vector<double> sag;
  for (double h : {0.02, 0.01, 0.005, 0.0025}) {
    Scene sc;
    wool_scene(sc);
    sc.solver = std::make_unique<loom::EigenLdlt>();
    BaraffWitkin bw;
    bw.prepare(sc, h);
    const int steps = static_cast<int>(std::lround(T / h));
    for (int k = 0; k < steps; ++k) bw.step(sc, h);
    // sag: mean drop of the bottom row
    double s = 0;
    for (Index ix = 0; ix < 32; ++ix) s += sc.mesh.positions[3 * ix + 1] - sc.state.x[3 * ix + 1];
    sag.push_back(s / 32);
  }
  const double d1 = std::abs(sag[1] - sag[0]), d2 = std::abs(sag[2] - sag[1]), d3 = std::abs(sag[3] - sag[2]);
  std::printf("sag at t = %.2f s: %.5f %.5f %.5f %.5f m (h = 0.02 ... 0.0025); differences %.3g %.3g %.3g\n", T,
              sag[0], sag[1], sag[2], sag[3], d1, d2, d3);
  EXPECT_GT(sag[3], 0.05);  // it sagged
  EXPECT_LT(d2, 0.75 * d1);
  EXPECT_LT(d3, 0.7 * d2);
  EXPECT_GT(d3, 0.35 * d2);  // first order, not faster (a sanity check on the measurement)
}

// Through the plugin loader, as the CLI runs it: the scene's solver list, parameters nested
// under the solver's name, integrator parameters, and errors for unknown keys.
TEST(BaraffWitkinMaterials, SceneThroughPluginModules) {
  auto scene = [](const std::string& solver_section) {
    return std::string(R"(
mesh:
  grid: {nx: 8, ny: 8, width: 0.5, height: 0.5, plane: xy}
material:
  type: mass_spring
  stiffness: {structural: 2000, shear: 2000, bend: 100}
  density: 0.1
integrator:
  type: baraff_witkin
  dt: 0.01
  substeps: 5
  kang_cho_damping: 0.01
  rayleigh: {alpha: 0.1, beta: 0.0}
  on_solver_failure: halve_step
)") + solver_section + R"(
pins: [top_corners]
gravity: [0, -9.81, 0]
frames: 2
)";
  };
  const std::string yaml = scene(R"(solver:
  type: [eigen_pcg, eigen_ldlt]
  eigen_pcg: {tolerance: 1.0e-6, preconditioner: block_jacobi})");
  loom::Registry reg;
  loom::PluginLoader loader(reg);
  auto sim = loom::Simulation::from_string(yaml, "bw_test.yaml", ".", {}, loader);
  EXPECT_EQ(sim->integrator_name(), "baraff_witkin");
  EXPECT_EQ(sim->solver_name(), "eigen_pcg");
  const std::vector<double> x0 = sim->scene().state.x;
  sim->advance_frame();
  sim->advance_frame();
  const loom::StepStats st = sim->integrator().last_step();
  EXPECT_GT(st.linear_iterations, 0);
  EXPECT_LE(st.linear_residual, 1e-6);
  EXPECT_NEAR(sim->scene().state.time, 0.1, 1e-12);
  for (Index p : sim->scene().state.pin_list)
    for (int c = 0; c < 3; ++c) EXPECT_EQ(sim->scene().state.x[3 * p + c], x0[3 * p + c]);

  // the direct solver, and typos rejected with a hint
  auto ldlt = loom::Simulation::from_string(
      scene("solver:\n  type: eigen_ldlt\n  eigen_ldlt: {pivot_tolerance: 1.0e-14}"), "bw_test.yaml", ".", {}, loader);
  EXPECT_EQ(ldlt->solver_name(), "eigen_ldlt");
  ldlt->step();
  auto error_of = [&](const std::vector<std::string>& sets) {
    try {
      loom::Simulation::from_string(yaml, "bw_test.yaml", ".", sets, loader);
    } catch (const loom::InputError& e) {
      return std::string(e.what());
    }
    return std::string();
  };
  EXPECT_NE(error_of({"solver.eigen_pcg.tolerence=1e-3"}).find("tolerance"), std::string::npos);
  EXPECT_NE(error_of({"integrator.kang_cho_dampin=1"}).find("kang_cho_damping"), std::string::npos);
  EXPECT_NE(error_of({"integrator.on_solver_failure=retry"}).find("halve_step"), std::string::npos);
  EXPECT_NE(error_of({"solver.eigen_pcg.preconditioner=ilu"}).find("block_jacobi"), std::string::npos);
}

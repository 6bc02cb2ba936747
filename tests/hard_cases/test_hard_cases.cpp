// Hard cases (issue 6's atlas, as regression tests). Each case expects ONE outcome, decided
// beforehand by analysis: an explicit run is expected to complete when its step is below the
// method's linear stability bound sqrt(lambda_max(M^-1 K)) h <= c (docs/NUMERICS.md sec. 1.5;
// lambda_max from estimate_step_limit's power iteration, an independent computation), and to
// diverge (DivergenceError naming the vertex) when it is far above it; an implicit run completes
// when its system is positive definite and fails in the solver (SolverError) when it is not.
// None may leave NaN in the state. The real plugins are loaded from the build tree, as the CLI
// loads them.
#include <gtest/gtest.h>

#include <cmath>
#include <filesystem>
#include <fstream>

#include "loom/simulation.hpp"
#include "loom/stability.hpp"

namespace {

enum class Outcome { Completed, Diverged, SolverFailed };

struct Case {
  std::string name;
  std::string yaml;
  int frames;
};

Outcome run_case(const std::string& yaml, int frames, std::string& message, loom::PluginLoader& loader) {
  // A source name inside scenes/ so that relative paths (../materials/wool.yaml) resolve.
  const std::string src = std::string(LOOM_SOURCE_DIR) + "/scenes/hard_case.yaml";
  auto sim = loom::Simulation::from_string(yaml, src, std::string(LOOM_SOURCE_DIR) + "/scenes", {}, loader);
  Outcome o = Outcome::Completed;
  try {
    for (int f = 0; f < frames; ++f) sim->advance_frame();
  } catch (const loom::DivergenceError& e) {
    o = Outcome::Diverged;
    message = e.what();
  } catch (const loom::SolverError& e) {
    o = Outcome::SolverFailed;
    message = e.what();
  }
  if (o == Outcome::Completed) {
    // the state a frame would write is finite, and within the guard's speed bound
    for (double c : sim->scene().state.x) EXPECT_TRUE(std::isfinite(c));
    for (double c : sim->scene().state.v) EXPECT_LT(std::abs(c), sim->guard().max_velocity);
  }
  return o;
}

// sqrt(lambda_max(M^-1 K)) h at the scene's initial state for the explicit integrator named
// (the integrator's own c is in StepLimit::factor: 2 for symplectic Euler, 2 sqrt(2) for RK4,
// sqrt(2) for HO, the safe end of its bracket).
struct Limit {
  double theta = 0;   // sqrt(lambda_max) h
  double factor = 0;  // the method's bound c
};
Limit step_limit(const std::string& yaml, const std::string& integrator, double h, loom::PluginLoader& loader) {
  const std::string src = std::string(LOOM_SOURCE_DIR) + "/scenes/hard_case.yaml";
  auto sim = loom::Simulation::from_string(yaml, src, std::string(LOOM_SOURCE_DIR) + "/scenes", {}, loader);
  const auto lim = loom::estimate_step_limit(sim->scene(), integrator);
  if (!lim) return {};
  return {std::sqrt(lim->lambda_max) * h, lim->factor};
}

struct HardCases : ::testing::Test {
  loom::Registry registry;
  loom::PluginLoader loader{registry};
};

const char* kCloth = R"(
mesh: {grid: {nx: 12, ny: 12, width: 1.0, height: 1.0, plane: xz}}
material: {type: mass_spring, stencil: structural_shear_bend, stiffness: STIFF, density: 0.1}
pins: [top_corners]
)";

std::string cloth(double k, const std::string& integrator, const std::string& extra = "") {
  std::string s = kCloth;
  s.replace(s.find("STIFF"), 5, std::to_string(k));
  return s + "integrator: " + integrator + "\n" + extra;
}

}  // namespace

TEST_F(HardCases, StiffSpringsPastTheExplicitLimitStopWithTheDivergenceError) {
  // k = 1e8, m ~ 7e-4 kg: sqrt(lambda) h ~ 1e3 at h = 1e-3: symplectic Euler must blow up.
  std::string msg;
  const Outcome o = run_case(cloth(1e8, "{type: symplectic_euler, dt: 1.0e-3, substeps: 5}"), 10, msg, loader);
  EXPECT_EQ(o, Outcome::Diverged);
  EXPECT_NE(msg.find("diverged at step"), std::string::npos) << msg;
  EXPECT_NE(msg.find("vertex"), std::string::npos) << msg;
}

TEST_F(HardCases, StiffSpringsWithLargeImplicitStepsStayBounded) {
  std::string msg;
  const Outcome o = run_case(cloth(1e8, "{type: baraff_witkin, dt: 0.01, substeps: 2}",
                                   "solver: {type: eigen_ldlt}\n"), 10, msg, loader);
  EXPECT_EQ(o, Outcome::Completed) << msg;
}

TEST_F(HardCases, HeavyVerticesAgainstALightCloth) {
  // Two corners a million times heavier than the rest, free (not pinned). Heavy vertices only
  // lower lambda_max(M^-1 K) (their rows are scaled by 1/m), so every explicit step here is
  // inside its stability bound (checked below, not assumed), and Baraff-Witkin's system
  // M - h df/dv - h^2 df/dx is positive definite with the compression clamp on: every run
  // completes. (HO runs at half the others' step: at 2e-4 it sits at sqrt(lambda) h = 1.41, on
  // the lower end sqrt(2) of its bound's bracket, where the analysis cannot decide.)
  const std::string heavy = "mass_scale: [{group: bottom_corners, factor: 1.0e6}]\n";
  struct Run {
    const char* type;
    const char* integrator;
    double h;
  };
  for (const Run r : {Run{"symplectic_euler", "{type: symplectic_euler, dt: 2.0e-4, substeps: 20}", 2e-4},
                      Run{"harmonic_oscillation", "{type: harmonic_oscillation, dt: 1.0e-4, substeps: 40}", 1e-4},
                      Run{"rk4", "{type: rk4, dt: 2.0e-4, substeps: 20}", 2e-4},
                      Run{"baraff_witkin", "{type: baraff_witkin, dt: 0.004}", 0.004}}) {
    const std::string yaml = cloth(2000, r.integrator, heavy + "solver: {type: eigen_pcg}\n");
    if (std::string(r.type) != "baraff_witkin") {
      const Limit lim = step_limit(yaml, r.type, r.h, loader);
      ASSERT_GT(lim.factor, 0) << r.type;
      ASSERT_LT(lim.theta, 0.8 * lim.factor) << r.type << ": the case no longer tests a stable step";
    }
    std::string msg;
    EXPECT_EQ(run_case(yaml, 5, msg, loader), Outcome::Completed) << r.integrator << ": " << msg;
  }
}

TEST_F(HardCases, CrumpledStartWithAndWithoutTheCompressionClamp) {
  // Start at half size: every spring compressed by 50%, so the unclamped Jacobian is indefinite.
  std::string msg;
  std::string s = cloth(2000, "{type: baraff_witkin, dt: 0.01}", "initial_scale: 0.5\nsolver: {type: eigen_pcg}\n");
  EXPECT_EQ(run_case(s, 5, msg, loader), Outcome::Completed) << msg;
  std::string unclamped = s;
  unclamped.replace(unclamped.find("density: 0.1"), 12, "density: 0.1, clamp_compressed: false");
  msg.clear();
  // Without the clamp, a spring at half its rest length has transverse stiffness
  // k (1 - l0/l) = -k, so each vertex's diagonal block of M + h^2 K has the eigenvalue
  // m - h^2 k n_springs < 0 (m ~ 7e-4 kg, h^2 k = 0.2 N/m s^2): the system is indefinite and the
  // PCG's block-Jacobi preconditioner must refuse it at the first step, saying why.
  const Outcome o = run_case(unclamped, 5, msg, loader);
  EXPECT_EQ(o, Outcome::SolverFailed) << msg;
  EXPECT_NE(msg.find("not positive"), std::string::npos) << msg;
  EXPECT_NE(msg.find("at step 0"), std::string::npos) << msg;
}

TEST_F(HardCases, HighSpeedImpactOnThePins) {
  // The whole cloth moving at 30 m/s when the two pinned corners hold it.
  const std::string fast = "initial_velocity: [0, 0, 30]\nsolver: {type: eigen_ldlt}\n";
  std::string msg;
  EXPECT_EQ(run_case(cloth(2000, "{type: baraff_witkin, dt: 0.002, substeps: 5}", fast), 5, msg, loader),
            Outcome::Completed) << msg;
  // Symplectic Euler at h = 1e-4 is inside its bound (checked): it is then a symplectic map of a
  // bounded-energy system, so the 45 J of kinetic energy (0.1 kg at 30 m/s) is exchanged with the
  // springs without growing and no vertex reaches the guard's 1000 m/s
  // (sqrt(2 E / m_vertex) ~ 730 m/s even if one vertex took it all).
  const std::string se = cloth(2000, "{type: symplectic_euler, dt: 1.0e-4, substeps: 20}", fast);
  const Limit lim = step_limit(se, "symplectic_euler", 1e-4, loader);
  ASSERT_LT(lim.theta, 0.8 * lim.factor);
  msg.clear();
  EXPECT_EQ(run_case(se, 5, msg, loader), Outcome::Completed) << msg;
}

TEST_F(HardCases, WoolStretchedFarBeyondTheMeasuredCurves) {
  // Gravity x 100 on the wool cloth: strains far past the last measured sample, where the
  // curves continue linearly with their end slope.
  const std::string yaml = R"(
mesh: {grid: {nx: 10, ny: 10, width: 1.0, height: 1.0, plane: xy}}
material: {type: gnatv, material_file: ../materials/wool.yaml}
integrator: {type: baraff_witkin, dt: 0.01, substeps: 2}
solver: {type: eigen_pcg}
pins: [top_edge]
gravity: [0, -981, 0]
)";
  std::string msg;
  loom::PluginLoader& l = loader;
  const Outcome o = run_case(yaml, 10, msg, l);
  EXPECT_EQ(o, Outcome::Completed) << msg;
}

TEST_F(HardCases, NearDegenerateTriangles) {
  // A unit square plus one sliver triangle on its top edge: vertex 4 lies 1e-5 above the middle
  // of the pinned edge 0-1. Its mass is rho A / 3 with A = 5e-6 m^2, while the membrane
  // stiffness it feels scales like A / height^2: lambda_max(M^-1 K) ~ 1/height^2 ~ 1e10 times
  // that of a well-shaped triangle. RK4 at h = 1e-4 is then thousands of times past its bound
  // 2 sqrt(2) (checked) and must stop at its first steps naming vertex 4; Baraff-Witkin is
  // unconditionally stable on the clamped (positive definite) system and completes.
  const auto dir = std::filesystem::temp_directory_path() / "loom_hard_sliver";
  std::filesystem::create_directories(dir);
  std::ofstream(dir / "sliver.obj") << "v 0 1 0\nv 1 1 0\nv 0 0 0\nv 1 0 0\nv 0.5 1.00001 0\n"
                                       "f 1 3 4\nf 1 4 2\nf 1 2 5\n";
  auto yaml = [&](const std::string& integ) {
    return "mesh: {obj: " + (dir / "sliver.obj").string() +
           "}\nmaterial: {type: gnatv, material_file: ../materials/wool.yaml}\nintegrator: " + integ +
           "\nsolver: {type: eigen_ldlt}\npins: [{vertices: [0, 1]}]\n";
  };
  const std::string rk4 = yaml("{type: rk4, dt: 1.0e-4, substeps: 10}");
  const Limit lim = step_limit(rk4, "rk4", 1e-4, loader);
  ASSERT_GT(lim.theta, 100 * lim.factor) << "the sliver no longer makes the explicit step unstable";
  std::string msg;
  EXPECT_EQ(run_case(rk4, 5, msg, loader), Outcome::Diverged) << msg;
  EXPECT_NE(msg.find("vertex 4"), std::string::npos) << msg;
  msg.clear();
  EXPECT_EQ(run_case(yaml("{type: baraff_witkin, dt: 0.005}"), 5, msg, loader), Outcome::Completed) << msg;
}

// Hard cases (issue 6's atlas, as regression tests): every run either stays finite and
// bounded to the end, or stops with a DivergenceError / SolverError. None may leave NaN in
// the state. The real plugins are loaded from the build tree, as the CLI loads them.
#include <gtest/gtest.h>

#include <cmath>
#include <filesystem>
#include <fstream>

#include "loom/simulation.hpp"

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
  // Two corners a million times heavier than the rest, free (not pinned): every integrator
  // either runs to the end or stops cleanly.
  const std::string heavy = "mass_scale: [{group: bottom_corners, factor: 1.0e6}]\n";
  for (const std::string integ : {"{type: symplectic_euler, dt: 2.0e-4, substeps: 20}",
                                  "{type: harmonic_oscillation, dt: 2.0e-4, substeps: 20}",
                                  "{type: rk4, dt: 2.0e-4, substeps: 20}", "{type: baraff_witkin, dt: 0.004}"}) {
    std::string msg;
    const Outcome o = run_case(cloth(2000, integ, heavy + "solver: {type: eigen_pcg}\n"), 5, msg, loader);
    EXPECT_TRUE(o == Outcome::Completed || o == Outcome::Diverged) << integ << ": " << msg;
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
  const Outcome o = run_case(unclamped, 5, msg, loader);
  // Either the solver notices the indefinite system (and says so), or the step still works.
  if (o == Outcome::SolverFailed) {
    EXPECT_FALSE(msg.empty());
  } else {
    EXPECT_EQ(o, Outcome::Completed) << msg;
  }
}

TEST_F(HardCases, HighSpeedImpactOnThePins) {
  // The whole cloth moving at 30 m/s when the two pinned corners hold it.
  const std::string fast = "initial_velocity: [0, 0, 30]\nsolver: {type: eigen_ldlt}\n";
  std::string msg;
  EXPECT_EQ(run_case(cloth(2000, "{type: baraff_witkin, dt: 0.002, substeps: 5}", fast), 5, msg, loader),
            Outcome::Completed) << msg;
  msg.clear();
  const Outcome o = run_case(cloth(2000, "{type: symplectic_euler, dt: 1.0e-4, substeps: 20}", fast), 5, msg, loader);
  EXPECT_TRUE(o == Outcome::Completed || o == Outcome::Diverged) << msg;
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
  // A strip with one sliver triangle (height 1e-5 of its base) under gnatv and RK4 / BW.
  const auto dir = std::filesystem::temp_directory_path() / "loom_hard_sliver";
  std::filesystem::create_directories(dir);
  std::ofstream(dir / "sliver.obj") << "v 0 1 0\nv 1 1 0\nv 0 0 0\nv 1 0 0\nv 2 1.00001 0\n"
                                       "f 1 3 4\nf 1 4 2\nf 2 4 5\n";
  for (const std::string integ : {"{type: rk4, dt: 1.0e-4, substeps: 10}", "{type: baraff_witkin, dt: 0.005}"}) {
    const std::string yaml = "mesh: {obj: " + (dir / "sliver.obj").string() +
                             "}\nmaterial: {type: gnatv, material_file: ../materials/wool.yaml}\nintegrator: " + integ +
                             "\nsolver: {type: eigen_ldlt}\npins: [{vertices: [0, 1]}]\n";
    std::string msg;
    const Outcome o = run_case(yaml, 5, msg, loader);
    EXPECT_TRUE(o == Outcome::Completed || o == Outcome::Diverged) << integ << ": " << msg;
  }
}

#include <gtest/gtest.h>

#include <omp.h>

#include <cmath>
#include <cstdlib>
#include <filesystem>
#include <fstream>
#include <iterator>
#include <string>

#include "loom/restart.hpp"
#include "loom/simulation.hpp"
#include "loom/thread_controller.hpp"
#include "loom/threads.hpp"

namespace fs = std::filesystem;

namespace {

const char* kBase = R"(
mesh:
  grid: {nx: 4, ny: 3, width: 1.0, height: 0.5}
material:
  type: test_gravity_only
  mass: 0.5
integrator:
  type: test_explicit_euler
  dt: 0.01
  substeps: 5
pins: [top_corners]
gravity: [0, -10, 0]
frames: 4
)";

struct Fixture : ::testing::Test {
  loom::Registry reg;
  loom::PluginLoader loader{reg, {LOOM_TEST_PLUGIN_DIR}};
  std::unique_ptr<loom::Simulation> make(const std::string& yaml, const std::vector<std::string>& sets = {}) {
    return loom::Simulation::from_string(yaml, "test.yaml", "", sets, loader);
  }
  std::string error_of(const std::string& yaml, const std::vector<std::string>& sets = {}) {
    try {
      make(yaml, sets);
    } catch (const loom::InputError& e) {
      return e.what();
    }
    return "";
  }
};

}  // namespace

TEST_F(Fixture, BuildsTheNamedCombo) {
  auto sim = make(kBase);
  EXPECT_EQ(sim->scene().state.size(), 12);
  EXPECT_EQ(sim->scene().state.pin_list.size(), 2u);
  EXPECT_DOUBLE_EQ(sim->dt(), 0.01);
  EXPECT_EQ(sim->substeps(), 5);
  EXPECT_EQ(sim->frames(), 4);
  EXPECT_EQ(sim->scene().gravity[1], -10.0);
  const auto lines = sim->describe();
  EXPECT_NE(lines[1].find("12 vertices"), std::string::npos);
}

TEST_F(Fixture, FreeFallMatchesForwardEulerRecurrenceAndPinsStayBitForBit) {
  auto sim = make(kBase);
  const auto x0 = sim->scene().state.x;
  for (int f = 0; f < 4; ++f) sim->advance_frame();
  const auto& st = sim->scene().state;
  EXPECT_EQ(st.step, 20);
  EXPECT_NEAR(st.time, 0.2, 1e-15);
  // forward Euler: y_n = y_0 - g h^2 n(n-1)/2
  const double h = 0.01, n = 20;
  for (loom::Index i = 0; i < st.size(); ++i) {
    if (st.pinned[i]) {
      for (int k = 0; k < 3; ++k) EXPECT_EQ(st.x[3 * i + k], x0[3 * i + k]);
    } else {
      EXPECT_NEAR(st.x[3 * i + 1], x0[3 * i + 1] - 10 * h * h * n * (n - 1) / 2, 1e-12);
    }
  }
}

TEST_F(Fixture, OverridesApply) {
  auto sim = make(kBase, {"integrator.dt=0.002", "frames=7", "gravity=[0,0,-1]"});
  EXPECT_DOUBLE_EQ(sim->dt(), 0.002);
  EXPECT_EQ(sim->frames(), 7);
  EXPECT_EQ(sim->scene().gravity[2], -1.0);
  EXPECT_NE(error_of(kBase, {"integrator.dt"}).find("key=value"), std::string::npos);
  EXPECT_NE(error_of(kBase, {"integrator.dt=-1"}).find("> 0"), std::string::npos);
}

TEST_F(Fixture, BadInputIsOneClearError) {
  std::string base = kBase;
  auto with = [&](const std::string& from, const std::string& to) {
    std::string s = base;
    const auto p = s.find(from);
    EXPECT_NE(p, std::string::npos) << from;
    return s.replace(p, from.size(), to);
  };
  std::string e = error_of(with("frames: 4", "frmaes: 4"));
  EXPECT_NE(e.find("test.yaml:"), std::string::npos) << e;
  EXPECT_NE(e.find("did you mean 'frames'"), std::string::npos) << e;
  e = error_of(with("dt: 0.01", "dt: 0"));
  EXPECT_NE(e.find("test.yaml:9"), std::string::npos) << e;
  e = error_of(with("dt: 0.01", "dt: .nan"));
  EXPECT_NE(e.find("finite"), std::string::npos) << e;
  e = error_of(with("mass: 0.5", "mass: -1"));
  EXPECT_NE(e.find("test.yaml:6"), std::string::npos) << e;
  e = error_of(with("type: test_gravity_only", "type: test_gravty_only"));
  EXPECT_NE(e.find("did you mean 'test_gravity_only'"), std::string::npos) << e;
  e = error_of(with("pins: [top_corners]", "pins: [top_corner]"));
  EXPECT_NE(e.find("did you mean 'top_corners'"), std::string::npos) << e;
  e = error_of(with("pins: [top_corners]", "pins: [{vertices: [0, 99]}]"));
  EXPECT_NE(e.find("out of range"), std::string::npos) << e;
  e = error_of(with("gravity: [0, -10, 0]", "gravity: [0, -10]"));
  EXPECT_NE(e.find("3 components"), std::string::npos) << e;
  e = error_of(with("nx: 4", "nx: 1"));
  EXPECT_NE(e.find("nx and ny"), std::string::npos) << e;
  e = error_of(with("substeps: 5", "substeps: 0"));
  EXPECT_NE(e.find(">= 1"), std::string::npos) << e;
  e = error_of(with("substeps: 5", "substeps: 2.5"));
  EXPECT_NE(e.find("integer"), std::string::npos) << e;
  e = error_of("material: {type: test_gravity_only}\n");
  EXPECT_NE(e.find("missing 'mesh'"), std::string::npos) << e;
  e = error_of(with("  grid: {nx: 4, ny: 3, width: 1.0, height: 0.5}", "  obj: missing.obj"));
  EXPECT_NE(e.find("not found"), std::string::npos) << e;
  e = error_of(base + "backend: cuda\n");
  EXPECT_NE(e.find("backend 'cuda' is not in this build"), std::string::npos) << e;
  EXPECT_NE(e.find("loom_backend_cuda.so"), std::string::npos) << e;
  e = error_of(base + "backend: gpu\n");
  EXPECT_NE(e.find("cpu, cuda"), std::string::npos) << e;
}

TEST_F(Fixture, ImpossibleCombosAreRefusedWithTheFix) {
  auto with_needs = [&](const std::string& what) {
    std::string s = kBase;
    s.replace(s.find("type: test_explicit_euler"), 25, "type: test_needs_all\n  needs: " + what);
    return s;
  };
  std::string e = error_of(with_needs("solver"));
  EXPECT_NE(e.find("needs a linear solver"), std::string::npos) << e;
  EXPECT_NE(e.find("solver: {type: eigen_pcg}"), std::string::npos) << e;
  e = error_of(with_needs("springs"));
  EXPECT_NE(e.find("has no springs"), std::string::npos) << e;
  e = error_of(with_needs("jacobian"));
  EXPECT_NE(e.find("needs force Jacobians"), std::string::npos) << e;
  // a solver list falls back to the first available one
  auto sim = make(with_needs("solver") + "solver:\n  type: [not_built_here, test_identity]\n  test_identity: {scale: 2}\n");
  EXPECT_EQ(sim->solver_name(), "test_identity");
  e = error_of(with_needs("solver") + "solver:\n  type: [nope_a, nope_b]\n");
  EXPECT_NE(e.find("none of the solvers [nope_a, nope_b]"), std::string::npos) << e;
  EXPECT_NE(e.find("test_identity"), std::string::npos) << e;
  e = error_of(with_needs("solver") + "solver:\n  type: test_identity\n  test_identity: {scael: 2}\n");
  EXPECT_NE(e.find("did you mean 'scale'"), std::string::npos) << e;
}

TEST_F(Fixture, DivergenceNamesStepVertexValueAndKeepsFrames) {
  const fs::path out = fs::temp_directory_path() / "loom_test_diverge";
  fs::remove_all(out);
  std::string s = kBase;
  s.replace(s.find("type: test_explicit_euler"), 25, "type: test_explicit_euler\n  blow_up_at: 12");
  auto sim = make(s);
  sim->output().dir = out.string();
  try {
    sim->run();
    FAIL() << "expected divergence";
  } catch (const loom::DivergenceError& e) {
    const std::string m = e.what();
    EXPECT_NE(m.find("step 13"), std::string::npos) << m;
    EXPECT_NE(m.find("vertex 5"), std::string::npos) << m;
    EXPECT_NE(m.find("max_velocity"), std::string::npos) << m;
  }
  // frames 0, 1 and 2 (steps 0, 5, 10) were written before step 13, and no temporary file is left
  EXPECT_TRUE(fs::exists(out / "frame_00002.obj"));
  EXPECT_FALSE(fs::exists(out / "frame_00003.obj"));
  int files = 0;
  for (const auto& f : fs::directory_iterator(out)) {
    ++files;
    EXPECT_EQ(f.path().string().find(".tmp"), std::string::npos);
  }
  EXPECT_EQ(files, 7);  // 3 frames + stats.csv + scene.yaml + restart.bin + the run's lock file .loom.lock
  // The restart point is the last complete frame (loom run --resume continues from it).
  const loom::RestartData restart = loom::read_restart(out.string());
  EXPECT_EQ(restart.frame, 2);
  EXPECT_EQ(restart.step, 10);
  std::ifstream stats(out / "stats.csv");
  std::string line;
  int lines = 0;
  while (std::getline(stats, line)) ++lines;
  EXPECT_EQ(lines, 4);  // header + 3 frames

  std::string n = kBase;
  n.replace(n.find("type: test_explicit_euler"), 25, "type: test_explicit_euler\n  nan_at: 3");
  auto sim2 = make(n);
  try {
    for (int f = 0; f < 4; ++f) sim2->advance_frame();
    FAIL() << "expected divergence";
  } catch (const loom::DivergenceError& e) {
    const std::string m = e.what();
    EXPECT_NE(m.find("vertex 7"), std::string::npos) << m;
    EXPECT_NE(m.find("not finite"), std::string::npos) << m;
  }
}

// loom run --resume hands the restart point's state to the integrator: one that keeps x and v to
// itself between steps (the CUDA backend; here the test integrator's own_copy) continues from
// the resumed frame, not from the state it took when the scene was built. The resumed run's last
// frame equals the uninterrupted run's, with and without the own copy.
TEST_F(Fixture, ResumeHandsTheRestartStateToAnIntegratorWithItsOwnCopy) {
  for (bool own : {false, true}) {
    std::string s = kBase;
    if (own) s.replace(s.find("type: test_explicit_euler"), 25, "type: test_explicit_euler\n  own_copy: true");
    const fs::path full = fs::temp_directory_path() / ("loom_test_resume_full" + std::to_string(own));
    const fs::path part = fs::temp_directory_path() / ("loom_test_resume_part" + std::to_string(own));
    fs::remove_all(full);
    fs::remove_all(part);
    auto a = make(s);
    a->output().dir = full.string();
    a->run();
    auto b = make(s, {"frames=2"});
    b->output().dir = part.string();
    b->run();
    auto c = make(s, {"frames=2"});
    c->output().dir = part.string();
    EXPECT_EQ(c->resume(4), 2);
    c->run();
    const auto text = [](const fs::path& f) {
      std::ifstream in(f);
      return std::string((std::istreambuf_iterator<char>(in)), {});
    };
    const std::string want = text(full / "frame_00004.obj"), got = text(part / "frame_00004.obj");
    ASSERT_FALSE(want.empty());
    EXPECT_EQ(got, want) << "own copy " << own;
    EXPECT_NE(text(full / "frame_00002.obj"), want);   // the cloth moved between frames 2 and 4
  }
}

// A program that changes the state between steps (sync_state(), change, state_changed()) gets the
// same steps from an integrator with its own copy as from one without.
TEST_F(Fixture, StateChangedHandsTheProgramsStateToTheIntegrator) {
  std::vector<double> x[2];
  for (bool own : {false, true}) {
    std::string s = kBase;
    if (own) s.replace(s.find("type: test_explicit_euler"), 25, "type: test_explicit_euler\n  own_copy: true");
    auto sim = make(s);
    for (int k = 0; k < 3; ++k) sim->step();
    sim->sync_state();
    sim->scene().state.v[3 * 6] += 2.0;   // a kick to vertex 6 (free)
    sim->state_changed();
    for (int k = 0; k < 3; ++k) sim->step();
    sim->sync_state();
    x[own] = sim->scene().state.x;
  }
  ASSERT_EQ(x[0].size(), x[1].size());
  EXPECT_EQ(x[1], x[0]);
  EXPECT_GT(std::abs(x[0][3 * 6] - x[0][3 * 5]), 0.0);
}

TEST_F(Fixture, RunWritesObjFramesAndStats) {
  const fs::path out = fs::temp_directory_path() / "loom_test_run";
  fs::remove_all(out);
  auto sim = make(kBase);
  sim->output().dir = out.string();
  int calls = 0;
  sim->run([&](int, int) { ++calls; });
  EXPECT_EQ(calls, 4);
  for (int f = 0; f <= 4; ++f) {
    char name[32];
    std::snprintf(name, sizeof(name), "frame_%05d.obj", f);
    ASSERT_TRUE(fs::exists(out / name)) << name;
  }
  std::ifstream obj(out / "frame_00004.obj");
  int v = 0, faces = 0;
  std::string line;
  while (std::getline(obj, line)) {
    if (line.rfind("v ", 0) == 0) ++v;
    if (line.rfind("f ", 0) == 0) ++faces;
  }
  EXPECT_EQ(v, 12);
  EXPECT_EQ(faces, 12);
  std::ifstream stats(out / "stats.csv");
  std::getline(stats, line);
  EXPECT_EQ(line.rfind("frame,time,kinetic_energy", 0), 0u);
}

TEST_F(Fixture, UnwritableOutputFolderIsBadInput) {
  auto sim = make(kBase);
  sim->output().dir = "/proc/loom_cannot_write_here";
  EXPECT_THROW(sim->run(), loom::InputError);
}

// threads: auto attaches the step-time controller (loom/thread_controller.hpp) unless a count,
// OMP_NUM_THREADS (which ctest sets) or a single usable core decides; Simulation::step applies
// the controller's count.
TEST_F(Fixture, ThreadsAutoAdaptsOnlyWhenNothingElseDecides) {
  const char* env = std::getenv("OMP_NUM_THREADS");
  const std::string saved = env ? env : "";
  const int saved_threads = omp_get_max_threads();
  unsetenv("OMP_NUM_THREADS");
  {
    auto sim = make(kBase, {"threads=auto"});
    ASSERT_EQ(sim->thread_controller() != nullptr, loom::usable_cores() > 1);
    for (int f = 0; f < 4; ++f) sim->advance_frame();
    if (const auto* tc = sim->thread_controller()) {
      EXPECT_EQ(omp_get_max_threads(), tc->threads());
      EXPECT_GT(tc->elapsed(), 0.0);
      // 12 vertices, below kParallelMinVertices: the steps start on 1 thread (choose_start_threads).
      EXPECT_EQ(tc->initial(), 1);
      EXPECT_EQ(sim->scene().threads, 1);
    }
    EXPECT_EQ(make(kBase, {"threads=1"})->thread_controller(), nullptr);
  }
  setenv("OMP_NUM_THREADS", "2", 1);
  EXPECT_EQ(make(kBase, {"threads=auto"})->thread_controller(), nullptr);
  if (env)
    setenv("OMP_NUM_THREADS", saved.c_str(), 1);
  else
    unsetenv("OMP_NUM_THREADS");
  omp_set_num_threads(saved_threads);
}

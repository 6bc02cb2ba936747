// `loom study`: orders measured against the halving-checked reference, unstable runs marked,
// stability bisection brackets the linear limit.
#include <gtest/gtest.h>

#include "common/csv_table.hpp"

#include <cmath>
#include <cstdio>
#include <filesystem>
#include <fstream>
#include <map>
#include <sstream>
#include <sys/wait.h>

namespace fs = std::filesystem;

namespace {

const char* kScene = R"(mesh:
  grid: {nx: 5, ny: 5, width: 0.4, height: 0.4, plane: xz}
material: {type: mass_spring, stencil: structural_shear_bend, stiffness: 200, vertex_mass: 0.01}
integrator: {type: symplectic_euler, dt: 0.001}
threads: 1
pins: [top_corners]
)";

int run(const std::string& args, std::string& out) {
  const std::string cmd = std::string(LOOM_EXE) + " " + args + " 2>&1";
  FILE* p = popen(cmd.c_str(), "r");
  char buf[4096];
  while (fgets(buf, sizeof buf, p)) out += buf;
  const int st = pclose(p);
  return WIFEXITED(st) ? WEXITSTATUS(st) : -1;
}

std::vector<std::map<std::string, std::string>> read_csv(const fs::path& p) {
  return loom_test::read_csv_table(p).by_name();
}

// An empty folder under the temporary directory with the test scene in it.
fs::path fresh_dir(const std::string& name) {
  const fs::path dir = fs::temp_directory_path() / name;
  fs::remove_all(dir);
  fs::create_directories(dir);
  std::ofstream(dir / "scene.yaml") << kScene;
  return dir;
}

}  // namespace

TEST(Study, MeasuresOrdersAgainstTheReferenceAndMarksUnstableRuns) {
  const fs::path dir = fresh_dir("loom_test_study");
  std::ofstream(dir / "study.yaml") << R"(times: [0.05]
steps: {h0: 2.0e-3, levels: 3}
reference: {integrator: rk4, dt: 1.25e-5}
combos:
  - {name: SE, set: {integrator.type: symplectic_euler}}
  - {name: RK4, set: {integrator.type: rk4}}
  - {name: SE stiff, set: {integrator.type: symplectic_euler, material.stiffness: 2.0e5}}
)";
  std::string out;
  const int code = run("study " + (dir / "scene.yaml").string() + " " + (dir / "study.yaml").string() + " --out " +
                           (dir / "out").string(), out);
  ASSERT_EQ(code, 0) << out;
  const auto rows = read_csv(dir / "out" / "study.csv");
  ASSERT_EQ(rows.size(), 9u) << out;
  // SE: order ~1 between the last rungs; RK4: order ~4
  EXPECT_NEAR(std::stod(rows[2].at("observed_order")), 1.0, 0.15);
  EXPECT_NEAR(std::stod(rows[5].at("observed_order")), 4.0, 0.3);
  EXPECT_LT(std::stod(rows[5].at("rms_error")), 1e-8);
  for (int k = 0; k < 6; ++k) EXPECT_EQ(rows[k].at("status"), "ok");
  // k = 2e5 with m = 0.01 at h = 2e-3 is far past symplectic Euler's limit: not "ok", and kept
  EXPECT_NE(rows[6].at("status"), "ok");
  EXPECT_GT(std::stoll(rows[2].at("force_evaluations")), 0);
  std::ifstream ref(dir / "out" / "reference.txt");
  std::string all((std::istreambuf_iterator<char>(ref)), {});
  EXPECT_NE(all.find("RMS change on halving"), std::string::npos);
}

TEST(Study, StabilityBisectionBracketsTheLimit) {
  const fs::path dir = fresh_dir("loom_test_stability");
  std::ofstream(dir / "study.yaml") << R"(stability:
  horizon: 0.2
  h_min: 1.0e-5
  h_max: 0.05
  bisections: 10
  sweep: {key: material.stiffness, values: [200, 2000]}
  combos: [{name: SE, set: {integrator.type: symplectic_euler}}]
)";
  std::string out;
  const int code = run("study " + (dir / "scene.yaml").string() + " " + (dir / "study.yaml").string() + " --stability --out " +
                           (dir / "out").string(), out);
  ASSERT_EQ(code, 0) << out;
  const auto rows = read_csv(dir / "out" / "stability.csv");
  ASSERT_EQ(rows.size(), 2u);
  const double h200 = std::stod(rows[0].at("h_stable")), h2000 = std::stod(rows[1].at("h_stable"));
  EXPECT_GT(h200, 0.0);
  EXPECT_LT(h200, std::stod(rows[0].at("h_unstable")));
  // the limit scales as 1/sqrt(k): ten times the stiffness, sqrt(10) times smaller step
  EXPECT_NEAR(h200 / h2000, std::sqrt(10.0), 0.35 * std::sqrt(10.0));
}

TEST(Study, BadStudyFileIsAClearError) {
  const fs::path dir = fresh_dir("loom_test_study_bad");
  std::ofstream(dir / "study.yaml") << "times: [0.05]\nsteps: {h0: 3.0e-3, levels: 2}\ncombos: [{name: SE}]\n";
  std::string out;
  EXPECT_EQ(run("study " + (dir / "scene.yaml").string() + " " + (dir / "study.yaml").string() + " --out " +
                    (dir / "out").string(), out), 2);
  EXPECT_NE(out.find("not a whole number of steps"), std::string::npos) << out;
  out.clear();
  std::ofstream(dir / "study2.yaml") << "times: [0.05]\nsteps: {h0: 1.0e-3}\ncombos: [{name: X, set: {integrator.type: nope}}]\n";
  EXPECT_EQ(run("study " + (dir / "scene.yaml").string() + " " + (dir / "study2.yaml").string(), out), 2);
  EXPECT_NE(out.find("combo 'X' does not build"), std::string::npos) << out;
  EXPECT_NE(out.find("study2.yaml:3"), std::string::npos) << out;
}

// Folder names reach python3 (the plot) as arguments, never through a shell: a name that
// would run a command under `sh -c` is inert.
TEST(Study, HostileFolderNameIsInert) {
  const fs::path base = fs::temp_directory_path() / "loom_test_study_hostile";
  fs::remove_all(base);
  const fs::path marker = base / "PWNED";
  const fs::path dir = base / ("x'; touch " + marker.string() + "; echo '");
  fs::create_directories(dir);
  std::ofstream(dir / "scene.yaml") << kScene;
  std::ofstream(dir / "study.yaml") << R"(times: [0.02]
steps: {h0: 2.0e-3, levels: 2}
reference: {integrator: rk4, dt: 1.0e-4}
combos:
  - {name: SE, set: {integrator.type: symplectic_euler}}
)";
  auto quote = [](const std::string& t) {
    std::string q = "'";
    for (char c : t) q += c == '\'' ? std::string("'\\''") : std::string(1, c);
    return q + "'";
  };
  std::string out;
  const int code = run("study " + quote((dir / "scene.yaml").string()) + " " + quote((dir / "study.yaml").string()) +
                           " --out " + quote((dir / "out").string()), out);
  ASSERT_EQ(code, 0) << out;
  EXPECT_TRUE(fs::exists(dir / "out" / "study.csv")) << out;
  EXPECT_FALSE(fs::exists(marker)) << "a folder name ran a shell command";
  // The plot itself is drawn when python3 with matplotlib is installed (scripts/setup.sh installs it).
  EXPECT_TRUE(fs::exists(dir / "out" / "study.png")) << out;
}

// run_stability used to mark every key of the study file used: a typo at the top level passed
// silently. Now only the declared sections are accepted.
TEST(Study, StabilityRefusesAMisspelledTopLevelKey) {
  const fs::path dir = fresh_dir("loom_test_stability_typo");
  std::ofstream(dir / "study.yaml") << R"(times: [0.05]
stability:
  horizon: 0.01
  combos: [{name: SE, set: {integrator.type: symplectic_euler}}]
stabilty_note: a typo of a key nobody reads
)";
  std::string out;
  EXPECT_EQ(run("study " + (dir / "scene.yaml").string() + " " + (dir / "study.yaml").string() + " --stability --out " +
                    (dir / "out").string(), out), 2) << out;
  EXPECT_NE(out.find("stabilty_note"), std::string::npos) << out;
  EXPECT_NE(out.find("study.yaml:5"), std::string::npos) << out;
}

// A run that reaches max_seconds_per_run before failing or reaching the horizon decides
// nothing: it is reported as a timeout, not counted as stable (it used to give h_stable = h_max).
TEST(Study, StabilityRunThatTimesOutIsNotCountedStable) {
  const fs::path dir = fresh_dir("loom_test_stability_timeout");
  // 1000 steps at h_max; the clock is checked every 256 steps, and 1 ns has passed by then.
  std::ofstream(dir / "study.yaml") << R"(stability:
  horizon: 1.0
  h_min: 1.0e-4
  h_max: 1.0e-3
  max_seconds_per_run: 1.0e-9
  combos: [{name: SE, set: {integrator.type: symplectic_euler}}]
)";
  std::string out;
  ASSERT_EQ(run("study " + (dir / "scene.yaml").string() + " " + (dir / "study.yaml").string() + " --stability --out " +
                    (dir / "out").string(), out), 0) << out;
  const auto rows = read_csv(dir / "out" / "stability.csv");
  ASSERT_EQ(rows.size(), 1u);
  EXPECT_EQ(rows[0].at("status"), "timeout");
  EXPECT_EQ(std::stod(rows[0].at("h_stable")), 0.0) << "a timed-out run was counted as stable";
  EXPECT_EQ(rows[0].at("runs"), "1");
  EXPECT_NE(rows[0].at("failure").find("timeout at h = 0.001"), std::string::npos) << rows[0].at("failure");
}

// The reference's change on halving is reported (reference.txt's last line and the CLI's
// summary), as the largest of the per-time changes reference.txt lists.
TEST(Study, ReferenceChangeOnHalvingIsReported) {
  const fs::path dir = fresh_dir("loom_test_study_reference");
  std::ofstream(dir / "study.yaml") << R"(times: [0.02, 0.04]
steps: {h0: 2.0e-3, levels: 1}
reference: {integrator: symplectic_euler, dt: 1.0e-4}
combos: [{name: SE, set: {integrator.type: symplectic_euler}}]
)";
  std::string out;
  ASSERT_EQ(run("study " + (dir / "scene.yaml").string() + " " + (dir / "study.yaml").string() + " --out " +
                    (dir / "out").string(), out), 0) << out;
  std::ifstream ref(dir / "out" / "reference.txt");
  double largest_listed = 0, reported = -1;
  int per_time = 0;
  for (std::string line; std::getline(ref, line);) {
    const std::string a = "RMS change on halving = ", b = "largest RMS change on halving = ";
    if (line.rfind(b, 0) == 0) {
      reported = std::stod(line.substr(b.size()));
    } else if (const auto p = line.find(a); p != std::string::npos) {
      largest_listed = std::max(largest_listed, std::stod(line.substr(p + a.size())));
      ++per_time;
    }
  }
  EXPECT_EQ(per_time, 2);
  // A first-order reference at 1e-4 moves by O(h) on halving: not zero, and far from O(1).
  EXPECT_GT(largest_listed, 0.0);
  EXPECT_LT(largest_listed, 1e-2);
  EXPECT_NEAR(reported, largest_listed, 1e-6 * largest_listed);
  EXPECT_NE(out.find("the reference changes by"), std::string::npos) << out;
}

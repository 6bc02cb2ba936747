// End-to-end tests of the `loom` executable: exit codes, files, messages.
#include <gtest/gtest.h>

#include <sched.h>

#include <cctype>
#include <cstdlib>

#include "cli_run.hpp"

#include <array>
#include <cstdio>
#include <filesystem>
#include <fstream>
#include <sys/wait.h>

namespace fs = std::filesystem;

namespace {

using loom_cli_test::Result;
Result run(const std::string& args, bool test_plugins = true) { return loom_cli_test::run_loom(args, test_plugins); }
fs::path scratch(const std::string& name) { return loom_cli_test::scratch_dir("loom_cli_", name); }

std::string write_scene(const fs::path& dir, const std::string& text, const std::string& name = "scene.yaml") {
  std::ofstream(dir / name) << text;
  return (dir / name).string();
}

const char* kScene = R"(mesh:
  grid: {nx: 5, ny: 5, width: 1.0, height: 1.0}
material:
  type: test_gravity_only
integrator:
  type: test_explicit_euler
  dt: 0.01
  substeps: 4
pins: [top_edge]
frames: 3
)";

// `loom ARGS` (the build's plugins) exits with 2 (bad input), its output holding every one of
// `says` and none of `not_says`.
void expect_refused(const std::string& args, std::initializer_list<std::string> says,
                    std::initializer_list<std::string> not_says = {}) {
  const Result r = run(args, false);
  EXPECT_EQ(r.code, 2) << args << "\n" << r.out;
  for (const auto& t : says) EXPECT_NE(r.out.find(t), std::string::npos) << t << "\n" << r.out;
  for (const auto& t : not_says) EXPECT_EQ(r.out.find(t), std::string::npos) << t << "\n" << r.out;
}

}  // namespace

TEST(Cli, HelpVersionAndUsageErrors) {
  EXPECT_EQ(run("--help").code, 0);
  EXPECT_NE(run("--help").out.find("loom run SCENE.yaml"), std::string::npos);
  EXPECT_EQ(run("--version").code, 0);
  Result r = run("");
  EXPECT_EQ(r.code, 2);
  EXPECT_NE(r.out.find("missing command"), std::string::npos) << r.out;
  r = run("rnu x.yaml");
  EXPECT_EQ(r.code, 2);
  EXPECT_NE(r.out.find("did you mean 'run'"), std::string::npos) << r.out;
  r = run("run x.yaml --fames 3");
  EXPECT_EQ(r.code, 2);
  EXPECT_NE(r.out.find("did you mean '--frames'"), std::string::npos) << r.out;
  r = run("run x.yaml --frames -3");
  EXPECT_EQ(r.code, 2);
  r = run("run x.yaml --set novalue");
  EXPECT_EQ(r.code, 2);
  EXPECT_NE(r.out.find("key=value"), std::string::npos) << r.out;
  r = run("run");
  EXPECT_EQ(r.code, 2);
  EXPECT_NE(r.out.find("needs a scene file"), std::string::npos) << r.out;
}

TEST(Cli, ValidatePrintsTheCombo) {
  const auto dir = scratch("validate");
  const Result r = run("validate " + write_scene(dir, kScene));
  EXPECT_EQ(r.code, 0) << r.out;
  EXPECT_NE(r.out.find("25 vertices, 32 triangles"), std::string::npos) << r.out;
  EXPECT_NE(r.out.find("test_explicit_euler"), std::string::npos) << r.out;
  EXPECT_NE(r.out.find("pins:       5 vertices"), std::string::npos) << r.out;
  EXPECT_NE(r.out.find("ok: the scene is valid"), std::string::npos) << r.out;
}

TEST(Cli, RunWritesFramesStatsAndResolvedScene) {
  const auto dir = scratch("run");
  const Result r = run("run " + write_scene(dir, kScene) + " --out " + (dir / "out").string() +
                       " --frames 2 --set integrator.dt=0.005");
  EXPECT_EQ(r.code, 0) << r.out;
  EXPECT_TRUE(fs::exists(dir / "out" / "frame_00000.obj"));
  EXPECT_TRUE(fs::exists(dir / "out" / "frame_00002.obj"));
  EXPECT_FALSE(fs::exists(dir / "out" / "frame_00003.obj"));
  EXPECT_TRUE(fs::exists(dir / "out" / "stats.csv"));
  std::ifstream sc(dir / "out" / "scene.yaml");
  std::string all((std::istreambuf_iterator<char>(sc)), {});
  EXPECT_NE(all.find("dt: 0.005"), std::string::npos) << all;
  // no progress bar when stdout is not a terminal
  EXPECT_EQ(r.out.find("\r["), std::string::npos);
}

TEST(Cli, BadInputExitsWith2AndNamesFileAndLine) {
  const auto dir = scratch("bad");
  std::string s = kScene;
  Result r = run("run " + write_scene(dir, s + "frames: [\n", "syntax.yaml"));
  EXPECT_EQ(r.code, 2);
  EXPECT_NE(r.out.find("syntax.yaml:"), std::string::npos) << r.out;
  EXPECT_NE(r.out.find("YAML syntax error"), std::string::npos) << r.out;
  r = run("run " + write_scene(dir, std::string(kScene) + "gravty: [0, -9.81, 0]\n", "key.yaml"));
  EXPECT_EQ(r.code, 2);
  EXPECT_NE(r.out.find("key.yaml:11"), std::string::npos) << r.out;
  EXPECT_NE(r.out.find("did you mean 'gravity'"), std::string::npos) << r.out;
  r = run("run " + (dir / "missing.yaml").string());
  EXPECT_EQ(r.code, 2);
  EXPECT_NE(r.out.find("not found"), std::string::npos) << r.out;
  r = run("run " + write_scene(dir, kScene) + " --out /proc/loom_not_writable");
  EXPECT_EQ(r.code, 2);
  EXPECT_NE(r.out.find("--out"), std::string::npos) << r.out;
  std::string nan_dt = kScene;
  nan_dt.replace(nan_dt.find("dt: 0.01"), 8, "dt: .nan");
  r = run("validate " + write_scene(dir, nan_dt, "nan.yaml"));
  EXPECT_EQ(r.code, 2);
  EXPECT_NE(r.out.find("nan.yaml:7"), std::string::npos) << r.out;
  // plugins not on the path: the error lists what is available
  r = run("validate " + write_scene(dir, kScene), false);
  EXPECT_EQ(r.code, 2);
  EXPECT_NE(r.out.find("unknown material 'test_gravity_only'"), std::string::npos) << r.out;
}

// A scene whose integrator or material type is switched keeps the keys of the plugin before:
// the error names the plugin that declares the key and how to drop it (from the file: a
// --set KEY=null; from a --set: drop it). A key no plugin declares gets no such sentence.
// This test needs only mass_spring, symplectic_euler and rk4 (the sanitizer build has them):
// `reorder` is a key of symplectic_euler, not of rk4.
TEST(Cli, KeyOfAnotherPluginNamesItsOwnerAndTheFix) {
  const std::string listed = run("plugins", false).out;
  for (const char* p : {"mass_spring", "symplectic_euler", "rk4"})
    if (listed.find(p) == std::string::npos) GTEST_SKIP() << p << " is not in this build";
  const auto dir = scratch("key_owner");
  const std::string scene = write_scene(dir, R"(mesh:
  grid: {nx: 5, ny: 5, width: 1.0, height: 1.0}
material: {type: mass_spring, stiffness: 100}
integrator:
  type: rk4
  dt: 1.0e-4
  reorder: rcm
frames: 2
)");
  expect_refused("validate " + scene,
                 {"scene.yaml:7: unknown key 'reorder' in 'integrator'", "'reorder' is a key of integrator ",
                  "'symplectic_euler'", "not of 'rk4': a scene switched to another integrator",
                  "Fix: remove it from the scene, or run with --set integrator.reorder=null."});
  const Result r = run("validate " + scene + " --set integrator.reorder=null", false);  // the fix works
  EXPECT_EQ(r.code, 0) << r.out;
  const std::string hanging = std::string(LOOM_SOURCE_DIR) + "/scenes/hanging_cloth.yaml";
  expect_refused("validate " + hanging + " --set integrator.type=rk4 --set integrator.reorder=none",
                 {"--set integrator.reorder=none: unknown key 'reorder'", "not of 'rk4'. Fix: drop that --set."});
  // a key no plugin declares: no owner named
  expect_refused("validate " + hanging + " --set integrator.dampin=0.1", {"unknown key 'dampin'"}, {"is a key of"});
}

// The same on the shipped Baraff-Witkin scenes switched to another integrator or material.
TEST(Cli, ShippedSceneSwitchedToAnotherPluginNamesTheKeysOwner) {
  const std::string listed = run("plugins", false).out;
  for (const char* p : {"mass_spring", "symplectic_euler", "rk4", "gnatv", "baraff_witkin"})
    if (listed.find(p) == std::string::npos) GTEST_SKIP() << p << " is not in this build";
  const std::string ball = std::string(LOOM_SOURCE_DIR) + "/scenes/draped_mesh_sphere_gnatv_bw.yaml";
  expect_refused("validate " + ball + " --set integrator.type=rk4",
                 {"draped_mesh_sphere_gnatv_bw.yaml:21: unknown key 'kang_cho_damping'",
                  "is a key of integrator 'baraff_witkin', not of 'rk4'", "--set integrator.kang_cho_damping=null"});
  // with that key dropped, the next one of baraff_witkin is named in turn
  expect_refused("validate " + ball + " --set integrator.type=rk4 --set integrator.kang_cho_damping=null",
                 {"unknown key 'on_solver_failure'", "--set integrator.on_solver_failure=null"});
  const std::string se = std::string(LOOM_SOURCE_DIR) + "/scenes/draped_ball_symplectic_euler.yaml";
  expect_refused("validate " + se + " --set material.type=gnatv --set material.material_file=../materials/wool.yaml",
                 {"unknown key 'stencil'", "is a key of material 'mass_spring', not of 'gnatv'"});
  expect_refused("validate " + se + " --set integrator.kang_cho_damping=0.1",
                 {"is a key of integrator 'baraff_witkin', not of 'symplectic_euler'. Fix: drop that --set."});
}

TEST(Cli, DivergenceExitsWith3AndKeepsEarlierFrames) {
  const auto dir = scratch("diverge");
  std::string s = kScene;
  s.replace(s.find("type: test_explicit_euler"), 25, "type: test_explicit_euler\n  blow_up_at: 6");
  const Result r = run("run " + write_scene(dir, s) + " --out " + (dir / "out").string());
  EXPECT_EQ(r.code, 3) << r.out;
  EXPECT_NE(r.out.find("diverged at step 7"), std::string::npos) << r.out;
  EXPECT_NE(r.out.find("vertex 5"), std::string::npos) << r.out;
  EXPECT_TRUE(fs::exists(dir / "out" / "frame_00001.obj"));
  EXPECT_FALSE(fs::exists(dir / "out" / "frame_00002.obj"));
}

// After a divergence of an explicit run, the stable-step estimate of the initial state (the one
// `loom validate` prints) says whether dt was above it, and the fix gives 0.9 of it.
TEST(Cli, DivergenceOfAnExplicitRunComparesDtWithTheStableStep) {
  const std::string plugins = run("plugins", false).out;
  for (const char* p : {"mass_spring", "symplectic_euler"})
    if (plugins.find(p) == std::string::npos) GTEST_SKIP() << p << " is not in this build";
  const auto dir = scratch("diverge_dt");
  const std::string scene = std::string(LOOM_SOURCE_DIR) + "/scenes/hanging_cloth.yaml";
  const Result v = run("validate " + scene, false);
  const auto at = v.out.find("largest stable step about ");
  ASSERT_NE(at, std::string::npos) << v.out;
  const double h_max = std::stod(v.out.substr(at + 26));
  ASSERT_GT(h_max, 0);
  char dt[32], fix[32], est[32];
  std::snprintf(dt, sizeof dt, "%.3g", 2.5 * h_max);
  std::snprintf(est, sizeof est, "%.3g", h_max);
  std::snprintf(fix, sizeof fix, "%.3g", 0.9 * h_max);
  Result r = run("run " + scene + " --frames 3 --quiet --set integrator.dt=" + dt + " --out " + (dir / "a").string(), false);
  EXPECT_EQ(r.code, 3) << r.out;
  EXPECT_NE(r.out.find("exceeds the largest stable step of symplectic_euler estimated at the initial state, " +
                       std::string(est) + " s"),
            std::string::npos)
      << r.out;
  EXPECT_NE(r.out.find("set integrator.dt <= " + std::string(fix)), std::string::npos) << r.out;
  // a stable dt that a tight guard stops: the message says dt was within the estimate
  r = run("run " + scene + " --frames 3 --quiet --set guard.max_velocity=0.05 --out " + (dir / "b").string(), false);
  EXPECT_EQ(r.code, 3) << r.out;
  EXPECT_NE(r.out.find("is within the largest stable step of symplectic_euler"), std::string::npos) << r.out;
  // a resumed run that diverges: the estimate of the scene the run ran (its scene.yaml)
  r = run("run " + scene + " --frames 2 --quiet --set guard.max_velocity=0.5 --out " + (dir / "d").string(), false);
  EXPECT_EQ(r.code, 0) << r.out;
  r = run("run --resume " + (dir / "d").string() + " --frames 10 --quiet", false);
  EXPECT_EQ(r.code, 3) << r.out;
  EXPECT_NE(r.out.find("is within the largest stable step of symplectic_euler estimated at the initial state, " +
                       std::string(est) + " s"),
            std::string::npos)
      << r.out;
}

// An implicit run has no stable-step estimate: nothing is added to its divergence message.
TEST(Cli, DivergenceOfAnImplicitRunAddsNoStepEstimate) {
  const std::string listed = run("plugins", false).out;
  if (listed.find("gnatv") == std::string::npos || listed.find("baraff_witkin") == std::string::npos)
    GTEST_SKIP() << "gnatv or baraff_witkin is not in this build";
  const auto dir = scratch("diverge_implicit");
  const Result r = run("run " + std::string(LOOM_SOURCE_DIR) + "/scenes/drape_denim.yaml --frames 2 --quiet --set "
          "guard.max_velocity=0.01 --out " + (dir / "c").string(), false);
  EXPECT_EQ(r.code, 3) << r.out;
  EXPECT_EQ(r.out.find("largest stable step"), std::string::npos) << r.out;
}

TEST(Cli, SummaryCountsStepHalvings) {
  // A step the integrator solved again as two halves (StepStats::retries) is counted in the
  // summary; a run without one prints no such line.
  const auto dir = scratch("halvings");
  std::string s = kScene;
  s.replace(s.find("type: test_explicit_euler"), 25, "type: test_explicit_euler\n  retry_at: 5");
  Result r = run("run " + write_scene(dir, s) + " --out " + (dir / "out").string());
  EXPECT_EQ(r.code, 0) << r.out;
  EXPECT_NE(r.out.find("loom: 1 step halving after failed linear solves"), std::string::npos) << r.out;
  r = run("run " + write_scene(dir, kScene, "plain.yaml") + " --out " + (dir / "plain").string());
  EXPECT_EQ(r.code, 0) << r.out;
  EXPECT_EQ(r.out.find("step halving"), std::string::npos) << r.out;
}

TEST(Cli, RunWithRenderDrawsTheFrames) {
  const auto dir = scratch("render");
  const Result r = run("run " + write_scene(dir, kScene) + " --frames 2 --quiet --render --out " + (dir / "out").string());
  if (r.code == 2 && r.out.find("unknown renderer 'gl'") != std::string::npos)
    GTEST_SKIP() << "the gl renderer is not in this build (EGL/GLES not found at configure time)";
  ASSERT_EQ(r.code, 0) << r.out;
  EXPECT_TRUE(fs::exists(dir / "out" / "render" / "frame_00000.png"));
  EXPECT_TRUE(fs::exists(dir / "out" / "render" / "frame_00002.png"));
}

TEST(Cli, ViewWithoutADisplayOrFramesIsBadInput) {
  const auto dir = scratch("view");
  // A missing folder: exit 2 naming the folder (checked before the display).
  Result r = run("view " + (dir / "missing").string());
  EXPECT_EQ(r.code, 2) << r.out;
  EXPECT_NE(r.out.find("not a folder"), std::string::npos) << r.out;
  // A folder without frames.
  r = run("view " + dir.string());
  EXPECT_EQ(r.code, 2) << r.out;
  EXPECT_NE(r.out.find("no frame_*.obj"), std::string::npos) << r.out;
  // A real run, but no display (CI): exit 2 with one clear line naming the fix.
  r = run("run " + write_scene(dir, kScene) + " --frames 1 --quiet --out " + (dir / "out").string());
  ASSERT_EQ(r.code, 0) << r.out;
  const std::string cmd_env = "env -u DISPLAY -u WAYLAND_DISPLAY ";
  std::string cmd = cmd_env + "LOOM_PLUGIN_PATH=" LOOM_TEST_PLUGIN_DIR " " + std::string(LOOM_EXE) + " view " +
                    (dir / "out").string() + " 2>&1";
  FILE* p = popen(cmd.c_str(), "r");
  std::string out;
  std::array<char, 4096> buf{};
  while (fgets(buf.data(), buf.size(), p)) out += buf.data();
  const int status = pclose(p);
  EXPECT_TRUE(WIFEXITED(status) && WEXITSTATUS(status) == 2) << out;
  EXPECT_NE(out.find("loom view needs a display"), std::string::npos) << out;
  EXPECT_NE(out.find("Fix:"), std::string::npos) << out;
  // view is a known command with a usage error when the folder is missing.
  r = run("view");
  EXPECT_EQ(r.code, 2) << r.out;
  EXPECT_NE(r.out.find("view needs the output folder"), std::string::npos) << r.out;
}

TEST(Cli, PluginsListsModulesOnThePath) {
  const Result r = run("plugins");
  EXPECT_NE(r.out.find("test_gravity_only"), std::string::npos) << r.out;
  EXPECT_NE(r.out.find(LOOM_TEST_PLUGIN_DIR), std::string::npos) << r.out;
  // the deliberately broken test modules are reported, and the exit code says so
  EXPECT_NE(r.out.find("ABI version"), std::string::npos) << r.out;
  EXPECT_EQ(r.code, 2);
}

// `loom plugins --params NAME`: the declared keys (loom/param_spec.hpp) as a table.
TEST(Cli, PluginsParamsPrintsTheDeclaredKeys) {
  // mass_spring is in every build (the sanitizer preset builds few plugins); gnatv and
  // baraff_witkin are checked where they are built.
  Result r = run("plugins --params mass_spring", false);
  EXPECT_EQ(r.code, 0) << r.out;
  for (const char* s : {"mass_spring (material; backends cpu", "key", "default", "range", "units", "stencil",
                        "stiffness.structural", "mesh_edges | structural_shear_bend", "N/m", "framework"})
    EXPECT_NE(r.out.find(s), std::string::npos) << s << "\n" << r.out;
  r = run("plugins --params mass_sprng", false);
  EXPECT_EQ(r.code, 2) << r.out;
  EXPECT_NE(r.out.find("did you mean 'mass_spring'"), std::string::npos) << r.out;
  r = run("plugins --markdown", false);
  EXPECT_EQ(r.code, 2) << r.out;
  const std::string listed = run("plugins", false).out;
  if (listed.find("gnatv") != std::string::npos) {
    r = run("plugins --params gnatv", false);
    EXPECT_EQ(r.code, 0) << r.out;
    for (const char* s : {"gnatv (material; backends cpu", "material_file", "stress_scale", "monotone_cubic | bspline",
                          "kg/m^2"})
      EXPECT_NE(r.out.find(s), std::string::npos) << s << "\n" << r.out;
  }
  if (listed.find("baraff_witkin") != std::string::npos) {
    r = run("plugins --params baraff_witkin --markdown", false);
    EXPECT_EQ(r.code, 0) << r.out;
    EXPECT_NE(r.out.find("| `max_halvings` | int | `3` | [1, 20] |"), std::string::npos) << r.out;
  }
}

// Issue 20's fuzz findings, each with the exit code and message it must give.
TEST(Cli, HardenedInputsAreBadInputWithAClearMessage) {
  const auto dir = scratch("hardened");
  auto expect_bad = [&](const std::string& args, const std::string& needle) {
    const Result r = run(args);
    EXPECT_EQ(r.code, 2) << args << "\n" << r.out;
    EXPECT_NE(r.out.find(needle), std::string::npos) << args << "\n" << r.out;
  };
  // duplicate keys (a second integrator section) name both lines
  expect_bad("validate " + write_scene(dir, std::string(kScene) + "integrator: {type: rk4}\n", "dup.yaml"),
             "dup.yaml:11: duplicate key 'integrator' (first given at line 5)");
  // a folder, a device and a symlink loop as the scene
  expect_bad("validate " + dir.string(), "is a folder");
  expect_bad("run /dev/zero", "not a regular file");
  fs::create_symlink(dir / "loop_b.yaml", dir / "loop_a.yaml");
  fs::create_symlink(dir / "loop_a.yaml", dir / "loop_b.yaml");
  expect_bad("validate " + (dir / "loop_a.yaml").string(), "symbolic link loop");
  // an absurd thread count
  expect_bad("validate " + write_scene(dir, kScene) + " --set threads=100000", "must be 'auto' or a count in [0, 1024]");
  // a step count that would overflow
  expect_bad("validate " + write_scene(dir, kScene) + " --set integrator.substeps=2147483647", ">= 1 and <= 1e8");
  // mass factors that overflow when multiplied
  expect_bad("validate " + write_scene(dir, std::string(kScene) +
                                              "mass_scale: [{vertices: [0], factor: 1.0e308}, {vertices: [0], factor: 1.0e308}]\n",
                                          "mass.yaml"),
             "overflow");
  // `--set key=&a` (an anchor alone) does not delete the key; a scalar YAML file with --set is bad input
  expect_bad("validate " + write_scene(dir, kScene) + " --set 'integrator.dt=&a'", "not a YAML value");
  expect_bad("validate " + write_scene(dir, "just a string\n", "scalar.yaml") + " --set frames=3", "not a YAML mapping");
  // an unknown material names the file and line, and a 200 KB name is not echoed in full
  const Result big = run("validate " + write_scene(dir, std::string(kScene).replace(
                                                               std::string(kScene).find("test_gravity_only"), 17,
                                                               std::string(200000, 'x')),
                                                           "long.yaml"));
  EXPECT_EQ(big.code, 2);
  EXPECT_NE(big.out.find("long.yaml:4"), std::string::npos) << big.out.substr(0, 400);
  EXPECT_NE(big.out.find("(200000 characters)"), std::string::npos) << big.out.substr(0, 400);
  EXPECT_LT(big.out.size(), 4000u);
  // a missing material file names the scene's line (issue 20: it named only the path)
  expect_bad("validate " + write_scene(dir, "mesh: {grid: {nx: 4, ny: 4}}\nmaterial: {type: gnatv, material_file: nowhere.yaml}\n"
                                            "integrator: {type: symplectic_euler, dt: 0.001}\n", "nomat.yaml"),
             "nomat.yaml:2");
  // an input file over the size limit
  {
    std::ofstream big(dir / "big.yaml");
    big << kScene << "description: \"";
    const std::string chunk(1 << 20, 'x');
    for (int k = 0; k < 17; ++k) big << chunk;
    big << "\"\n";
  }
  expect_bad("validate " + (dir / "big.yaml").string(), "limited to 16 MiB");
  // a collider offset larger than the cloth (issue 20: 1e308 threw the cloth to 1e308)
  expect_bad("validate " + write_scene(dir, std::string(kScene) +
                                              "colliders: [{type: plane, point: [0, -2, 0], normal: [0, 1, 0], thickness: 1.0e308}]\n",
                                          "thick.yaml"),
             "larger than the whole cloth");
  // an initial state beyond the guards: refused before anything is written
  const Result r = run("run " + write_scene(dir, std::string(kScene) + "initial_velocity: [1.0e200, 0, 0]\n", "v0.yaml") +
                       " --out " + (dir / "out_v0").string());
  EXPECT_EQ(r.code, 2) << r.out;
  EXPECT_NE(r.out.find("initial state"), std::string::npos) << r.out;
  EXPECT_FALSE(fs::exists(dir / "out_v0" / "frame_00000.obj"));
  EXPECT_FALSE(fs::exists(dir / "out_v0" / "stats.csv"));
}

TEST(Cli, ThreadsAutoIsTheDefaultAndCountsAreCapped) {
  const auto dir = scratch("threads");
  Result r = run("validate " + write_scene(dir, kScene));
  ASSERT_EQ(r.code, 0) << r.out;
  EXPECT_NE(r.out.find("usable cores"), std::string::npos) << r.out;
  r = run("validate " + write_scene(dir, kScene) + " --set threads=1000");
  ASSERT_EQ(r.code, 0) << r.out;
  EXPECT_NE(r.out.find("capped at"), std::string::npos) << r.out;
  r = run("validate " + write_scene(dir, kScene) + " --set threads=auto");
  EXPECT_EQ(r.code, 0) << r.out;
}

// OpenMP binding (OMP_PROC_BIND, OMP_PLACES) binds the initial thread to the first place before
// loom counts the cores it may use; the count is the places' CPUs, not that one place's (it was:
// `threads: 2` capped at 1 under OMP_PLACES=cores on two cores). A narrower mask (taskset)
// still caps it.
TEST(Cli, ThreadCapCountsEveryOpenMpPlace) {
  const auto dir = scratch("threads_places");
  const std::string scene = write_scene(dir, kScene);
  const auto usable = [&](const std::string& env) {
    const Result r = loom_cli_test::run_loom_shell(env + " LOOM_PLUGIN_PATH=" LOOM_TEST_PLUGIN_DIR " " +
                                                   std::string(LOOM_EXE) + " validate " + scene + " --set threads=1000");
    EXPECT_EQ(r.code, 0) << r.out;
    const std::size_t at = r.out.find(" usable cores");
    EXPECT_NE(at, std::string::npos) << r.out;
    if (at == std::string::npos) return -1;
    std::size_t b = at;
    while (b > 0 && std::isdigit(static_cast<unsigned char>(r.out[b - 1]))) --b;
    return std::atoi(r.out.substr(b, at - b).c_str());
  };
  const int plain = usable("env -u OMP_PROC_BIND -u OMP_PLACES");
  ASSERT_GE(plain, 1);
  EXPECT_EQ(usable("env OMP_PROC_BIND=close OMP_PLACES=cores"), plain);
  EXPECT_EQ(usable("env OMP_PROC_BIND=spread OMP_PLACES=threads"), plain);
  EXPECT_EQ(usable("env OMP_PROC_BIND=true"), plain);
  // one CPU of the mask (the first one this process may use), bound or not: 1
  cpu_set_t set;
  CPU_ZERO(&set);
  ASSERT_EQ(sched_getaffinity(0, sizeof(set), &set), 0);
  int first = 0;
  while (first < CPU_SETSIZE && !CPU_ISSET(first, &set)) ++first;
  ASSERT_LT(first, CPU_SETSIZE);
  if (std::system("command -v taskset > /dev/null 2>&1") == 0) {
    const std::string ts = "taskset -c " + std::to_string(first) + " env";
    EXPECT_EQ(usable(ts + " OMP_PROC_BIND=close OMP_PLACES=cores"), 1);
    EXPECT_EQ(usable(ts + " -u OMP_PROC_BIND -u OMP_PLACES"), 1);
  }
}

// `loom validate` predicts divergence: the README's scene template (dt 1e-3 with k = 2000 on a
// 32 x 32 grid) is past symplectic Euler's limit and gets the warning; no shipped scene does.
TEST(Cli, ValidateWarnsWhenDtExceedsTheStableStep) {
  std::ifstream readme(std::string(LOOM_SOURCE_DIR) + "/README.md");
  const std::string text((std::istreambuf_iterator<char>(readme)), {});
  const auto sec = text.find("## Scene files");
  ASSERT_NE(sec, std::string::npos);
  const auto a = text.find("```yaml\n", sec);
  const auto b = text.find("```", a + 8);
  ASSERT_NE(a, std::string::npos);
  const auto dir = scratch("validate_readme");
  // The template names files relative to the scene's folder as the shipped scenes do (meshes/).
  fs::create_directory_symlink(std::string(LOOM_SOURCE_DIR) + "/scenes/meshes", dir / "meshes");
  const std::string scene = write_scene(dir, text.substr(a + 8, b - a - 8), "readme.yaml");
  Result r = run("validate " + scene, false);
  EXPECT_EQ(r.code, 0) << r.out;
  EXPECT_NE(r.out.find("exceeds the estimated stable step"), std::string::npos) << r.out;
  for (const auto& e : fs::directory_iterator(std::string(LOOM_SOURCE_DIR) + "/scenes")) {
    if (e.path().extension() != ".yaml") continue;
    r = run("validate " + e.path().string(), false);
    EXPECT_EQ(r.code, 0) << e.path() << "\n" << r.out;
    EXPECT_EQ(r.out.find("exceeds the estimated stable step"), std::string::npos) << e.path() << "\n" << r.out;
  }
}

// OpenBLAS (under the cholmod plugin) runs the kernel set loom/blas_kernels.hpp names for this
// CPU unless the user set OPENBLAS_CORETYPE: `loom` sets it before it loads a plugin. Expected
// set from /proc/cpuinfo's flags (independent of the header's cpuid test): AVX-512 F, DQ, BW,
// VL and CD: SkylakeX; else AVX2 and FMA: Haswell; else OpenBLAS's own choice (not checked).
// OPENBLAS_VERBOSE=2 makes OpenBLAS print the set it runs ("Core: <name>").
TEST(Cli, OpenBlasRunsTheKernelsOfTheCpuUnlessTheUserChose) {
  if (run("plugins", false).out.find("cholmod") == std::string::npos) GTEST_SKIP() << "no cholmod plugin in this build";
  std::ifstream info("/proc/cpuinfo");
  std::string line, flags;
  while (std::getline(info, line))
    if (line.rfind("flags", 0) == 0) {
      flags = line + " ";
      break;
    }
  const auto has = [&](const char* f) { return flags.find(std::string(" ") + f + " ") != std::string::npos; };
  std::string expected;
  if (has("avx512f") && has("avx512dq") && has("avx512bw") && has("avx512vl") && has("avx512cd"))
    expected = "SkylakeX";
  else if (has("avx2") && has("fma"))
    expected = "Haswell";
  const auto dir = scratch("openblas");
  std::ofstream(dir / "scene.yaml") << "mesh: {grid: {nx: 6, ny: 6, width: 0.5, height: 0.5}}\n"
                                       "material: {type: mass_spring, stiffness: 200, density: 0.1}\n"
                                       "integrator: {type: baraff_witkin, dt: 0.01}\n"
                                       "solver: {type: cholmod}\npins: [top_edge]\nframes: 1\n";
  const std::string args = "run " + (dir / "scene.yaml").string() + " --out " + (dir / "out").string() + " --quiet";
  const Result chosen = loom_cli_test::run_loom_shell("env -u OPENBLAS_CORETYPE OPENBLAS_VERBOSE=2 " +
                                                      std::string(LOOM_EXE) + " " + args);
  ASSERT_EQ(chosen.code, 0) << chosen.out;
  if (chosen.out.find("Core: ") == std::string::npos)   // an OpenBLAS built for one CPU (not Debian's) prints none
    GTEST_SKIP() << "this OpenBLAS does not print the kernel set it runs: " << chosen.out;
  if (!expected.empty()) {
    EXPECT_NE(chosen.out.find("Core: " + expected), std::string::npos) << chosen.out;
  }
  const Result user = loom_cli_test::run_loom_shell("OPENBLAS_CORETYPE=Prescott OPENBLAS_VERBOSE=2 " +
                                                    std::string(LOOM_EXE) + " " + args);
  ASSERT_EQ(user.code, 0) << user.out;
  EXPECT_NE(user.out.find("Core: Prescott"), std::string::npos) << user.out;
}

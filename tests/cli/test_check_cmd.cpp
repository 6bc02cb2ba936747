// `loom check RUN_DIR`: per-frame intersection counts, exit codes, bad input.
#include <gtest/gtest.h>

#include "cli_run.hpp"

#include <array>
#include <cstdio>
#include <filesystem>
#include <fstream>
#include <string>
#include <sys/wait.h>

namespace fs = std::filesystem;

namespace {

using loom_cli_test::Result;
Result loom(const std::string& args) { return loom_cli_test::run_loom(args); }
fs::path scratch(const std::string& name) { return loom_cli_test::scratch_dir("loom_check_", name); }

// Two triangles: A in z = 0 around the origin; B vertical, at x = bx. B pierces A when
// bx is inside A (|bx| < 0.5 at y = 0), and is beside it otherwise.
void write_frame(const fs::path& dir, int frame, double bx, const std::string& extra = "") {
  char name[32];
  std::snprintf(name, sizeof name, "frame_%05d.obj", frame);
  std::ofstream f(dir / name);
  f << "v -1 -1 0\nv 1 -1 0\nv 0 1 0\n";
  f << "v " << bx << " 0 -1\nv " << bx << " 0.1 1\nv " << bx << " -0.1 1\n" << extra;
  f << "f 1 2 3\nf 4 5 6\n";
}

}  // namespace

TEST(CheckCmd, CountsPerFrameAndExitsNonZeroOnIntersections) {
  const fs::path d = scratch("pierce");
  write_frame(d, 0, 3.0);   // beside
  write_frame(d, 1, 0.25);  // through A's interior
  write_frame(d, 2, 0.0);   // through A's interior
  const Result r = loom("check " + d.string());
  EXPECT_EQ(r.code, 5) << r.out;
  EXPECT_NE(r.out.find("frame_00000.obj          0"), std::string::npos) << r.out;
  EXPECT_NE(r.out.find("frame_00001.obj          1"), std::string::npos) << r.out;
  EXPECT_NE(r.out.find("2 of 3 frames"), std::string::npos) << r.out;
  const Result allow = loom("check " + d.string() + " --allow --list");
  EXPECT_EQ(allow.code, 0) << allow.out;
  EXPECT_NE(allow.out.find("triangles 0 1"), std::string::npos) << allow.out;
  // All frames clean: exit 0.
  const fs::path c = scratch("clean");
  write_frame(c, 0, 3.0);
  write_frame(c, 1, -2.0);
  const Result ok = loom("check " + c.string());
  EXPECT_EQ(ok.code, 0) << ok.out;
  EXPECT_NE(ok.out.find("no intersecting triangle pairs in 2 frames"), std::string::npos) << ok.out;
}

TEST(CheckCmd, ARunOfTheSimulatorChecksClean) {
  // A hanging grid under gravity alone: it stays in its plane (every pair coplanar) and its
  // free rows fall together: no non-adjacent pair meets.
  const fs::path d = scratch("run");
  std::ofstream(d / "scene.yaml") << "mesh:\n  grid: {nx: 6, ny: 6, width: 1.0, height: 1.0}\n"
                                     "material: {type: test_gravity_only}\n"
                                     "integrator: {type: test_explicit_euler, dt: 0.01, substeps: 4}\n"
                                     "pins: [top_edge]\nframes: 3\n";
  const Result run = loom("run " + (d / "scene.yaml").string() + " --out " + (d / "out").string() + " --quiet");
  ASSERT_EQ(run.code, 0) << run.out;
  const Result r = loom("check " + (d / "out").string());
  EXPECT_EQ(r.code, 0) << r.out;
  EXPECT_NE(r.out.find("in 4 frames (50 triangles)"), std::string::npos) << r.out;
}

TEST(CheckCmd, BadInputExitsWith2) {
  const Result none = loom("check /nonexistent_loom_dir");
  EXPECT_EQ(none.code, 2);
  EXPECT_NE(none.out.find("not a folder"), std::string::npos) << none.out;
  const fs::path e = scratch("empty");
  EXPECT_EQ(loom("check " + e.string()).code, 2);
  const fs::path m = scratch("mismatch");
  write_frame(m, 0, 3.0);
  write_frame(m, 1, 3.0, "v 0 0 0\n");
  const Result mm = loom("check " + m.string());
  EXPECT_EQ(mm.code, 2) << mm.out;
  EXPECT_NE(mm.out.find("frame_00001.obj: has 7 vertices"), std::string::npos) << mm.out;
  const fs::path n = scratch("nan");
  write_frame(n, 0, 3.0);
  write_frame(n, 1, 3.0, "v nan 0 0\n");
  const Result nn = loom("check " + n.string());
  EXPECT_EQ(nn.code, 2) << nn.out;
  EXPECT_NE(nn.out.find("frame_00001.obj:7: NaN or Inf"), std::string::npos) << nn.out;
  EXPECT_EQ(loom("check").code, 2);
}

namespace {

// Two 3 x 3 sheets of spacing 0.01 m, the upper one `gap` above the lower and shifted in its
// plane: their closest approach is the gap (the sheets' own non-adjacent pairs are 0.0071 m apart).
void write_sheets(const fs::path& dir, int frame, double gap) {
  char name[32];
  std::snprintf(name, sizeof name, "frame_%05d.obj", frame);
  std::ofstream f(dir / name);
  f.precision(17);
  for (int layer = 0; layer < 2; ++layer)
    for (int j = 0; j < 3; ++j)
      for (int i = 0; i < 3; ++i)
        f << "v " << 0.01 * i + 0.003 * layer << " " << 0.01 * j + 0.004 * layer << " " << gap * layer << "\n";
  for (int layer = 0; layer < 2; ++layer)
    for (int j = 0; j < 2; ++j)
      for (int i = 0; i < 2; ++i) {
        const int a = 9 * layer + 3 * j + i + 1, b = a + 1, c = a + 3, d = a + 4;
        f << "f " << a << " " << b << " " << d << "\nf " << a << " " << d << " " << c << "\n";
      }
}

}  // namespace

// --distance: each frame's closest approach of non-adjacent elements, in m and, with the run's
// self_collision thickness (its scene.yaml), as a fraction of it; the summary names the frame
// and the pair. The exit code still follows the intersections only.
TEST(CheckCmd, DistanceReportsTheClosestApproachPerFrame) {
  const fs::path d = scratch("distance");
  write_sheets(d, 0, 0.004);
  write_sheets(d, 1, 0.0025);
  write_sheets(d, 2, 0.003);
  std::ofstream(d / "scene.yaml") << "# The scene as it ran\nmesh: {obj: x.obj}\nself_collision: {thickness: 0.002, friction: 0.3}\n";
  const Result r = loom("check " + d.string() + " --distance");
  EXPECT_EQ(r.code, 0) << r.out;
  EXPECT_NE(r.out.find("CLOSEST_M"), std::string::npos) << r.out;
  EXPECT_NE(r.out.find("CLOSEST/THICKNESS"), std::string::npos) << r.out;
  EXPECT_NE(r.out.find("0.004          2"), std::string::npos) << r.out;    // frame 0: 0.004 m, 2 thicknesses
  EXPECT_NE(r.out.find("0.0025         1.25"), std::string::npos) << r.out;  // frame 1
  EXPECT_NE(r.out.find("closest approach 0.0025 m (1.25 of the thickness 0.002 m) in frame_00001.obj: vertex"),
            std::string::npos)
      << r.out;
  // without a scene.yaml: metres only
  fs::remove(d / "scene.yaml");
  const Result m = loom("check " + d.string() + " --distance --quiet");
  EXPECT_EQ(m.code, 0) << m.out;
  EXPECT_EQ(m.out.find("THICKNESS"), std::string::npos) << m.out;
  EXPECT_NE(m.out.find("closest approach 0.0025 m in frame_00001.obj"), std::string::npos) << m.out;
  // sheets far apart: the closest approach is a pair of elements of one sheet
  const fs::path far = scratch("distance_far");
  write_sheets(far, 0, 0.5);
  const Result f = loom("check " + far.string() + " --distance");
  EXPECT_EQ(f.code, 0) << f.out;
  EXPECT_NE(f.out.find("closest approach 0.00707107 m"), std::string::npos) << f.out;  // in-sheet: 0.01 / sqrt(2)
}

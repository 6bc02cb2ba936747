// Output files a DCC reads (PC2, OBJ with UVs and normals), output-folder rules, and what a
// killed or interrupted run leaves behind.
#include <gtest/gtest.h>

#include "cli_run.hpp"
#include <signal.h>
#include <sys/wait.h>
#include <unistd.h>

#include <array>
#include <chrono>
#include <cmath>
#include <cstdint>
#include <cstdio>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <random>
#include <sstream>
#include <string>
#include <thread>
#include <vector>

#include "loom/mesh.hpp"

namespace fs = std::filesystem;

namespace {

using loom_cli_test::Result;
Result run(const std::string& args) { return loom_cli_test::run_loom(args); }
fs::path scratch(const std::string& name) { return loom_cli_test::scratch_dir("loom_output_", name); }

std::string scene(const fs::path& dir, int frames, const std::string& extra = "") {
  return loom_cli_test::falling_grid_scene(dir, frames, extra);
}

// Positions of an OBJ frame, read by hand (not through Loom's reader).
std::vector<double> obj_positions(const fs::path& p) {
  std::ifstream in(p);
  std::vector<double> x;
  std::string line;
  while (std::getline(in, line)) {
    if (line.rfind("v ", 0) != 0) continue;
    std::istringstream ls(line.substr(2));
    double a, b, c;
    ls >> a >> b >> c;
    x.insert(x.end(), {a, b, c});
  }
  return x;
}

// An independent PC2 reader, from the documented layout: char[12] "POINTCACHE2\0",
// int32 version, int32 points, float32 start frame, float32 sample rate, int32 samples,
// then samples x points x float32[3].
struct Pc2 {
  std::int32_t version = 0, points = 0, samples = 0;
  float start = -1, rate = -1;
  std::vector<std::vector<float>> frames;
};
Pc2 read_pc2(const fs::path& p) {
  Pc2 c;
  std::ifstream in(p, std::ios::binary);
  char magic[12];
  in.read(magic, 12);
  EXPECT_EQ(std::memcmp(magic, "POINTCACHE2\0", 12), 0);
  in.read(reinterpret_cast<char*>(&c.version), 4);
  in.read(reinterpret_cast<char*>(&c.points), 4);
  in.read(reinterpret_cast<char*>(&c.start), 4);
  in.read(reinterpret_cast<char*>(&c.rate), 4);
  in.read(reinterpret_cast<char*>(&c.samples), 4);
  for (int s = 0; s < c.samples; ++s) {
    std::vector<float> f(3 * static_cast<std::size_t>(c.points));
    in.read(reinterpret_cast<char*>(f.data()), static_cast<std::streamsize>(f.size() * 4));
    EXPECT_TRUE(in) << "sample " << s << " is truncated";
    c.frames.push_back(f);
  }
  return c;
}

}  // namespace

TEST(Output, Pc2MatchesTheObjFramesAndRestObjKeepsUvsAndNormals) {
  const auto dir = scratch("pc2");
  const Result r = run("run " + scene(dir, 4, "output: {pc2: true, every: 2, lossless: true}\n") + " --quiet --out " +
                       (dir / "out").string());
  ASSERT_EQ(r.code, 0) << r.out;
  const Pc2 c = read_pc2(dir / "out" / "run.pc2");
  EXPECT_EQ(c.version, 1);
  EXPECT_EQ(c.points, 30);
  EXPECT_EQ(c.start, 0.0f);
  EXPECT_EQ(c.rate, 2.0f);  // every 2nd frame
  ASSERT_EQ(c.samples, 3);  // frames 0, 2, 4
  for (int k = 0; k < 3; ++k) {
    char name[32];
    std::snprintf(name, sizeof name, "frame_%05d.obj", 2 * k);
    const auto x = obj_positions(dir / "out" / name);
    ASSERT_EQ(x.size(), 90u);
    for (std::size_t i = 0; i < x.size(); ++i) EXPECT_EQ(c.frames[k][i], static_cast<float>(x[i])) << k << " " << i;
  }
  // The frames moved (gravity), so the comparison is not between constant files.
  EXPECT_NE(c.frames[0][1], c.frames[2][1]);
  // rest.obj: UVs (the grid's material coordinates) and unit normals, read back by Loom's reader.
  const loom::Mesh rest = loom::read_obj((dir / "out" / "rest.obj").string());
  const loom::Mesh grid = loom::make_grid(6, 5, 1.0, 0.8);
  ASSERT_EQ(rest.uvs.size(), grid.uvs.size());
  for (std::size_t i = 0; i < grid.uvs.size(); ++i) EXPECT_NEAR(rest.uvs[i], grid.uvs[i], 1e-15);
  EXPECT_EQ(rest.triangles, grid.triangles);
  std::ifstream in(dir / "out" / "rest.obj");
  std::string line;
  int vn = 0;
  while (std::getline(in, line))
    if (line.rfind("vn ", 0) == 0) {
      std::istringstream ls(line.substr(3));
      double a, b, cc;
      ls >> a >> b >> cc;
      EXPECT_NEAR(std::abs(cc), 1.0, 1e-9);  // the grid lies in the xy plane
      ++vn;
    }
  EXPECT_EQ(vn, 30);
}

TEST(Output, LosslessFramesRoundTripEveryDouble) {
  const auto dir = scratch("lossless");
  ASSERT_EQ(run("run " + scene(dir, 3, "output: {lossless: true}\n") + " --quiet --out " + (dir / "a").string()).code, 0);
  ASSERT_EQ(run("run " + scene(dir, 3) + " --quiet --out " + (dir / "b").string()).code, 0);
  const auto a = obj_positions(dir / "a" / "frame_00003.obj");
  const auto b = obj_positions(dir / "b" / "frame_00003.obj");
  ASSERT_EQ(a.size(), b.size());
  // 9 digits lose information below ~1e-9 relative: the lossless file differs from the short one
  // somewhere, and re-printing a lossless value with 17 digits gives the same double back.
  bool differs = false;
  for (std::size_t i = 0; i < a.size(); ++i) differs |= a[i] != b[i];
  EXPECT_TRUE(differs);
  for (double v : a) {
    char buf[40];
    std::snprintf(buf, sizeof buf, "%.17g", v);
    EXPECT_EQ(std::strtod(buf, nullptr), v);
  }
}

TEST(Output, FolderRulesNeverMixTwoRuns) {
  const auto dir = scratch("rules");
  const std::string sc = scene(dir, 6);
  const std::string out = (dir / "out").string();
  ASSERT_EQ(run("run " + sc + " --quiet --out " + out).code, 0);
  EXPECT_TRUE(fs::exists(dir / "out" / "frame_00006.obj"));
  // The same scene again with fewer frames: its old files are cleared, nothing is left behind.
  Result r = run("run " + sc + " --quiet --frames 2 --out " + out);
  ASSERT_EQ(r.code, 0) << r.out;
  EXPECT_TRUE(fs::exists(dir / "out" / "frame_00002.obj"));
  EXPECT_FALSE(fs::exists(dir / "out" / "frame_00003.obj"));
  // A different scene (an override) is refused and nothing is touched...
  r = run("run " + sc + " --quiet --set integrator.dt=0.005 --out " + out);
  EXPECT_EQ(r.code, 2) << r.out;
  EXPECT_NE(r.out.find("holds the files of another run"), std::string::npos) << r.out;
  EXPECT_NE(r.out.find("--overwrite"), std::string::npos) << r.out;
  EXPECT_TRUE(fs::exists(dir / "out" / "frame_00002.obj"));
  // ... unless --overwrite says to replace them.
  r = run("run " + sc + " --quiet --set integrator.dt=0.005 --frames 1 --overwrite --out " + out);
  EXPECT_EQ(r.code, 0) << r.out;
  EXPECT_FALSE(fs::exists(dir / "out" / "frame_00002.obj"));
  // A folder locked by a running loom is refused with the holder's pid.
  const std::string lock = (dir / "out" / ".loom.lock").string();
  pid_t holder = fork();
  if (holder == 0) {
    execlp("flock", "flock", lock.c_str(), "sleep", "3", static_cast<char*>(nullptr));
    _exit(127);
  }
  std::this_thread::sleep_for(std::chrono::milliseconds(300));
  r = run("run " + sc + " --quiet --overwrite --out " + out);
  EXPECT_EQ(r.code, 2) << r.out;
  EXPECT_NE(r.out.find("in use by another loom run"), std::string::npos) << r.out;
  kill(holder, SIGKILL);
  waitpid(holder, nullptr, 0);
}

// kill -9 at random times: only complete frames, stats rows never ahead of the frames, and the
// next run removes every temporary file.
TEST(Output, KillNineLeavesOnlyCompleteFrames) {
  const auto dir = scratch("kill9");
  const std::string sc = scene(dir, 4000);
  const std::string out = (dir / "out").string();
  std::mt19937 rng(12345);
  std::uniform_int_distribution<int> ms(5, 120);
  const std::string exe = LOOM_EXE;
  for (int k = 0; k < 20; ++k) {
    pid_t pid = fork();
    if (pid == 0) {
      setenv("LOOM_PLUGIN_PATH", LOOM_TEST_PLUGIN_DIR, 1);
      freopen("/dev/null", "w", stdout);
      freopen("/dev/null", "w", stderr);
      execl(exe.c_str(), exe.c_str(), "run", sc.c_str(), "--quiet", "--overwrite", "--out", out.c_str(),
            static_cast<char*>(nullptr));
      _exit(127);
    }
    // the random delay counts from when the run has made its folder (a kill during start-up
    // tests nothing, and a slow start-up, as under the sanitizers, left no folder to read)
    loom_cli_test::wait_for_path(out, std::chrono::seconds(10));
    std::this_thread::sleep_for(std::chrono::milliseconds(ms(rng)));
    kill(pid, SIGKILL);
    waitpid(pid, nullptr, 0);
    int frames = 0;
    for (const auto& e : fs::directory_iterator(out)) {
      const std::string name = e.path().filename().string();
      if (name.rfind("frame_", 0) != 0 || name.find(".tmp.") != std::string::npos) continue;
      ++frames;
      // a complete frame has all its faces (the grid has 5 x 4 x 2 = 40 triangles)
      std::ifstream in(e.path());
      std::string line;
      int faces = 0;
      while (std::getline(in, line)) faces += line.rfind("f ", 0) == 0;
      EXPECT_EQ(faces, 40) << name;
    }
    std::ifstream st(fs::path(out) / "stats.csv");
    int rows = -1;  // header
    for (std::string line; std::getline(st, line);) rows += !line.empty();
    EXPECT_LE(std::max(rows, 0), frames) << "kill " << k;
  }
  ASSERT_EQ(run("run " + sc + " --quiet --frames 3 --overwrite --out " + out).code, 0);
  for (const auto& e : fs::directory_iterator(out))
    EXPECT_EQ(e.path().filename().string().find(".tmp."), std::string::npos) << e.path();
}

TEST(Output, CtrlCStopsCleanlyAndSaysWhatWasKept) {
  const auto dir = scratch("sigint");
  // No gravity: the run must still be going when the signal comes, on any machine (falling
  // freely, the grid passed the guard's 1000 m/s at step 10194 within the 400 ms on a fast one).
  const std::string sc = scene(dir, 100000, "gravity: [0, 0, 0]\n");
  const std::string out = (dir / "out").string();
  const std::string log = (dir / "log.txt").string();
  pid_t pid = fork();
  if (pid == 0) {
    setenv("LOOM_PLUGIN_PATH", LOOM_TEST_PLUGIN_DIR, 1);
    freopen(log.c_str(), "w", stdout);
    freopen(log.c_str(), "a", stderr);
    const std::string exe = LOOM_EXE;
    execl(exe.c_str(), exe.c_str(), "run", sc.c_str(), "--quiet", "--out", out.c_str(), static_cast<char*>(nullptr));
    _exit(127);
  }
  // the signal once the first frame is written (or after 20 s), so that a slow start does not
  // interrupt the run before it has kept anything
  loom_cli_test::wait_for_path(fs::path(out) / "frame_00000.obj", std::chrono::seconds(20));
  std::this_thread::sleep_for(std::chrono::milliseconds(100));
  kill(pid, SIGINT);
  int status = 0;
  waitpid(pid, &status, 0);
  ASSERT_TRUE(WIFEXITED(status));
  EXPECT_EQ(WEXITSTATUS(status), 130);
  std::ifstream in(log);
  const std::string text((std::istreambuf_iterator<char>(in)), {});
  EXPECT_NE(text.find("interrupted at step"), std::string::npos) << text;
  EXPECT_NE(text.find("kept in"), std::string::npos) << text;
  EXPECT_TRUE(fs::exists(fs::path(out) / "frame_00000.obj"));
}

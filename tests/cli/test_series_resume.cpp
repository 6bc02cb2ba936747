// ParaView series (.vtu frames + run.pvd) read back by an independent parser, velocity
// export, `loom run --resume` (bit for bit against an uninterrupted run, also after Ctrl-C and
// kill -9), and `loom plot`.
#include <gtest/gtest.h>

#include <signal.h>
#include <sys/wait.h>
#include <unistd.h>

#include <chrono>
#include <cmath>
#include <cstdint>
#include <cstdio>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <map>
#include <set>
#include <sstream>
#include <string>
#include <thread>
#include <vector>

#include "cli_run.hpp"

namespace fs = std::filesystem;

namespace {

using loom_cli_test::Result;
Result run(const std::string& args) { return loom_cli_test::run_loom(args); }
Result run_real(const std::string& args) { return loom_cli_test::run_loom(args, /*test_plugins=*/false); }
fs::path scratch(const std::string& name) { return loom_cli_test::scratch_dir("loom_series_", name); }

// Whether this build has the plugin module (the sanitizer build has only a few).
bool have(const std::string& module) {
  return fs::exists(fs::path(LOOM_BINARY_DIR) / "lib/loom/plugins" / ("loom_" + module + ".so"));
}
#define NEED_PLUGINS(...)                                                   \
  for (const char* m : {__VA_ARGS__})                                      \
    if (!have(m)) GTEST_SKIP() << "plugin " << m << " is not built here";

std::string slurp(const fs::path& p) {
  std::ifstream in(p, std::ios::binary);
  return std::string((std::istreambuf_iterator<char>(in)), {});
}

// The falling 6 x 5 grid of cli_run.hpp.
std::string scene(const fs::path& dir, int frames, const std::string& extra = "") {
  return loom_cli_test::falling_grid_scene(dir, frames, extra);
}

// ---- an independent reader of the VTK XML we expect (not Loom's code) ----
struct XmlTag {
  std::string name;
  std::map<std::string, std::string> attr;
  std::string body;  // text up to the matching close tag (for DataArray)
};

// Every <name ...> tag in text, with its attributes; for DataArray also the text inside.
std::vector<XmlTag> tags(const std::string& text, const std::string& name) {
  std::vector<XmlTag> out;
  std::size_t pos = 0;
  while ((pos = text.find("<" + name, pos)) != std::string::npos) {
    const std::size_t end = text.find('>', pos);
    XmlTag t;
    t.name = name;
    std::string head = text.substr(pos + 1 + name.size(), end - pos - 1 - name.size());
    std::size_t a = 0;
    while ((a = head.find('=', a)) != std::string::npos) {
      std::size_t k = a;
      while (k > 0 && head[k - 1] != ' ') --k;
      const std::size_t q1 = head.find('"', a), q2 = head.find('"', q1 + 1);
      t.attr[head.substr(k, a - k)] = head.substr(q1 + 1, q2 - q1 - 1);
      a = q2 + 1;
    }
    if (head.empty() || head.back() != '/') {
      const std::size_t close = text.find("</" + name + ">", end);
      if (close != std::string::npos) t.body = text.substr(end + 1, close - end - 1);
    }
    out.push_back(t);
    pos = end;
  }
  return out;
}

std::vector<double> numbers(const std::string& body) {
  std::istringstream in(body);
  std::vector<double> v;
  for (double d; in >> d;) v.push_back(d);
  return v;
}

struct Vtu {
  long points = -1, cells = -1;
  double time = -1;
  std::map<std::string, std::vector<double>> arrays;  // by Name
  std::map<std::string, int> components;
};

Vtu read_vtu(const fs::path& p) {
  const std::string text = slurp(p);
  Vtu v;
  EXPECT_NE(text.find("<VTKFile type=\"UnstructuredGrid\""), std::string::npos) << p;
  const auto piece = tags(text, "Piece");
  EXPECT_EQ(piece.size(), 1u);
  if (piece.empty()) return v;
  v.points = std::stol(piece[0].attr.at("NumberOfPoints"));
  v.cells = std::stol(piece[0].attr.at("NumberOfCells"));
  for (const XmlTag& a : tags(text, "DataArray")) {
    const std::string name = a.attr.count("Name") ? a.attr.at("Name") : "";
    v.arrays[name] = numbers(a.body);
    v.components[name] = a.attr.count("NumberOfComponents") ? std::stoi(a.attr.at("NumberOfComponents")) : 1;
    EXPECT_EQ(a.attr.at("format"), "ascii");
  }
  v.time = v.arrays["TimeValue"].empty() ? -1 : v.arrays["TimeValue"][0];
  return v;
}

std::vector<double> obj_numbers(const fs::path& p, const std::string& prefix) {
  std::ifstream in(p);
  std::vector<double> x;
  for (std::string line; std::getline(in, line);) {
    if (line.rfind(prefix, 0) != 0) continue;
    std::istringstream ls(line.substr(prefix.size()));
    for (std::string tok; ls >> tok;) x.push_back(std::stod(tok.substr(0, tok.find('/'))));
  }
  return x;
}

std::vector<float> pc2_samples(const fs::path& p, int& points, int& samples) {
  const std::string s = slurp(p);
  std::int32_t pts = 0, n = 0;
  std::memcpy(&pts, s.data() + 16, 4);
  std::memcpy(&n, s.data() + 28, 4);
  points = pts;
  samples = n;
  std::vector<float> f((s.size() - 32) / 4);
  std::memcpy(f.data(), s.data() + 32, f.size() * 4);
  return f;
}

}  // namespace

TEST(ParaView, SeriesReadsBackWithAnIndependentParser) {
  const auto dir = scratch("vtk");
  const std::string out = (dir / "out").string();
  const Result r = run("run " + scene(dir, 4, "output: {vtk: true, velocities: true, pc2: true, lossless: true}\n") +
                       " --quiet --out " + out);
  ASSERT_EQ(r.code, 0) << r.out;

  // run.pvd lists frames 0..4 with their times: frame k is 2k steps of 0.01 s.
  const auto sets = tags(slurp(fs::path(out) / "run.pvd"), "DataSet");
  ASSERT_EQ(sets.size(), 5u);
  const auto rest = obj_numbers(fs::path(out) / "frame_00000.obj", "v ");
  const auto faces = obj_numbers(fs::path(out) / "frame_00000.obj", "f ");
  ASSERT_EQ(faces.size(), 120u);  // 40 triangles
  int pc2_points = 0, pc2_count = 0;
  const auto vel_cache = pc2_samples(fs::path(out) / "velocity.pc2", pc2_points, pc2_count);
  EXPECT_EQ(pc2_points, 30);
  ASSERT_EQ(pc2_count, 5);
  for (int k = 0; k < 5; ++k) {
    const double t = 0.02 * k;
    EXPECT_NEAR(std::stod(sets[k].attr.at("timestep")), t, 1e-12);
    char name[32];
    std::snprintf(name, sizeof name, "frame_%05d", k);
    EXPECT_EQ(sets[k].attr.at("file"), std::string(name) + ".vtu");
    const Vtu v = read_vtu(fs::path(out) / (std::string(name) + ".vtu"));
    EXPECT_EQ(v.points, 30);
    EXPECT_EQ(v.cells, 40);
    EXPECT_NEAR(v.time, t, 1e-12);
    // Connectivity: the OBJ's faces (1-based) minus one; offsets 3, 6, ...; all VTK_TRIANGLE (5).
    const auto& conn = v.arrays.at("connectivity");
    ASSERT_EQ(conn.size(), 120u);
    for (std::size_t i = 0; i < conn.size(); ++i) EXPECT_EQ(conn[i], faces[i] - 1) << i;
    const auto& off = v.arrays.at("offsets");
    ASSERT_EQ(off.size(), 40u);
    for (std::size_t c = 0; c < 40; ++c) EXPECT_EQ(off[c], 3.0 * (c + 1));
    for (double type : v.arrays.at("types")) EXPECT_EQ(type, 5.0);
    // Positions: exactly the lossless OBJ frame's.
    const auto& x = v.arrays.at("Points");
    EXPECT_EQ(v.components.at("Points"), 3);
    EXPECT_EQ(x, obj_numbers(fs::path(out) / (std::string(name) + ".obj"), "v "));
    // Velocities: the pinned top row (y = 0.8 at rest) is still; every free vertex falls at
    // g t (explicit Euler under gravity alone gives v = n h g exactly up to rounding).
    const auto& vel = v.arrays.at("velocity");
    EXPECT_EQ(v.components.at("velocity"), 3);
    ASSERT_EQ(vel.size(), 90u);
    for (int i = 0; i < 30; ++i) {
      const bool pinned = rest[3 * i + 1] == 0.8;
      EXPECT_EQ(vel[3 * i], 0.0);
      EXPECT_NEAR(vel[3 * i + 1], pinned ? 0.0 : -9.81 * t, 1e-12) << "frame " << k << " vertex " << i;
      EXPECT_EQ(vel[3 * i + 2], 0.0);
      for (int c = 0; c < 3; ++c) EXPECT_EQ(vel_cache[90 * k + 3 * i + c], static_cast<float>(vel[3 * i + c]));
    }
    // Strain: recomputed here from the triangles' edges, the rest frame and this frame.
    std::vector<double> strain(30, 0.0);
    for (std::size_t f = 0; f < 40; ++f)
      for (int e = 0; e < 3; ++e) {
        const int a = static_cast<int>(conn[3 * f + e]), b = static_cast<int>(conn[3 * f + (e + 1) % 3]);
        auto len = [&](const std::vector<double>& p) {
          return std::hypot(p[3 * b] - p[3 * a], p[3 * b + 1] - p[3 * a + 1], p[3 * b + 2] - p[3 * a + 2]);
        };
        const double s = std::abs(len(x) / len(rest) - 1.0);
        strain[a] = std::max(strain[a], s);
        strain[b] = std::max(strain[b], s);
      }
    const auto& sv = v.arrays.at("strain");
    ASSERT_EQ(sv.size(), 30u);
    for (int i = 0; i < 30; ++i) EXPECT_NEAR(sv[i], strain[i], 1e-12);
    if (k > 0) {
      EXPECT_GT(*std::max_element(sv.begin(), sv.end()), 0.0);  // pinned row vs falling rows
    }
  }
}

// The contact field: with colliders, each frame carries collider_gap (signed distance to the
// nearest collider's offset surface) and contact (1 where the gap is at most 1 um). Expected
// values recomputed here from the frame's positions and the plane's analytic distance.
TEST(ParaView, ContactFieldIsTheGapToTheColliders) {
  const auto dir = scratch("vtk_contact");
  const std::string out = (dir / "out").string();
  // A horizontal plane whose offset surface (point y - 0.001, thickness 0.0005) is 0.5 mm
  // below the bottom row (y = 0): the falling rows reach it within the run.
  const Result r = run("run " +
                       scene(dir, 4,
                             "colliders:\n  - {type: plane, point: [0, -0.001, 0], normal: [0, 1, 0], thickness: 0.0005}\n"
                             "output: {vtk: true, lossless: true}\n") +
                       " --quiet --out " + out);
  ASSERT_EQ(r.code, 0) << r.out;
  const double surface = -0.001 + 0.0005;
  int touching_last = 0;
  for (int k = 0; k <= 4; ++k) {
    char name[32];
    std::snprintf(name, sizeof name, "frame_%05d.vtu", k);
    const Vtu v = read_vtu(fs::path(out) / name);
    const auto& x = v.arrays.at("Points");
    const auto& gap = v.arrays.at("collider_gap");
    const auto& contact = v.arrays.at("contact");
    ASSERT_EQ(gap.size(), 30u);
    ASSERT_EQ(contact.size(), 30u);
    for (int i = 0; i < 30; ++i) {
      EXPECT_NEAR(gap[i], x[3 * i + 1] - surface, 1e-12) << "frame " << k << " vertex " << i;
      EXPECT_EQ(contact[i], gap[i] <= 1e-6 ? 1.0 : 0.0) << "frame " << k << " vertex " << i;
      if (k == 0) {
        EXPECT_EQ(contact[i], 0.0) << i;
      }
      if (k == 4 && contact[i] == 1.0) ++touching_last;
    }
  }
  EXPECT_GE(touching_last, 6);  // at least the bottom row has reached the plane
  // Without colliders there is no contact field.
  const auto dir2 = scratch("vtk_nocontact");
  const Result r2 = run("run " + scene(dir2, 1, "output: {vtk: true}\n") + " --quiet --out " + (dir2 / "o").string());
  ASSERT_EQ(r2.code, 0) << r2.out;
  EXPECT_EQ(read_vtu(dir2 / "o" / "frame_00001.vtu").arrays.count("collider_gap"), 0u);
}

// uvs: true gives the ParaView frames the mesh's material coordinates as point data `uv`,
// marked as the texture coordinates (TCoords). Expected values from the mesh's definition: a
// grid's uv is the vertex's position in the flat sheet (the XY grid's rest x and y here); an
// OBJ's uv is the vt its faces give the vertex. An OBJ with a UV seam cannot be described by one
// uv per point and gets no array; neither does a run without uvs: true.
TEST(ParaView, UvsAreTheTextureCoordinatesOfASeamFreeMesh) {
  auto pointdata_tcoords = [](const fs::path& vtu) {
    const auto pd = tags(slurp(vtu), "PointData");
    return pd.size() == 1 && pd[0].attr.count("TCoords") ? pd[0].attr.at("TCoords") : std::string();
  };
  const auto dir = scratch("vtk_uv");
  const std::string out = (dir / "out").string();
  Result r = run("run " + scene(dir, 2, "output: {vtk: true, uvs: true, lossless: true}\n") + " --quiet --out " + out);
  ASSERT_EQ(r.code, 0) << r.out;
  const auto rest = obj_numbers(fs::path(out) / "frame_00000.obj", "v ");
  ASSERT_EQ(rest.size(), 90u);
  for (const char* name : {"frame_00000.vtu", "frame_00002.vtu"}) {
    const Vtu v = read_vtu(fs::path(out) / name);
    ASSERT_EQ(v.arrays.count("uv"), 1u) << name;
    EXPECT_EQ(v.components.at("uv"), 2);
    EXPECT_EQ(pointdata_tcoords(fs::path(out) / name), "uv");
    const auto& uv = v.arrays.at("uv");
    ASSERT_EQ(uv.size(), 60u);
    for (int i = 0; i < 30; ++i) {
      EXPECT_EQ(uv[2 * i], rest[3 * i]) << name << " vertex " << i;
      EXPECT_EQ(uv[2 * i + 1], rest[3 * i + 1]) << name << " vertex " << i;
    }
  }
  // without uvs: true, no array
  const auto dir0 = scratch("vtk_no_uv");
  r = run("run " + scene(dir0, 1, "output: {vtk: true}\n") + " --quiet --out " + (dir0 / "o").string());
  ASSERT_EQ(r.code, 0) << r.out;
  EXPECT_EQ(read_vtu(dir0 / "o" / "frame_00001.vtu").arrays.count("uv"), 0u);
  EXPECT_EQ(pointdata_tcoords(dir0 / "o" / "frame_00001.vtu"), "");
  // OBJ meshes: a square of two triangles, its vt agreeing at every vertex, then with a seam
  // (vertex 1 has another vt in the second face)
  auto obj_run = [&](const std::string& name, const std::string& second_face, const std::string& extra_vt) {
    const auto d = scratch(name);
    std::ofstream(d / "square.obj") << "v 0 0 0\nv 1 0 0\nv 1 1 0\nv 0 1 0\n"
                                     "vt 0.1 0.2\nvt 0.9 0.2\nvt 0.9 0.8\nvt 0.1 0.8\n" + extra_vt +
                                     "f 1/1 2/2 3/3\n" + second_face + "\n";
    std::ofstream(d / "scene.yaml") << "mesh: {obj: square.obj}\nmaterial: {type: test_gravity_only}\n"
                                       "integrator: {type: test_explicit_euler, dt: 0.01}\nframes: 1\n"
                                       "output: {vtk: true, uvs: true}\n";
    const Result rr = run("run " + (d / "scene.yaml").string() + " --quiet --out " + (d / "o").string());
    EXPECT_EQ(rr.code, 0) << rr.out;
    return read_vtu(d / "o" / "frame_00001.vtu");
  };
  const Vtu plain = obj_run("vtk_uv_obj", "f 1/1 3/3 4/4", "");
  ASSERT_EQ(plain.arrays.count("uv"), 1u);
  EXPECT_EQ(plain.arrays.at("uv"), (std::vector<double>{0.1, 0.2, 0.9, 0.2, 0.9, 0.8, 0.1, 0.8}));
  const Vtu seam = obj_run("vtk_uv_seam", "f 1/5 3/3 4/4", "vt 0.5 0.5\n");
  EXPECT_EQ(seam.points, 4);
  EXPECT_EQ(seam.arrays.count("uv"), 0u);
}

TEST(ParaView, VelocitiesNeedAFormatThatCarriesThem) {
  const auto dir = scratch("vel_alone");
  const Result r = run("run " + scene(dir, 2, "output: {velocities: true}\n") + " --quiet --out " + (dir / "o").string());
  EXPECT_EQ(r.code, 2) << r.out;
  EXPECT_NE(r.out.find("scene.yaml:"), std::string::npos) << r.out;
  EXPECT_NE(r.out.find("vtk: true"), std::string::npos) << r.out;
}

namespace {

// Every file of two run folders that must agree: frames, point caches, the series, the restart
// point; stats.csv without its wall-time column.
void expect_same_run(const fs::path& a, const fs::path& b) {
  std::set<std::string> names;
  for (const auto& e : fs::directory_iterator(a)) names.insert(e.path().filename().string());
  std::set<std::string> names_b;
  for (const auto& e : fs::directory_iterator(b)) names_b.insert(e.path().filename().string());
  names.erase(".loom.lock");
  names_b.erase(".loom.lock");
  EXPECT_EQ(names, names_b);
  int compared = 0;
  for (const auto& n : names) {
    if (n == "stats.csv" || n == ".loom.lock") continue;
    EXPECT_TRUE(slurp(a / n) == slurp(b / n)) << n << " differs between " << a << " and " << b;
    ++compared;
  }
  EXPECT_GT(compared, 3);
  auto rows = [](const fs::path& p) {
    std::ifstream in(p);
    std::vector<std::string> out;
    for (std::string line; std::getline(in, line);) {
      std::vector<std::string> f;
      std::stringstream ls(line);
      for (std::string c; std::getline(ls, c, ',');) f.push_back(c);
      if (f.size() > 7) f.erase(f.begin() + 7);  // wall_ms_per_step
      std::string s;
      for (const auto& c : f) s += c + ",";
      out.push_back(s);
    }
    return out;
  };
  EXPECT_EQ(rows(a / "stats.csv"), rows(b / "stats.csv"));
}

// Start `loom run` in the background; stop it with sig once frame `after` exists.
int run_and_stop(const std::vector<std::string>& args, const fs::path& out, int after, int sig, bool test_plugins) {
  pid_t pid = fork();
  if (pid == 0) {
    if (test_plugins) setenv("LOOM_PLUGIN_PATH", LOOM_TEST_PLUGIN_DIR, 1);
    freopen("/dev/null", "w", stdout);
    freopen("/dev/null", "w", stderr);
    std::vector<char*> argv;
    static std::string exe = LOOM_EXE;
    argv.push_back(exe.data());
    std::vector<std::string> copy = args;
    for (auto& a : copy) argv.push_back(a.data());
    argv.push_back(nullptr);
    execv(exe.c_str(), argv.data());
    _exit(127);
  }
  char name[32];
  std::snprintf(name, sizeof name, "frame_%05d.obj", after);
  loom_cli_test::wait_for_path(out / name, std::chrono::seconds(10));
  kill(pid, sig);
  int status = 0;
  waitpid(pid, &status, 0);
  return status;
}

}  // namespace

TEST(Resume, ContinuesAStoppedRunBitForBit) {
  const auto dir = scratch("resume");
  const std::string sc = scene(dir, 12, "output: {vtk: true, velocities: true, pc2: true, lossless: true, every: 2}\n");
  const fs::path whole = dir / "whole", parts = dir / "parts";
  ASSERT_EQ(run("run " + sc + " --quiet --out " + whole.string()).code, 0);
  ASSERT_EQ(run("run " + sc + " --quiet --frames 5 --out " + parts.string()).code, 0);
  // frame 5 is not a written frame (every 2): the point caches and the series resume at 4.
  Result r = run("run --resume " + parts.string() + " --frames 12");
  ASSERT_EQ(r.code, 0) << r.out;
  EXPECT_NE(r.out.find("resuming " + parts.string() + " at frame 5 of 12"), std::string::npos) << r.out;
  expect_same_run(whole, parts);
  // Nothing left to do, and the fixes are named.
  r = run("run --resume " + parts.string());
  EXPECT_EQ(r.code, 2) << r.out;
  EXPECT_NE(r.out.find("the run is complete"), std::string::npos) << r.out;
  r = run("run --resume " + parts.string() + " --set frames=20");
  EXPECT_EQ(r.code, 2) << r.out;
  r = run("run --resume " + (dir / "nothing").string());
  EXPECT_EQ(r.code, 2) << r.out;
  EXPECT_NE(r.out.find("not a folder"), std::string::npos) << r.out;
  fs::remove(parts / "restart.bin");
  r = run("run --resume " + parts.string() + " --frames 14");
  EXPECT_EQ(r.code, 2) << r.out;
  EXPECT_NE(r.out.find("no restart point"), std::string::npos) << r.out;
}

TEST(Resume, AfterCtrlCOrKillNineMatchesAnUninterruptedRun) {
  for (int sig : {SIGINT, SIGKILL}) {
    const auto dir = scratch(sig == SIGINT ? "sigint" : "sigkill");
    const std::string sc = scene(dir, 1000000, "output: {vtk: true, velocities: true, pc2: true, lossless: true}\n");
    const fs::path stopped = dir / "stopped", whole = dir / "whole";
    const int status = run_and_stop({"run", sc, "--quiet", "--out", stopped.string()}, stopped, 30, sig, true);
    if (sig == SIGINT) {
      ASSERT_TRUE(WIFEXITED(status));
      EXPECT_EQ(WEXITSTATUS(status), 130);
    } else {
      ASSERT_TRUE(WIFSIGNALED(status));
    }
    // The last complete frame: the highest frame that has a stats row.
    std::ifstream st(stopped / "stats.csv");
    int rows = -1;
    for (std::string line; std::getline(st, line);) rows += !line.empty();
    ASSERT_GE(rows, 30);
    const int target = rows + 25;
    Result r = run("run --resume " + stopped.string() + " --quiet --frames " + std::to_string(target));
    ASSERT_EQ(r.code, 0) << r.out;
    r = run("run " + sc + " --quiet --frames " + std::to_string(target) + " --out " + whole.string());
    ASSERT_EQ(r.code, 0) << r.out;
    expect_same_run(whole, stopped);
    for (const auto& e : fs::directory_iterator(stopped))
      EXPECT_EQ(e.path().filename().string().find(".tmp."), std::string::npos) << e.path();
  }
}

// The frame of a run folder's restart.bin (int32 after the 8-byte tag, docs/OUTPUT.md).
int restart_frame(const fs::path& dir) {
  const std::string b = slurp(dir / "restart.bin");
  if (b.size() < 12 || b.compare(0, 8, "LOOMRST1") != 0) return -1;
  std::int32_t f;
  std::memcpy(&f, b.data() + 8, 4);
  return f;
}

// The rows of a run folder's stats.csv, frame 0 included (the last complete frame is rows - 1).
int stats_rows(const fs::path& dir) {
  std::ifstream st(dir / "stats.csv");
  int rows = -1;  // the header
  for (std::string line; std::getline(st, line);) rows += !line.empty();
  return rows;
}

// restart.bin is written after frame 0, then at most once per restart_interval of wall time,
// after the last frame and when a run stops early. With an interval no run here reaches: a
// finished run's restart point is its last frame; Ctrl-C writes the last complete frame's
// (kept in memory); kill -9 leaves frame 0's, and --resume from it still matches an
// uninterrupted run (the frames and rows after it are cut and redone).
TEST(Resume, RestartPointsAreThrottledAndWrittenAtAnEarlyStop) {
  const auto dir = scratch("restart_interval");
  const std::string sc = scene(dir, 12, "output: {restart_interval: 1000, lossless: true}\n");
  ASSERT_EQ(run("run " + sc + " --quiet --out " + (dir / "done").string()).code, 0);
  EXPECT_EQ(restart_frame(dir / "done"), 12);
  const std::string sc_long = scene(dir, 1000000, "output: {restart_interval: 1000, lossless: true}\n");
  for (int sig : {SIGINT, SIGKILL}) {
    const fs::path stopped = dir / (sig == SIGINT ? "sigint" : "sigkill"), whole = dir / "whole";
    run_and_stop({"run", sc_long, "--quiet", "--out", stopped.string()}, stopped, 30, sig, true);
    const int rows = stats_rows(stopped);
    ASSERT_GE(rows, 30);
    if (sig == SIGINT) {
      EXPECT_EQ(restart_frame(stopped), rows - 1) << "Ctrl-C keeps the last complete frame";
    } else {
      EXPECT_EQ(restart_frame(stopped), 0) << "nothing after frame 0 within the interval";
    }
    const int target = rows + 5;
    Result r = run("run --resume " + stopped.string() + " --quiet --frames " + std::to_string(target));
    ASSERT_EQ(r.code, 0) << r.out;
    fs::remove_all(whole);
    r = run("run " + sc_long + " --quiet --frames " + std::to_string(target) + " --out " + whole.string());
    ASSERT_EQ(r.code, 0) << r.out;
    expect_same_run(whole, stopped);
    EXPECT_EQ(restart_frame(stopped), target);
  }
}

// Baraff-Witkin carries a warm start and the contact flags from step to step: restored from
// restart.bin, the continuation is exact (with the PCG's warm start on, its default).
TEST(Resume, BaraffWitkinWithContactsIsExact) {
  NEED_PLUGINS("material_mass_spring", "integrator_baraff_witkin", "solver_eigen_pcg");
  const auto dir = scratch("resume_bw");
  const std::string text =
      "mesh:\n  grid: {nx: 8, ny: 8, width: 0.5, height: 0.5, plane: xz}\n"
      "material: {type: mass_spring, stencil: structural_shear_bend, stiffness: {structural: 500, shear: 500, bend: 20},"
      " damping: 0.001, density: 0.1}\n"
      "integrator: {type: baraff_witkin, dt: 0.004, substeps: 5}\n"
      "solver: {type: eigen_pcg, eigen_pcg: {tolerance: 1.0e-4}}\n"
      "colliders:\n  - {type: plane, point: [0, -0.01, 0], normal: [0.2, 1, 0], thickness: 0.003, friction: 0.05}\n"
      "threads: 1\ngravity: [0, -9.81, 0]\nframes: 16\noutput: {lossless: true}\n";
  std::ofstream(dir / "bw.yaml") << text;
  const std::string sc = (dir / "bw.yaml").string();
  const fs::path whole = dir / "whole", parts = dir / "parts";
  ASSERT_EQ(run_real("run " + sc + " --quiet --out " + whole.string()).code, 0);
  ASSERT_EQ(run_real("run " + sc + " --quiet --frames 9 --out " + parts.string()).code, 0);
  const Result r = run_real("run --resume " + parts.string() + " --quiet --frames 16");
  ASSERT_EQ(r.code, 0) << r.out;
  expect_same_run(whole, parts);
  // The cloth lies on the plane and slides down it (slope 0.2 > friction 0.05) across the
  // restart: at frames 9 and 16 its lowest point is within a few millimetres of the plane and
  // it still moves (kinetic energy, stats.csv column 3, grows).
  double kinetic[2] = {0, 0};
  int k = 0;
  for (const char* f : {"frame_00009.obj", "frame_00016.obj"}) {
    const auto x = obj_numbers(whole / f, "v ");
    double lowest = 1e9;
    for (std::size_t i = 1; i < x.size(); i += 3) lowest = std::min(lowest, x[i] + 0.01 + 0.2 * x[i - 1]);
    EXPECT_LT(lowest, 0.006) << f;
    EXPECT_GT(lowest, -0.001) << f;
    std::ifstream st(whole / "stats.csv");
    for (std::string line; std::getline(st, line);)
      if (line.rfind(k == 0 ? "9," : "16,", 0) == 0) kinetic[k] = std::stod(line.substr(line.find(',', line.find(',') + 1) + 1));
    ++k;
  }
  EXPECT_GT(kinetic[0], 1e-6);
  EXPECT_GT(kinetic[1], kinetic[0]);
}

TEST(Plot, DrawsStatsCsvOrSaysWhatIsMissing) {
  const auto dir = scratch("plot");
  const fs::path out = dir / "out";
  ASSERT_EQ(run("run " + scene(dir, 6) + " --quiet --out " + out.string()).code, 0);
  // Without python3 on the PATH: a clear error with the fix, exit 2.
  fs::create_directories(dir / "empty");
  Result r = loom_cli_test::run_loom_shell("PATH=" + (dir / "empty").string() + " " + std::string(LOOM_EXE) + " plot " +
                                           out.string());
  EXPECT_EQ(r.code, 2) << r.out;
  EXPECT_NE(r.out.find("python3-matplotlib"), std::string::npos) << r.out;
  // A python3 that cannot import matplotlib (exit 3, as scripts/plot_run.py does then).
  {
    fs::create_directories(dir / "fake");
    std::ofstream(dir / "fake" / "python3") << "#!/bin/sh\necho 'no module named matplotlib' >&2\nexit 3\n";
    fs::permissions(dir / "fake" / "python3", fs::perms::owner_all);
    r = loom_cli_test::run_loom_shell("PATH=" + (dir / "fake").string() + ":/usr/bin:/bin " + std::string(LOOM_EXE) +
                                      " plot " + out.string());
    EXPECT_EQ(r.code, 2) << r.out;
    EXPECT_NE(r.out.find("cannot import"), std::string::npos) << r.out;
    EXPECT_NE(r.out.find("apt-get install python3-matplotlib"), std::string::npos) << r.out;
  }
  // Not a run folder.
  r = run("plot " + dir.string());
  EXPECT_EQ(r.code, 2) << r.out;
  EXPECT_NE(r.out.find("stats.csv: not found"), std::string::npos) << r.out;
  // With matplotlib (Debian's python3-matplotlib, as scripts/setup.sh installs): a PNG.
  if (std::system("/usr/bin/python3 -c 'import matplotlib' >/dev/null 2>&1") != 0)
    GTEST_SKIP() << "python3-matplotlib is not installed here; the errors above were checked";
  const fs::path png = dir / "stats.png";
  r = run("plot " + out.string() + " --out " + png.string());
  ASSERT_EQ(r.code, 0) << r.out;
  const std::string bytes = slurp(png);
  ASSERT_GT(bytes.size(), 10000u);
  EXPECT_EQ(bytes.substr(1, 3), "PNG");
}

// The other CPU integrators carry nothing between steps besides x and v; with the direct
// solvers Baraff-Witkin has no solver state either. Each continuation equals the whole run.
TEST(Resume, EveryCpuIntegratorIsExact) {
  NEED_PLUGINS("material_mass_spring", "integrator_symplectic_euler", "integrator_rk4", "integrator_harmonic_oscillation",
               "integrator_baraff_witkin", "solver_eigen_ldlt");
  const std::vector<std::pair<std::string, std::string>> combos = {
      {"symplectic_euler", "integrator: {type: symplectic_euler, dt: 2.0e-4, substeps: 20}\n"},
      {"rk4", "integrator: {type: rk4, dt: 4.0e-4, substeps: 10}\n"},
      {"harmonic_oscillation", "integrator: {type: harmonic_oscillation, dt: 4.0e-4, substeps: 10}\n"},
      {"bw_ldlt", "integrator: {type: baraff_witkin, dt: 0.004}\nsolver: {type: eigen_ldlt}\n"},
      {"bw_cholmod", "integrator: {type: baraff_witkin, dt: 0.004}\nsolver: {type: [cholmod, eigen_ldlt]}\n"},
  };
  for (const auto& [name, integrator] : combos) {
    const auto dir = scratch("resume_" + name);
    std::ofstream(dir / "s.yaml") << "mesh:\n  grid: {nx: 7, ny: 7, width: 0.4, height: 0.4}\n"
                                     "material: {type: mass_spring, stiffness: {structural: 300, shear: 300, bend: 10},"
                                     " density: 0.1}\n"
                                  << integrator << "pins: [top_corners]\nthreads: 1\nframes: 10\noutput: {lossless: true}\n";
    const std::string sc = (dir / "s.yaml").string();
    ASSERT_EQ(run_real("run " + sc + " --quiet --out " + (dir / "whole").string()).code, 0) << name;
    ASSERT_EQ(run_real("run " + sc + " --quiet --frames 4 --out " + (dir / "parts").string()).code, 0) << name;
    const Result r = run_real("run --resume " + (dir / "parts").string() + " --quiet --frames 10");
    ASSERT_EQ(r.code, 0) << name << ": " << r.out;
    SCOPED_TRACE(name);
    expect_same_run(dir / "whole", dir / "parts");
  }
}

// `loom study` prints its table; `--stability` plots the atlas (or says what is missing).
TEST(Study, PrintsItsTableAndPlotsTheStabilityAtlas) {
  NEED_PLUGINS("material_mass_spring", "integrator_symplectic_euler", "integrator_rk4");
  const auto dir = scratch("study");
  std::ofstream(dir / "s.yaml") << "mesh:\n  grid: {nx: 5, ny: 5, width: 0.5, height: 0.5}\n"
                                   "material: {type: mass_spring, stiffness: {structural: 200, shear: 200, bend: 10},"
                                   " density: 0.1}\n"
                                   "integrator: {type: symplectic_euler, dt: 1.0e-3, substeps: 1}\n"
                                   "pins: [top_corners]\nthreads: 1\nframes: 1\n";
  std::ofstream(dir / "study.yaml")
      << "times: [0.02]\nsteps: {h0: 1.0e-3, levels: 2}\nreference: {integrator: rk4, dt: 1.0e-4}\n"
         "max_seconds_per_run: 20\ncombos:\n  - {name: SE, set: {integrator.type: symplectic_euler}}\n"
         "  - {name: RK4, set: {integrator.type: rk4}}\n"
         "stability:\n  horizon: 0.05\n  h_min: 1.0e-5\n  h_max: 0.05\n  bisections: 3\n  max_strain: 1.0\n"
         "  sweep: {key: material.stiffness.structural, values: [200, 2000]}\n"
         "  combos:\n    - {name: SE, set: {integrator.type: symplectic_euler}}\n";
  const std::string args = (dir / "s.yaml").string() + " " + (dir / "study.yaml").string() + " --out " + (dir / "o").string();
  Result r = run_real("study " + args);
  ASSERT_EQ(r.code, 0) << r.out;
  // The table: a header and one row per combo, step and time (2 combos x 2 steps).
  EXPECT_NE(r.out.find("COMBO"), std::string::npos) << r.out;
  EXPECT_NE(r.out.find("RMS_ERROR"), std::string::npos) << r.out;
  int rows = 0;
  std::istringstream lines(r.out);
  for (std::string line; std::getline(lines, line);) rows += line.rfind("SE ", 0) == 0 || line.rfind("RK4 ", 0) == 0;
  EXPECT_EQ(rows, 4) << r.out;
  r = run_real("study " + args + " --stability");
  ASSERT_EQ(r.code, 0) << r.out;
  EXPECT_TRUE(fs::exists(dir / "o" / "stability.csv"));
  if (std::system("/usr/bin/python3 -c 'import matplotlib' >/dev/null 2>&1") != 0) {
    EXPECT_NE(r.out.find("no stability plot"), std::string::npos) << r.out;
    GTEST_SKIP() << "python3-matplotlib is not installed here";
  }
  const std::string png = slurp(dir / "o" / "stability.png");
  ASSERT_GT(png.size(), 5000u) << r.out;
  EXPECT_EQ(png.substr(1, 3), "PNG");
}

// A shipped scene whose material plugin reads a file relative to the scene (gnatv's
// material_file: ../materials/wool.yaml), resumed from a run folder elsewhere: the
// continuation finds the file (scene.yaml records the original scene file) and is exact.
TEST(Resume, ShippedGnatvSceneFromAnotherFolder) {
  NEED_PLUGINS("material_gnatv", "integrator_baraff_witkin", "solver_eigen_pcg");
  const auto dir = scratch("resume_wool");
  const std::string sc = std::string(LOOM_SOURCE_DIR) + "/scenes/wool_hanging_32.yaml";
  const std::string common = " --quiet --set output.lossless=true --set integrator.substeps=2";
  ASSERT_EQ(run_real("run " + sc + common + " --frames 4 --out " + (dir / "whole").string()).code, 0);
  ASSERT_EQ(run_real("run " + sc + common + " --frames 2 --out " + (dir / "parts").string()).code, 0);
  const Result r = run_real("run --resume " + (dir / "parts").string() + " --quiet --frames 4");
  ASSERT_EQ(r.code, 0) << r.out;
  expect_same_run(dir / "whole", dir / "parts");
}

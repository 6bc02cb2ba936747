// Self-collision in whole scenes: no intersecting pair of non-adjacent triangles in any frame
// (counted by the exact test of loom/intersection_check.hpp, `loom check`, which shares no code
// with the collision code), the thickness kept, bad input refused.
#include <gtest/gtest.h>

#include <algorithm>
#include <array>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <filesystem>
#include <fstream>
#include <iterator>
#include <map>
#include <sstream>
#include <sys/wait.h>
#include <utility>

#include "loom/simulation.hpp"
#include "loom/intersection_check.hpp"
#include "loom/restart.hpp"
#include "common/csv_table.hpp"
#include "common/restart_file.hpp"

namespace fs = std::filesystem;

namespace {

struct SelfCollisionScenes : ::testing::Test {
  loom::Registry registry;
  loom::PluginLoader loader{registry};
  void SetUp() override { loom::Simulation::set_notes(false); }
  std::unique_ptr<loom::Simulation> make(const std::string& yaml) {
    return loom::Simulation::from_string(yaml, "scene.yaml", std::string(LOOM_SOURCE_DIR) + "/scenes", {}, loader);
  }
};

bool verbose() { return std::getenv("LOOM_TEST_VERBOSE") != nullptr; }

// Smallest distance between a vertex and a triangle not containing it (brute force with a box
// filter at `within`), computed here by projection, independently of the library.
double min_vertex_triangle_distance(const loom::Mesh& m, const std::vector<double>& x, double within) {
  auto d3 = [](const double* u, const double* v) { return u[0] * v[0] + u[1] * v[1] + u[2] * v[2]; };
  auto point_segment = [&](const double* p, const double* a, const double* b) {
    double ab[3], ap[3], q[3];
    for (int k = 0; k < 3; ++k) ab[k] = b[k] - a[k], ap[k] = p[k] - a[k];
    const double t = std::clamp(d3(ap, ab) / d3(ab, ab), 0.0, 1.0);
    for (int k = 0; k < 3; ++k) q[k] = ap[k] - t * ab[k];
    return std::sqrt(d3(q, q));
  };
  double best = within;
  const loom::Index nt = m.num_triangles();
  for (loom::Index v = 0; v < m.num_vertices(); ++v) {
    const double* p = &x[3 * v];
    for (loom::Index t = 0; t < nt; ++t) {
      const loom::Index* tv = &m.triangles[3 * t];
      if (v == tv[0] || v == tv[1] || v == tv[2]) continue;
      const double *a = &x[3 * tv[0]], *b = &x[3 * tv[1]], *c = &x[3 * tv[2]];
      bool far = false;
      for (int k = 0; k < 3 && !far; ++k)
        far = p[k] < std::min({a[k], b[k], c[k]}) - best || p[k] > std::max({a[k], b[k], c[k]}) + best;
      if (far) continue;
      double e1[3], e2[3], r[3];
      for (int k = 0; k < 3; ++k) e1[k] = b[k] - a[k], e2[k] = c[k] - a[k], r[k] = p[k] - a[k];
      const double A = d3(e1, e1), B = d3(e1, e2), C = d3(e2, e2), D = d3(e1, r), E = d3(e2, r);
      const double det = A * C - B * B;
      const double s = (C * D - B * E) / det, u = (A * E - B * D) / det;
      double dist;
      if (s >= 0 && u >= 0 && s + u <= 1) {
        double q[3];
        for (int k = 0; k < 3; ++k) q[k] = r[k] - s * e1[k] - u * e2[k];
        dist = std::sqrt(d3(q, q));
      } else {
        dist = std::min({point_segment(p, a, b), point_segment(p, b, c), point_segment(p, c, a)});
      }
      best = std::min(best, dist);
    }
  }
  return best;
}

struct RunResult {
  int max_intersections = 0;
  int first_bad_frame = -1;
  double min_distance = 1e300;
  long long impulses = 0;  ///< proximity + CCD impulses over the run (the contact was real)
  long long frozen = 0;
  double min_height = 1e300;  ///< lowest vertex (y) after any step: the ground plane's check
};

RunResult run_and_check(loom::Simulation& sim, int frames, double thickness) {
  RunResult r;
  const loom::Mesh& mesh = sim.scene().mesh;
  for (int f = 1; f <= frames; ++f) {
    for (int k = 0; k < sim.substeps(); ++k) {
      sim.step();
      const auto& xs = sim.scene().state.x;
      for (std::size_t i = 1; i < xs.size(); i += 3) r.min_height = std::min(r.min_height, xs[i]);
      if (const auto* sc = sim.scene().self_collision.get()) {
        r.impulses += sc->last_stats().proximity + sc->last_stats().ccd_collisions;
        r.frozen += sc->last_stats().frozen;
      }
    }
    const auto& x = sim.scene().state.x;
    const int c = static_cast<int>(loom::count_intersecting_pairs(mesh, x));
    if (c > r.max_intersections) r.max_intersections = c;
    if (c > 0 && r.first_bad_frame < 0) r.first_bad_frame = f;
    if (thickness > 0) r.min_distance = std::min(r.min_distance, min_vertex_triangle_distance(mesh, x, thickness));
    if (verbose())
      std::printf("  frame %d: %d intersecting pairs, min vertex-triangle distance %.3g\n", f, c, r.min_distance);
  }
  return r;
}

// A 0.4 m square cloth standing on its lower edge, released: it collapses onto the ground
// (friction 0.8) in folds that pile on each other, tipped over by a sideways gravity part.
std::string folding_cloth(const std::string& integrator, const std::string& self) {
  return R"(
mesh: {grid: {nx: 14, ny: 14, width: 0.4, height: 0.4, plane: xy}}
material: {type: mass_spring, stencil: structural_shear_bend, stiffness: {structural: 300, shear: 300, bend: 0.2}, damping: 0.01, density: 0.2}
integrator: )" + integrator + R"(
solver: {type: eigen_ldlt}
threads: 1
gravity: [0, -9.81, 1.5]
colliders: [{type: plane, point: [0, -0.01, 0], normal: [0, 1, 0], friction: 0.8}]
)" + self;
}

const std::array<std::string, 4> kFoldIntegrators = {
    "{type: symplectic_euler, dt: 2.0e-4, substeps: 50}", "{type: harmonic_oscillation, dt: 2.0e-4, substeps: 50}",
    "{type: rk4, dt: 2.0e-4, substeps: 50}", "{type: baraff_witkin, dt: 2.0e-3, substeps: 5}"};

constexpr double kFoldThickness = 0.004;
constexpr int kFoldFrames = 50;   // 0.5 s: the cloth has collapsed and lies in folds

// The draped-ball scene (scenes/draped_ball_*.yaml) at 24 x 24 vertices for 45 frames (0.75 s).
std::string draped_ball(const std::string& material, const std::string& integrator, const std::string& self,
                        const std::string& solver = "{type: eigen_ldlt}") {
  return R"(
mesh: {grid: {nx: 24, ny: 24, width: 1.0, height: 1.0, plane: xz}}
material: )" + material + R"(
integrator: )" + integrator + R"(
solver: )" + solver + R"(
threads: 1
colliders:
  - {type: sphere, center: [0.5, -0.35, -0.5], radius: 0.3, thickness: 0.004, friction: {static: 0.5, kinetic: 0.4},
     motion: {type: rotate, axis: [0, 1, 0], angular_velocity: 2.0}}
)" + self;
}
// At 24 x 24 the shipped springs (200, 200, 20 N/m) make a cloth too stiff to fold within a
// second; these softer springs fold it over the ball as the 128 x 128 cloth does (without
// self-collision it intersects itself from frame 20 on).
const std::string kMassSpring =
    "{type: mass_spring, stencil: structural_shear_bend, stiffness: {structural: 30, shear: 30, bend: 0.05}, damping: 0.0005, density: 0.1}";
const std::string kWool = "{type: gnatv, material_file: " LOOM_SOURCE_DIR "/materials/wool.yaml}";
constexpr double kBallThickness = 0.006;
constexpr int kBallFrames = 45;  // the frames where the unprotected scene intersects most

}  // namespace

TEST_F(SelfCollisionScenes, WithoutSelfCollisionTheFoldingClothPassesThroughItself) {
  // The control: the scene below is a real test only if it intersects when nothing prevents it.
  auto sim = make(folding_cloth(kFoldIntegrators[0], ""));
  const RunResult r = run_and_check(*sim, kFoldFrames, 0);
  EXPECT_GT(r.max_intersections, 0);
}

TEST_F(SelfCollisionScenes, FoldingClothNeverIntersectsItselfWithEveryIntegrator) {
  for (const auto& integ : kFoldIntegrators) {
    SCOPED_TRACE(integ);
    auto sim = make(folding_cloth(integ, "self_collision: {thickness: 0.004, friction: 0.3}\n"));
    const RunResult r = run_and_check(*sim, kFoldFrames, kFoldThickness);
    EXPECT_EQ(r.max_intersections, 0) << "first at frame " << r.first_bad_frame;
    // Layers rest on each other at the thickness; fast approaches may dip below it for a step.
    EXPECT_GE(r.min_distance, 0.5 * kFoldThickness);
    // The layers above must not press the lowest one into the ground (plane y = -0.01) at any
    // step: the self-collision response puts a vertex it pushed into a collider back on it.
    EXPECT_GE(r.min_height, -0.01 - 1e-9);
    EXPECT_GT(r.impulses, 0);
    if (verbose())
      std::printf("%s: min distance / thickness = %.3f, lowest vertex %.6f m, impulses %lld, frozen %lld\n",
                  integ.c_str(), r.min_distance / kFoldThickness, r.min_height, r.impulses, r.frozen);
  }
}

TEST_F(SelfCollisionScenes, WithoutSelfCollisionTheDrapedBallPassesThroughItself) {
  auto sim = make(draped_ball(kWool, "{type: baraff_witkin, dt: 2.0e-3, substeps: 8, kang_cho_damping: 0.001}", ""));
  EXPECT_GT(run_and_check(*sim, kBallFrames, 0).max_intersections, 0);
  sim = make(draped_ball(kMassSpring, "{type: symplectic_euler, dt: 2.0e-4, substeps: 83}", ""));
  EXPECT_GT(run_and_check(*sim, 25, 0).max_intersections, 0);
}

void check_draped(SelfCollisionScenes& t, const std::string& mat, const std::string& integ, int frames,
                  const std::string& solver = "{type: eigen_ldlt}") {
  SCOPED_TRACE(integ + " " + solver);
  auto sim = t.make(draped_ball(mat, integ, "self_collision: {thickness: 0.006, friction: 0.3}\n", solver));
  const RunResult r = run_and_check(*sim, frames, kBallThickness);
  EXPECT_EQ(r.max_intersections, 0) << "first at frame " << r.first_bad_frame;
  EXPECT_GE(r.min_distance, 0.5 * kBallThickness);
  EXPECT_GT(r.impulses, 0);
  if (verbose())
    std::printf("%s: min distance / thickness = %.3f, impulses %lld, frozen %lld\n", integ.c_str(),
                r.min_distance / kBallThickness, r.impulses, r.frozen);
}

TEST_F(SelfCollisionScenes, DrapedBallNeverIntersectsItselfWithTheExplicitIntegrators) {
  // 25 frames (0.42 s): the cloth has landed on the spinning ball and folds around it.
  check_draped(*this, kMassSpring, "{type: symplectic_euler, dt: 2.0e-4, substeps: 83}", 25);
  check_draped(*this, kMassSpring, "{type: harmonic_oscillation, dt: 2.0e-4, substeps: 83}", 25);
  check_draped(*this, kMassSpring, "{type: rk4, dt: 4.0e-4, substeps: 42}", 25);
}

TEST_F(SelfCollisionScenes, DrapedBallNeverIntersectsItselfWithBaraffWitkin) {
  check_draped(*this, kWool, "{type: baraff_witkin, dt: 2.0e-3, substeps: 8, kang_cho_damping: 0.001}", kBallFrames);
}

// With filtered_pcg the self-contact springs are applied matrix-free inside the solver's product
// (test_bw_contact_operator.cpp): the same guarantee.
TEST_F(SelfCollisionScenes, DrapedBallNeverIntersectsItselfWithBaraffWitkinMatrixFree) {
  check_draped(*this, kWool, "{type: baraff_witkin, dt: 2.0e-3, substeps: 8, kang_cho_damping: 0.001}", kBallFrames,
               "{type: filtered_pcg}");
}

TEST_F(SelfCollisionScenes, BadSelfCollisionKeysAreRefusedWithFileLineAndFix) {
  const std::string base = folding_cloth(kFoldIntegrators[0], "");
  const int line = static_cast<int>(std::count(base.begin(), base.end(), '\n')) + 1;
  struct Case {
    std::string text, expect;
  };
  for (const Case& c : std::vector<Case>{{"self_collision: {thickness: 0}", "thickness must be a finite number > 0"},
                                         {"self_collision: {thickness: -0.001}", "thickness must be a finite number > 0"},
                                         {"self_collision: {thickness: .nan}", "thickness must be a finite number > 0"},
                                         {"self_collision: {thickness: 0.002, friction: -0.1}", "friction must be a finite number >= 0"},
                                         {"self_collision: {friction: 0.3}", "missing 'thickness'"},
                                         {"self_collision: {thickness: 0.002, fricton: 0.3}", "fricton"},
                                         {"self_collision: 0.002", "must be a mapping"},
                                         {"self_collision: {thickness: 0.05}", "exceeds the smallest distance"}}) {
    SCOPED_TRACE(c.text);
    try {
      make(base + c.text + "\n");
      ADD_FAILURE() << "accepted";
    } catch (const loom::InputError& e) {
      const std::string msg = e.what();
      EXPECT_NE(msg.find(c.expect), std::string::npos) << msg;
      EXPECT_NE(msg.find("scene.yaml:" + std::to_string(line)), std::string::npos) << msg;
    }
  }
}

namespace {

// Two 2 x 2 sheets of 9 vertices each (the 18 positions, 3 per vertex): sheet 0 in the plane
// y = 0, sheet 1 off-centre (no coincident points) either parallel to it at height `gap` or,
// `crossing`, in the plane z = 0, through sheet 0 along the x axis.
std::vector<double> two_sheets(bool crossing, double gap) {
  std::vector<double> x;
  for (int s = 0; s < 2; ++s)
    for (int j = 0; j < 3; ++j)
      for (int i = 0; i < 3; ++i) {
        const double u = 0.1 * (i - 1) + 0.013, w = 0.1 * (j - 1) + 0.007;
        if (s == 0) x.insert(x.end(), {0.1 * (i - 1), 0.0, 0.1 * (j - 1)});
        else if (crossing) x.insert(x.end(), {u, w, 0.0});
        else x.insert(x.end(), {u, gap, w});
      }
  return x;
}

// The OBJ of two_sheets' positions (8 triangles per sheet); returns its path.
std::string write_two_sheets(const fs::path& path, const std::vector<double>& x) {
  std::ofstream obj(path);
  for (std::size_t k = 0; k < x.size(); k += 3) obj << "v " << x[k] << " " << x[k + 1] << " " << x[k + 2] << "\n";
  for (int s = 0; s < 2; ++s)
    for (int j = 0; j < 2; ++j)
      for (int i = 0; i < 2; ++i) {
        const int a = 9 * s + 3 * j + i + 1;
        obj << "f " << a << " " << a + 1 << " " << a + 4 << "\nf " << a << " " << a + 4 << " " << a + 3 << "\n";
      }
  return path.string();
}

}  // namespace

// A cloth mesh that starts intersecting itself is refused (the response keeps each pair on the
// side it starts on, so it could not undo the crossing): two 2 x 2 sheets (8 triangles each),
// one in the plane y = 0 and one in the plane z = 0, crossing along the x axis; so are two
// parallel sheets closer than the thickness (the layers would repel each other from the start).
// Without self_collision both meshes are accepted.
TEST_F(SelfCollisionScenes, ACrossingOrTooCloseStartMeshIsRefused) {
  const fs::path dir = fs::temp_directory_path() / "loom_selfcol_start_mesh";
  fs::create_directories(dir);
  auto sheets = [&](const std::string& name, bool crossing, double gap) {
    return write_two_sheets(dir / name, two_sheets(crossing, gap));
  };
  const std::string cross = sheets("cross.obj", true, 0), close = sheets("close.obj", false, 0.002);
  auto scene = [](const std::string& obj, const std::string& self) {
    return "mesh: {obj: " + obj + "}\n" +
           "material: {type: mass_spring, stencil: mesh_edges, stiffness: 300, density: 0.2}\n"
           "integrator: {type: symplectic_euler, dt: 1.0e-4}\nthreads: 1\n" + self;
  };
  // The exact check agrees that the first mesh crosses itself and the second does not.
  {
    auto sim = make(scene(cross, ""));
    EXPECT_GT(loom::count_intersecting_pairs(sim->scene().mesh, sim->scene().state.x), 0u);
    auto sim2 = make(scene(close, ""));
    EXPECT_EQ(loom::count_intersecting_pairs(sim2->scene().mesh, sim2->scene().state.x), 0u);
  }
  struct Case {
    std::string obj, expect;
  };
  for (const Case& c : std::vector<Case>{{cross, "intersects itself"}, {close, "exceeds the smallest distance"}}) {
    SCOPED_TRACE(c.obj);
    try {
      make(scene(c.obj, "self_collision: {thickness: 0.005}\n"));
      ADD_FAILURE() << "accepted";
    } catch (const loom::InputError& e) {
      const std::string msg = e.what();
      EXPECT_NE(msg.find(c.expect), std::string::npos) << msg;
      EXPECT_NE(msg.find("scene.yaml:5"), std::string::npos) << msg;
      EXPECT_NE(msg.find("Fix:"), std::string::npos) << msg;
    }
  }
  // Farther apart than the thickness: accepted.
  EXPECT_NO_THROW(make(scene(sheets("apart.obj", false, 0.02), "self_collision: {thickness: 0.005}\n")));
  fs::remove_all(dir);
}

namespace {

// Runs a shell command; returns its exit code (-1 if it did not exit) and its output.
std::pair<int, std::string> run_command(const std::string& cmd) {
  FILE* p = popen((cmd + " 2>&1").c_str(), "r");
  std::string out;
  std::array<char, 4096> buf{};
  while (fgets(buf.data(), buf.size(), p)) out += buf.data();
  const int status = pclose(p);
  return {WIFEXITED(status) ? WEXITSTATUS(status) : -1, out};
}

// Writes restart.bin with this test's own encoder (tests/common/restart_file.hpp).
void write_restart_file(const fs::path& path, const loom::RestartData& r) {
  std::ofstream(path, std::ios::binary) << loom_test::restart_file_bytes(r);
}

// An empty folder `name` in the temporary directory.
fs::path fresh_dir(const std::string& name) {
  const fs::path dir = fs::temp_directory_path() / name;
  fs::remove_all(dir);
  fs::create_directories(dir);
  return dir;
}

// The scene of the two sheets 20 mm apart (written to dir/sheets.obj), with self-collision.
std::string two_sheets_scene(const fs::path& dir) {
  const std::string obj = write_two_sheets(dir / "sheets.obj", two_sheets(false, 0.02));
  return "mesh: {obj: " + obj + "}\n" +
         "material: {type: mass_spring, stencil: mesh_edges, stiffness: 300, density: 0.2}\n"
         "integrator: {type: symplectic_euler, dt: 1.0e-4, substeps: 20}\nthreads: 1\n"
         "gravity: [0, -9.81, 0]\nself_collision: {thickness: 0.005}\n";
}

}  // namespace

// `loom run --resume` gives the restored state the start mesh's crossing check: a restart.bin
// whose cloth crosses itself (two_sheets' crossing positions, put into the restart point of a
// run of the same two sheets 20 mm apart) is refused with exit 2, one error naming the file, the
// count of the exact check, a pair and the fix, and the run folder is left as it was; the run's
// own restart point, re-encoded by this test, resumes (and stays free of crossings by `loom
// check`), and so does a state whose layers are closer than the thickness without crossing.
TEST_F(SelfCollisionScenes, AResumedStateThatCrossesItselfIsRefused) {
  const fs::path dir = fresh_dir("loom_selfcol_resume");
  const std::string yaml = two_sheets_scene(dir);
  std::ofstream(dir / "scene.yaml") << yaml;
  const std::string exe = std::string(LOOM_EXE), run = (dir / "run").string();
  auto [rc0, out0] = run_command(exe + " run " + (dir / "scene.yaml").string() + " --quiet --frames 1 --out " + run);
  ASSERT_EQ(rc0, 0) << out0;
  const loom::RestartData clean = loom::read_restart(run);
  ASSERT_EQ(clean.frame, 1);
  ASSERT_EQ(clean.x.size(), 54u);
  const loom::Mesh mesh = make(yaml)->scene().mesh;

  // The crossing state: the exact check (that of `loom check`) counts its pairs.
  loom::RestartData crossing = clean;
  crossing.x = two_sheets(true, 0);
  const std::size_t ncross = loom::count_intersecting_pairs(mesh, crossing.x);
  ASSERT_GT(ncross, 0u);
  ASSERT_EQ(loom::count_intersecting_pairs(mesh, clean.x), 0u);
  write_restart_file(fs::path(run) / "restart.bin", crossing);
  auto [rc1, out1] = run_command(exe + " run --resume " + run + " --quiet --frames 2");
  EXPECT_EQ(rc1, 2) << out1;
  if (verbose()) std::printf("%s", out1.c_str());
  EXPECT_NE(out1.find(run + "/restart.bin: the cloth in this state intersects itself (" + std::to_string(ncross) +
                      " pairs of non-adjacent triangles, e.g. triangles "),
            std::string::npos)
      << out1;
  EXPECT_NE(out1.find("Fix:"), std::string::npos) << out1;
  EXPECT_EQ(std::count(out1.begin(), out1.end(), '\n'), 1) << out1;  // one error, nothing else
  EXPECT_FALSE(fs::exists(fs::path(run) / "frame_00002.obj"));
  EXPECT_EQ(loom::read_restart(run).frame, 1);

  // The run's own state, written by this test's encoder: resumes to frame 2, no crossing.
  write_restart_file(fs::path(run) / "restart.bin", clean);
  auto [rc2, out2] = run_command(exe + " run --resume " + run + " --quiet --frames 2");
  EXPECT_EQ(rc2, 0) << out2;
  EXPECT_TRUE(fs::exists(fs::path(run) / "frame_00002.obj"));

  // Layers 2 mm apart (under the 5 mm thickness) but not crossing: resumed too, and pushed apart.
  loom::RestartData close = loom::read_restart(run);
  ASSERT_EQ(close.frame, 2);
  close.x = two_sheets(false, 0.002);
  ASSERT_EQ(loom::count_intersecting_pairs(mesh, close.x), 0u);
  write_restart_file(fs::path(run) / "restart.bin", close);
  auto [rc3, out3] = run_command(exe + " run --resume " + run + " --quiet --frames 3");
  EXPECT_EQ(rc3, 0) << out3;
  EXPECT_TRUE(fs::exists(fs::path(run) / "frame_00003.obj"));
  // The independent judge over every frame written (0-3): no intersecting pair.
  auto [rc4, out4] = run_command(exe + " check " + run);
  EXPECT_EQ(rc4, 0) << out4;
  fs::remove_all(dir);
}

// A state that a program sets through Scene::state gets the same crossing check at the first
// step (the scene's own start and a resumed state are checked when they are read): the crossing
// two sheets are refused with one InputError naming the count of the exact check and the fix;
// Simulation::accept_state() runs self-collision on them anyway (the benchmark of a tangled
// start); a state that does not cross passes, and only the first step pays for the check.
TEST_F(SelfCollisionScenes, AStateSetByAProgramThatCrossesItselfIsRefused) {
  const fs::path dir = fresh_dir("loom_selfcol_program_state");
  const std::string yaml = two_sheets_scene(dir);
  const std::vector<double> crossing = two_sheets(true, 0);
  {
    auto sim = make(yaml);
    const std::size_t ncross = loom::count_intersecting_pairs(sim->scene().mesh, crossing);
    ASSERT_GT(ncross, 0u);
    sim->scene().state.x = crossing;
    try {
      sim->step();
      ADD_FAILURE() << "a crossing state set by the program was stepped";
    } catch (const loom::InputError& e) {
      const std::string m = e.what();
      EXPECT_NE(m.find("the state set through Scene::state intersects itself (" + std::to_string(ncross) +
                       " pairs of non-adjacent triangles"),
                std::string::npos)
          << m;
      EXPECT_NE(m.find("Fix:"), std::string::npos) << m;
      EXPECT_NE(m.find("accept_state"), std::string::npos) << m;
    }
    EXPECT_EQ(sim->scene().state.step, 0);  // nothing was stepped
  }
  {  // accepted: it runs, and the response keeps the crossing rather than adding to it
    auto sim = make(yaml);
    sim->scene().state.x = crossing;
    sim->accept_state();
    for (int k = 0; k < 5; ++k) EXPECT_NO_THROW(sim->step());
    EXPECT_EQ(sim->scene().state.step, 5);
  }
  {  // another state without crossings (the layers 10 mm apart): stepped
    auto sim = make(yaml);
    sim->scene().state.x = two_sheets(false, 0.01);
    for (int k = 0; k < 5; ++k) EXPECT_NO_THROW(sim->step());
    ASSERT_EQ(loom::count_intersecting_pairs(sim->scene().mesh, sim->scene().state.x), 0u);
  }
  {  // set after the first step: not checked any more (documented: only the first step checks)
    auto sim = make(yaml);
    sim->step();
    sim->scene().state.x = crossing;
    EXPECT_NO_THROW(sim->step());
  }
  fs::remove_all(dir);
}

TEST_F(SelfCollisionScenes, CliExitsWithCode2OnABadThickness) {
  const fs::path dir = fs::temp_directory_path() / "loom_selfcol_cli";
  fs::remove_all(dir);
  fs::create_directories(dir);
  std::ofstream(dir / "bad.yaml") << folding_cloth(kFoldIntegrators[0], "self_collision: {thickness: -1}\n");
  const auto [rc, out] = run_command(std::string(LOOM_EXE) + " validate " + (dir / "bad.yaml").string());
  EXPECT_EQ(rc, 2) << out;
  EXPECT_NE(out.find("bad.yaml:"), std::string::npos) << out;
  EXPECT_NE(out.find("Fix:"), std::string::npos) << out;
}

TEST_F(SelfCollisionScenes, StatsOfAStepAreReported) {
  auto sim = make(folding_cloth(kFoldIntegrators[0], "self_collision: {thickness: 0.004, friction: 0.3}\n"));
  // 0.5 s: the cloth collapses into folds. The candidate lists hold only pairs that can come
  // within the thickness before they are rebuilt, so they fill once layers approach.
  const int steps = 2500;
  loom::Index most_candidates = 0, impulses = 0;
  int rebuilds = 0;
  for (int k = 0; k < steps; ++k) {
    sim->step();
    const auto& st = sim->scene().self_collision->last_stats();
    EXPECT_GE(st.ccd_iterations, 1);
    EXPECT_EQ(st.rebuilt, st.rebuilds > 0 || st.refreshed > 0);
    most_candidates = std::max(most_candidates, st.candidates_vt + st.candidates_ee);
    impulses += st.proximity + st.ccd_collisions;
    rebuilds += st.rebuilds;
  }
  EXPECT_GT(most_candidates, 0);
  EXPECT_GT(impulses, 0);
  // The lists are reused across steps: a vertex moves at most ~0.5 mm per step of 2e-4 s here
  // (below 2.5 m/s), and a rebuild gives each vertex at least half the thickness (2 mm) of room.
  EXPECT_GE(rebuilds, 1);
  EXPECT_LT(rebuilds, steps / 2);
}

namespace {

// stats.csv as rows of named columns; every row must have as many fields as the header.
std::vector<std::map<std::string, std::string>> read_stats(const fs::path& path, std::string* header_out = nullptr) {
  const loom_test::CsvTable t = loom_test::read_csv_table(path);
  if (header_out) {
    header_out->clear();
    for (std::size_t k = 0; k < t.header.size(); ++k) *header_out += (k ? "," : "") + t.header[k];
  }
  for (const auto& r : t.rows) EXPECT_EQ(r.size(), t.header.size()) << path;
  return t.by_name();
}

}  // namespace

// What a run says about self-collision (docs/OUTPUT.md, docs/CONTACT.md): stats.csv's five
// columns per frame and the summary line of `loom run`. The folding cloth collapses into folds
// within its 0.5 s, so there are impulses. The per-frame impulses, frozen vertices and list
// rebuilds must equal an independent count: the same scene stepped in this process, summing
// SelfCollision::last_stats() step by step (the run is deterministic on one thread; baraff_witkin's
// rebuilds from the totals, its search rebuilds outside last_stats()); the self-collision time is part of the
// step's; baraff_witkin reports the self-contacts of its solves. A scene without self_collision
// has none of the columns, and a run whose stats.csv was begun without them resumes without them.
TEST_F(SelfCollisionScenes, StatsCsvAndTheSummarySayWhatSelfCollisionDid) {
  const fs::path dir = fresh_dir("loom_selfcol_stats");
  const std::string self = "self_collision: {thickness: 0.004, friction: 0.3}\n";
  const std::string exe = std::string(LOOM_EXE);
  const int frames = kFoldFrames;
  for (const int which : {0, 3}) {  // symplectic_euler, baraff_witkin
    const std::string yaml = folding_cloth(kFoldIntegrators[which], self);
    const fs::path scene = dir / ("fold" + std::to_string(which) + ".yaml"), out = dir / ("run" + std::to_string(which));
    std::ofstream(scene) << yaml;
    auto [rc, text] = run_command(exe + " run " + scene.string() + " --frames " + std::to_string(frames) + " --out " + out.string());
    ASSERT_EQ(rc, 0) << text;
    std::string header;
    const auto rows = read_stats(out / "stats.csv", &header);
    ASSERT_EQ(rows.size(), static_cast<std::size_t>(frames + 1));
    EXPECT_NE(header.find(",self_collision_ms_per_step,self_collision_impulses,self_collision_frozen,self_collision_contacts,"
                          "self_collision_rebuilds"),
              std::string::npos)
        << header;
    // The independent count.
    auto sim = make(yaml);
    long long impulses_total = 0, frozen_total = 0, rebuilds_total = 0;
    double contacts_max = 0;
    for (int f = 1; f <= frames; ++f) {
      long long impulses = 0, frozen = 0, rebuilds = 0;
      const long long rebuilds_before = sim->scene().self_collision->totals().rebuilds;
      for (int k = 0; k < sim->substeps(); ++k) {
        sim->step();
        const auto& st = sim->scene().self_collision->last_stats();
        impulses += st.proximity + st.ccd_collisions;
        frozen += st.frozen;
        rebuilds += st.rebuilds;  // the after-step pass's (baraff_witkin's search rebuilds too: below)
      }
      // symplectic_euler rebuilds only in the after-step pass, so its step-by-step count is the
      // whole; baraff_witkin's search rebuilds before it, counted by the run's totals.
      if (which == 3) rebuilds = sim->scene().self_collision->totals().rebuilds - rebuilds_before;
      const auto& row = rows[static_cast<std::size_t>(f)];
      EXPECT_EQ(std::stoll(row.at("self_collision_impulses")), impulses) << "frame " << f << ", integrator " << which;
      EXPECT_EQ(std::stoll(row.at("self_collision_frozen")), frozen) << "frame " << f << ", integrator " << which;
      EXPECT_EQ(std::stoll(row.at("self_collision_rebuilds")), rebuilds) << "frame " << f << ", integrator " << which;
      const double ms = std::stod(row.at("self_collision_ms_per_step")), wall = std::stod(row.at("wall_ms_per_step"));
      EXPECT_GT(ms, 0.0) << "frame " << f;
      EXPECT_LE(ms, wall) << "frame " << f << ": self-collision is part of the step";
      const double contacts = std::stod(row.at("self_collision_contacts"));
      if (which == 0) EXPECT_EQ(contacts, 0.0) << "frame " << f;
      contacts_max = std::max(contacts_max, contacts);
      impulses_total += impulses;
      frozen_total += frozen;
      rebuilds_total += rebuilds;
    }
    EXPECT_GT(rebuilds_total, 0) << "the lists were built: the column is not vacuous";
    EXPECT_NE(text.find("candidate lists rebuilt " + std::to_string(rebuilds_total) + " times"), std::string::npos) << text;
    if (which == 0) EXPECT_GT(impulses_total, 0) << "the layers met: the check is not vacuous";
    if (which == 3) EXPECT_GT(contacts_max, 0.0) << "baraff_witkin entered self-contacts into its solves";
    // The summary line: the run's totals.
    const std::string want = std::to_string(impulses_total) + " impulses (";
    EXPECT_NE(text.find("loom: self-collision: "), std::string::npos) << text;
    EXPECT_NE(text.find(want), std::string::npos) << want << "\n" << text;
    EXPECT_NE(text.find(std::to_string(frozen_total) + " vertices frozen by the fail-safe"), std::string::npos) << text;
    if (which == 3) EXPECT_NE(text.find("the integrator's self-contact search"), std::string::npos) << text;
    if (verbose()) std::printf("%s", text.c_str());
  }
  // Without self_collision: no such columns and no summary line.
  {
    const fs::path scene = dir / "plain.yaml", out = dir / "plain";
    std::ofstream(scene) << folding_cloth(kFoldIntegrators[0], "");
    auto [rc, text] = run_command(exe + " run " + scene.string() + " --frames 2 --out " + out.string());
    ASSERT_EQ(rc, 0) << text;
    std::string header;
    read_stats(out / "stats.csv", &header);
    EXPECT_EQ(header.find("self_collision"), std::string::npos) << header;
    EXPECT_EQ(text.find("loom: self-collision"), std::string::npos) << text;
  }
  // A run begun without the columns (a stats.csv written before they existed) resumes without
  // them; one begun with the first four but without the rebuilds' column (added later) resumes
  // with the four.
  fs::copy(dir / "run0", dir / "run0b", fs::copy_options::recursive);
  for (const int dropped : {5, 1}) {
    const fs::path out = dir / (dropped == 5 ? "run0" : "run0b");
    std::ifstream in(out / "stats.csv");
    std::string text((std::istreambuf_iterator<char>(in)), {});
    in.close();
    std::string old;
    std::stringstream ls(text);
    for (std::string line; std::getline(ls, line);) {
      for (int k = 0; k < dropped; ++k) line.erase(line.rfind(','));  // drop the last columns
      old += line + "\n";
    }
    std::ofstream(out / "stats.csv", std::ios::trunc) << old;
    auto [rc, t2] = run_command(exe + " run --resume " + out.string() + " --quiet --frames " + std::to_string(frames + 2));
    ASSERT_EQ(rc, 0) << t2;
    std::string header;
    const auto rows = read_stats(out / "stats.csv", &header);  // every row as many fields as the header
    EXPECT_EQ(rows.size(), static_cast<std::size_t>(frames + 3));
    if (dropped == 5) {
      EXPECT_EQ(header.find("self_collision"), std::string::npos) << header;
    } else {
      EXPECT_NE(header.find(",self_collision_contacts"), std::string::npos) << header;
      EXPECT_EQ(header.find("self_collision_rebuilds"), std::string::npos) << header;
      EXPECT_GT(std::stod(rows.back().at("self_collision_ms_per_step")), 0.0) << "the resumed frames have the four";
    }
  }
  fs::remove_all(dir);
}

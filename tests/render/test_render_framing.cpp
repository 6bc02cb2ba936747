// `loom render`'s framing: the camera fits the whole sequence, and a ground with the cloth's
// shadow is drawn (render.fit, render.ground; framework/cli/render_framing.cpp and
// plugins/renderers/gl/ground.cpp).
#include <gtest/gtest.h>

#include <sys/wait.h>

#include <array>
#include <cmath>
#include <cstdio>
#include <filesystem>
#include <fstream>
#include <string>
#include <vector>

#include "gl_renderer.hpp"
#include "loom/mesh.hpp"

namespace fs = std::filesystem;
using namespace loom;

namespace {

int run(const std::string& cmd, std::string& out) {
  out.clear();
  FILE* p = popen((cmd + " 2>&1").c_str(), "r");
  std::array<char, 4096> buf{};
  while (fgets(buf.data(), buf.size(), p)) out += buf.data();
  const int status = pclose(p);
  return WIFEXITED(status) ? WEXITSTATUS(status) : -1;
}

// A run folder with one frame per offset: an 8 x 8 grid of 1 m (plane xy or xz) moved by it.
std::string make_run(const std::string& name, const std::vector<std::array<double, 3>>& offsets, GridPlane plane,
                     const std::string& scene_extra) {
  const fs::path dir = fs::temp_directory_path() / ("loom_framing_" + name);
  fs::remove_all(dir);
  fs::create_directories(dir);
  const Mesh m = make_grid(8, 8, 1.0, 1.0, plane);
  for (std::size_t f = 0; f < offsets.size(); ++f) {
    char file[32];
    std::snprintf(file, sizeof file, "frame_%05zu.obj", f);
    std::ofstream o(dir / file);
    o << "# Loom frame: t = " << 0.1 * double(f) << " s\n";
    for (Index i = 0; i < m.num_vertices(); ++i)
      o << "v " << m.positions[3 * i] + offsets[f][0] << " " << m.positions[3 * i + 1] + offsets[f][1] << " "
        << m.positions[3 * i + 2] + offsets[f][2] << "\n";
    for (Index t = 0; t < m.num_triangles(); ++t)
      o << "f " << m.triangles[3 * t] + 1 << " " << m.triangles[3 * t + 1] + 1 << " " << m.triangles[3 * t + 2] + 1 << "\n";
  }
  std::ofstream(dir / "scene.yaml") << "render:\n  type: gl\n  width: 160\n  height: 120\n  supersample: 1\n  video: off\n"
                                    << scene_extra;
  return dir.string();
}

std::vector<unsigned char> image(const std::string& path) {
  int w = 0, h = 0;
  return render::read_png(path, w, h);
}

// Pixels within tol of rgb (0..255).
std::size_t count_near(const std::vector<unsigned char>& img, const double rgb[3], double tol) {
  std::size_t n = 0;
  for (std::size_t p = 0; p + 2 < img.size(); p += 3)
    n += std::abs(img[p] - rgb[0]) <= tol && std::abs(img[p + 1] - rgb[1]) <= tol && std::abs(img[p + 2] - rgb[2]) <= tol;
  return n;
}

const double kWhite[3] = {255, 255, 255};

}  // namespace

TEST(RenderFraming, TheCameraFitsTheWholeSequence) {
  // Frame 1 is the cloth moved 4 m to the side: a camera fitted to frame 0 loses it.
  const std::string dir = make_run("fit", {{0, 0, 0}, {4, 0, 0}}, GridPlane::XY, "  ground: false\n");
  std::string out;
  int rc = run(std::string(LOOM_EXE) + " render " + dir + " --quiet", out);
  if (rc != 0 && out.find("EGL") != std::string::npos) GTEST_SKIP() << "no EGL context: " << out;
  ASSERT_EQ(rc, 0) << out;
  const std::size_t pixels = 160 * 120;
  for (const char* f : {"frame_00000.png", "frame_00001.png"}) {
    const auto img = image(dir + "/render/" + f);
    EXPECT_GT(pixels - count_near(img, kWhite, 0), pixels / 50) << f << ": the cloth is not in the picture";
  }
  rc = run(std::string(LOOM_EXE) + " render " + dir + " --quiet --set render.fit=first_frame --out " + dir + "/first", out);
  ASSERT_EQ(rc, 0) << out;
  EXPECT_GT(pixels - count_near(image(dir + "/first/frame_00000.png"), kWhite, 0), pixels / 20);
  EXPECT_EQ(pixels - count_near(image(dir + "/first/frame_00001.png"), kWhite, 0), 0u)
      << "with fit: first_frame, the moved cloth should leave the picture (else this test proves nothing)";
  rc = run(std::string(LOOM_EXE) + " render " + dir + " --quiet --set render.fit=everything", out);
  EXPECT_EQ(rc, 2) << out;
  EXPECT_NE(out.find("sequence"), std::string::npos) << out;
  fs::remove_all(dir);
}

TEST(RenderFraming, GroundAndShadowUnderTheLowestPoint) {
  // A flat cloth (plane xz) at height 0, then lifted by 0.6 m: the ground lies under frame 0,
  // and in frame 1 the cloth's shadow falls on it. The light is given, so the expected colours
  // follow from the ground's albedo: lit = albedo (ambient + intensity n.l), shadow = albedo
  // ambient, both in display space (gamma 2.2).
  const std::string light = "  light: {direction: [0.3, 1.0, 0.2], intensity: 0.8, ambient: 0.2, color: [1, 1, 1]}\n";
  const std::string dir = make_run("ground", {{0, 0, 0}, {0, 0.6, 0}}, GridPlane::XZ, light);
  std::string out;
  int rc = run(std::string(LOOM_EXE) + " render " + dir + " --quiet", out);
  if (rc != 0 && out.find("EGL") != std::string::npos) GTEST_SKIP() << "no EGL context: " << out;
  ASSERT_EQ(rc, 0) << out;
  const float albedo[3] = {render::GlRenderer::kGroundAlbedo.x, render::GlRenderer::kGroundAlbedo.y,
                           render::GlRenderer::kGroundAlbedo.z};
  const double ndotl = 1.0 / std::sqrt(0.3 * 0.3 + 1.0 + 0.2 * 0.2);
  double lit[3], shadow[3];
  for (int c = 0; c < 3; ++c) {
    lit[c] = 255.0 * std::pow(albedo[c] * (0.2 + 0.8 * ndotl), 1.0 / 2.2);
    shadow[c] = 255.0 * std::pow(albedo[c] * 0.2, 1.0 / 2.2);
  }
  const std::size_t pixels = 160 * 120;
  const auto lifted = image(dir + "/render/frame_00001.png");
  EXPECT_GT(count_near(lifted, lit, 2.0), pixels / 5) << "the lit ground covers less than a fifth of the picture";
  const std::size_t shadow_on = count_near(lifted, shadow, 2.0);
  EXPECT_GT(shadow_on, pixels / 100) << "no shadow on the ground";
  // Without the ground: no ground colour, no shadow colour.
  rc = run(std::string(LOOM_EXE) + " render " + dir + " --quiet --set render.ground=false --out " + dir + "/bare", out);
  ASSERT_EQ(rc, 0) << out;
  const auto bare = image(dir + "/bare/frame_00001.png");
  EXPECT_LT(count_near(bare, lit, 2.0), pixels / 200);
  EXPECT_LT(count_near(bare, shadow, 2.0) * 10, shadow_on);
  // A plane collider is the scene's ground: no second one.
  std::ofstream(dir + "/scene.yaml", std::ios::app) << "colliders: [{type: plane, point: [0, -0.5, 0]}]\n";
  rc = run(std::string(LOOM_EXE) + " render " + dir + " --quiet --out " + dir + "/plane", out);
  ASSERT_EQ(rc, 0) << out;
  EXPECT_LT(count_near(image(dir + "/plane/frame_00001.png"), lit, 2.0), pixels / 200);
  fs::remove_all(dir);
}

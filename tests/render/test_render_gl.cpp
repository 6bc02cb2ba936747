// The gl renderer: golden image against the CPU reference, determinism, bad input, CLI.
#include <gtest/gtest.h>

#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <filesystem>
#include <fstream>
#include <memory>
#include <sstream>
#include <string>

#include "common/tube_obj.hpp"
#include "gl_renderer.hpp"
#include "loom/common.hpp"
#include "loom/mesh.hpp"
#include "loom/params.hpp"

namespace fs = std::filesystem;
using namespace loom;
using namespace loom::render;

namespace {

// Creates the renderer; skips the test (with the reason) where no EGL context can be made.
std::unique_ptr<GlRenderer> make_renderer_or_skip(const RenderSettings& s, const Mesh& mesh, std::string& skip) {
  auto r = std::make_unique<GlRenderer>(s);
  try {
    r->begin(mesh);
  } catch (const std::runtime_error& e) {
    if (std::string(e.what()).find("EGL") == std::string::npos) throw;
    skip = e.what();
    return nullptr;
  }
  return r;
}

#define BEGIN_OR_SKIP(var, settings, mesh)                     \
  std::string skip_reason_;                                    \
  auto var = make_renderer_or_skip(settings, mesh, skip_reason_); \
  if (!var) GTEST_SKIP() << "no EGL context: " << skip_reason_

std::string temp_dir(const std::string& name) {
  const fs::path d = fs::temp_directory_path() / ("loom_render_test_" + name + "_" + std::to_string(::getpid()));
  fs::remove_all(d);
  fs::create_directories(d);
  return d.string();
}

RenderSettings swatch_settings(float mode, float mdf) {
  RenderSettings s;
  s.width = s.height = 128;
  s.supersample = 1;
  s.fabric = default_fabric();
  s.fabric.n_w = 2;
  s.fabric.n_pi = 1;
  s.fabric.n_sigma = 1;
  s.fabric.density_u = s.fabric.density_v = 9.0f;
  s.fabric.yarn_curvature = 0.7f;
  s.fabric.fibre_curvature = 0.35f;
  s.fabric.twists = 2.0f;
  s.fabric.alpha_along = 0.12f;
  s.fabric.alpha_across = 0.45f;
  s.fabric.specular = glm::vec3(0.25f);
  s.fabric.mode = mode;
  s.fabric.mdf = mdf;
  s.camera.has_position = s.camera.has_target = true;
  s.camera.position = glm::vec3(0.25f, 0.15f, 1.3f);
  s.camera.target = glm::vec3(0.5f, 0.5f, 0.0f);
  s.camera.fov_deg = 40.0f;
  s.light.has_direction = true;
  s.light.direction = glm::normalize(glm::vec3(0.35f, 0.6f, 1.0f));
  s.background = glm::vec3(0.1f, 0.2f, 0.3f);
  return s;
}

unsigned char to_byte(float c) { return static_cast<unsigned char>(std::floor(c * 255.0f + 0.5f)); }

// CPU reference of the flat unit swatch z = 0, (x, y) in [0,1]^2, uv = (x, y): ray cast per
// pixel centre, shaded with the same shading.glsl functions.
std::vector<unsigned char> cpu_swatch(const GlRenderer& r) {
  const RenderSettings& s = r.settings();
  const Camera& cam = r.camera();
  std::vector<unsigned char> img(std::size_t(s.width) * s.height * 3);
  const glm::vec3 light = s.light.color * s.light.intensity, ambient = s.light.color * s.light.ambient;
  for (int y = 0; y < s.height; ++y)
    for (int x = 0; x < s.width; ++x) {
      const glm::vec3 d = cam.ray(x + 0.5f, y + 0.5f);
      glm::vec3 rgb = s.background;
      if (std::abs(d.z) > 1e-9f) {
        const float t = -cam.eye.z / d.z;
        const glm::vec3 p = cam.eye + t * d;
        if (t > 0 && p.x >= 0 && p.x <= 1 && p.y >= 0 && p.y <= 1) {
          const glm::vec3 c = shading::shade_world(s.fabric, glm::vec2(p.x, p.y), glm::vec3(0, 0, 1),
                                                   glm::vec3(1, 0, 0), -d, r.light_dir(), light, ambient);
          rgb = shading::display_color(c, s.exposure);
        }
      }
      for (int k = 0; k < 3; ++k) img[(std::size_t(y) * s.width + x) * 3 + k] = to_byte(rgb[k]);
    }
  return img;
}

struct ImageDiff {
  double mean = 0;           // mean absolute difference per channel, in 8-bit levels
  double frac_over = 0;      // fraction of pixels with a channel off by more than `level`
  int max = 0;
};
ImageDiff compare(const std::vector<unsigned char>& a, const std::vector<unsigned char>& b, int level) {
  ImageDiff d;
  std::size_t over = 0, n = a.size() / 3;
  for (std::size_t p = 0; p < n; ++p) {
    int m = 0;
    for (int k = 0; k < 3; ++k) {
      const int e = std::abs(int(a[3 * p + k]) - int(b[3 * p + k]));
      d.mean += e;
      m = std::max(m, e);
    }
    d.max = std::max(d.max, m);
    over += m > level;
  }
  d.mean /= double(a.size());
  d.frac_over = double(over) / double(n);
  return d;
}

}  // namespace

// Golden image: GPU (llvmpipe here) against the CPU reference. Stated tolerance: mean absolute
// difference <= 0.25 levels (of 255) per channel, and at most 0.5% of the pixels with a channel
// more than 2 levels off (pixels whose centre falls within float rounding of a weave element
// boundary may take the neighbouring element on one side).
TEST(GlRenderer, GoldenSwatchMatchesCpuReference) {
  const Mesh swatch = make_grid(5, 5, 1.0, 1.0, GridPlane::XY);
  for (float mdf : {shading::LOOM_MDF_WARD, shading::LOOM_MDF_ASHIKHMIN})
    for (float mode : {shading::LOOM_MODE_FLAT, shading::LOOM_MODE_NORMAL_MAP, shading::LOOM_MODE_ROTATE_EXACT,
                       shading::LOOM_MODE_ROTATE_PAPER}) {
      BEGIN_OR_SKIP(r, swatch_settings(mode, mdf), swatch);
      const auto gpu = r->render_image(swatch.positions);
      const auto cpu = cpu_swatch(*r);
      const ImageDiff d = compare(gpu, cpu, 2);
      std::printf("  [%s] mdf %.0f mode %.0f: mean |diff| %.4f levels, %.3f%% pixels > 2 levels, max %d\n",
                  r->gl_renderer().c_str(), mdf, mode, d.mean, 100.0 * d.frac_over, d.max);
      EXPECT_LE(d.mean, 0.25) << "mdf " << mdf << " mode " << mode;
      EXPECT_LE(d.frac_over, 0.005) << "mdf " << mdf << " mode " << mode << " max " << d.max;
      // The swatch covers a good part of the image and has texture (the test can see a difference).
      std::size_t bg = 0;
      for (std::size_t p = 0; p < cpu.size() / 3; ++p) bg += cpu[3 * p] == to_byte(0.1f) && cpu[3 * p + 2] == to_byte(0.3f);
      EXPECT_LT(bg, cpu.size() / 3 / 2);
    }
}

TEST(GlRenderer, GoldenComparisonDetectsAWrongMode) {
  // The comparison above can fail: normal mapping drawn on the GPU is far from MDF rotation on the CPU.
  const Mesh swatch = make_grid(5, 5, 1.0, 1.0, GridPlane::XY);
  BEGIN_OR_SKIP(r, swatch_settings(shading::LOOM_MODE_NORMAL_MAP, shading::LOOM_MDF_WARD), swatch);
  const auto gpu = r->render_image(swatch.positions);
  GlRenderer other(swatch_settings(shading::LOOM_MODE_ROTATE_EXACT, shading::LOOM_MDF_WARD));
  other.begin(swatch);
  const auto cpu = cpu_swatch(other);
  const ImageDiff d = compare(gpu, cpu, 2);
  EXPECT_GT(d.frac_over, 0.05);
}

namespace {
// A curved cloth: a 48x48 grid with a travelling wave, as a simulated frame would be.
std::vector<double> wavy(const Mesh& m, double phase) {
  std::vector<double> x = m.positions;
  for (std::size_t i = 0; i < x.size(); i += 3) {
    x[i + 2] = 0.08 * std::sin(7.0 * x[i] + phase) * std::cos(5.0 * x[i + 1]);
    x[i + 1] -= 0.02 * std::sin(9.0 * x[i] * x[i + 1]);
  }
  return x;
}
}  // namespace

TEST(GlRenderer, RenderOfAFrameIsDeterministic) {
  const Mesh cloth = make_grid(48, 48, 1.0, 1.0, GridPlane::XY);
  RenderSettings s;
  s.width = 160;
  s.height = 90;
  s.supersample = 2;
  BEGIN_OR_SKIP(a, s, cloth);
  const auto x = wavy(cloth, 0.3);
  const auto img1 = a->render_image(x);
  const auto other = a->render_image(wavy(cloth, 1.3));
  const auto img2 = a->render_image(x);
  EXPECT_EQ(img1, img2);
  EXPECT_NE(img1, other);
  GlRenderer b(s);
  b.begin(cloth);
  EXPECT_EQ(b.render_image(x), img1);
  // render() writes exactly that image as a PNG.
  const std::string dir = temp_dir("det");
  b.render(x, dir + "/f.png");
  int w = 0, h = 0;
  const auto back = read_png(dir + "/f.png", w, h);
  EXPECT_EQ(w, 160);
  EXPECT_EQ(h, 90);
  EXPECT_EQ(back, img1);
  fs::remove_all(dir);
}

TEST(GlRenderer, DefaultCameraFramesTheCloth) {
  // Hanging (xy) and flat (xz) cloth: the default camera sees all of it, and it fills a good part.
  for (GridPlane plane : {GridPlane::XY, GridPlane::XZ}) {
    const Mesh cloth = make_grid(16, 16, 2.0, 1.0, plane);
    RenderSettings s;
    s.width = 128;
    s.height = 72;
    s.supersample = 1;
    BEGIN_OR_SKIP(r, s, cloth);
    const auto img = r->render_image(cloth.positions);
    std::size_t covered = 0, border = 0;
    for (int y = 0; y < s.height; ++y)
      for (int x = 0; x < s.width; ++x) {
        const unsigned char* p = &img[(std::size_t(y) * s.width + x) * 3];
        const bool bg = p[0] == 255 && p[1] == 255 && p[2] == 255;
        covered += !bg;
        if (!bg && (x == 0 || y == 0 || x == s.width - 1 || y == s.height - 1)) ++border;
      }
    EXPECT_EQ(border, 0u) << "the cloth touches the image border";
    EXPECT_GT(covered, std::size_t(s.width * s.height) / 10);
  }
}

TEST(GlRenderer, VertexFramesOfAFlatGrid) {
  const Mesh m = make_grid(4, 3, 1.0, 1.0, GridPlane::XZ);
  std::vector<float> x(m.positions.begin(), m.positions.end());
  const auto uv = texture_coords(m);
  std::vector<float> n(x.size()), t(x.size());
  vertex_frames(x, uv, m.triangles, n, t);
  for (Index i = 0; i < m.num_vertices(); ++i) {
    const glm::vec3 ni = glm::normalize(glm::vec3(n[3 * i], n[3 * i + 1], n[3 * i + 2]));
    const glm::vec3 ti = glm::normalize(glm::vec3(t[3 * i], t[3 * i + 1], t[3 * i + 2]));
    EXPECT_NEAR(std::abs(ni.y), 1.0f, 1e-6f);
    EXPECT_NEAR(ti.x, 1.0f, 1e-6f);  // dP/du = +x
  }
  // Planar UVs from positions when the mesh has none (frames written by loom run): for the
  // grids they equal the generated UVs (xz: (x, -z), kept right-handed about the normal +y).
  for (GridPlane plane : {GridPlane::XY, GridPlane::XZ}) {
    const Mesh g = make_grid(5, 4, 2.0, 1.0, plane);
    Mesh bare = g;
    bare.uvs.clear();
    const auto uv2 = texture_coords(bare);
    for (std::size_t k = 0; k < g.uvs.size(); ++k) EXPECT_NEAR(uv2[k], g.uvs[k], 1e-6);
  }
}

TEST(GlRenderer, DrawMeshKeepsEachSideOfAUvSeamAndOneNormalAcrossIt) {
  // The seamed tube (tests/common/tube_obj.hpp): the closing quads' corners at column N carry
  // u = 1 where the seam vertices' first use has u = 0, one distinct uv per ring, so the drawn
  // mesh must have exactly M copies (one per ring, of the column-0 vertex).
  const tube_test::Tube tube{.N = 6, .M = 4, .shear = 0.25};
  const Mesh m = read_obj(tube.write("draw"));
  const Index n = m.num_vertices();
  const DrawMesh d = draw_mesh(m);
  ASSERT_EQ(d.source.size(), std::size_t(n + tube.M));
  ASSERT_EQ(d.uv.size(), 2 * d.source.size());
  ASSERT_EQ(d.triangles.size(), m.triangles.size());
  for (Index i = 0; i < n; ++i) EXPECT_EQ(d.source[std::size_t(i)], i);
  for (std::size_t i = std::size_t(n); i < d.source.size(); ++i) EXPECT_EQ(d.source[i] % tube.N, 0) << i;  // column 0
  for (Index t = 0; t < m.num_triangles(); ++t)
    for (int k = 0; k < 3; ++k) {
      const Index c = d.triangles[3 * std::size_t(t) + k];
      EXPECT_EQ(d.source[std::size_t(c)], m.triangles[3 * std::size_t(t) + k]);
      EXPECT_EQ(d.uv[2 * std::size_t(c)], float(m.corner_uv(t, k)[0])) << t << " " << k;
      EXPECT_EQ(d.uv[2 * std::size_t(c) + 1], float(m.corner_uv(t, k)[1])) << t << " " << k;
    }
  // Normals: the merged copies equal the area-weighted normals of the unsplit mesh (computed
  // here on the mesh's own triangles), so a seam leaves no shading edge.
  std::vector<float> x(3 * d.source.size());
  for (std::size_t i = 0; i < d.source.size(); ++i)
    for (int k = 0; k < 3; ++k) x[3 * i + k] = float(m.positions[3 * std::size_t(d.source[i]) + k]);
  std::vector<float> nd(x.size()), td(x.size());
  vertex_frames(x, d.uv, d.triangles, nd, td);
  merge_seam_normals(d.source, n, nd);
  const std::vector<float> xm(m.positions.begin(), m.positions.end());
  const auto uvm = texture_coords(m);
  std::vector<float> nm(xm.size()), tm(xm.size());
  vertex_frames(xm, uvm, m.triangles, nm, tm);
  for (std::size_t i = 0; i < d.source.size(); ++i)
    for (int k = 0; k < 3; ++k)
      EXPECT_NEAR(nd[3 * i + k], nm[3 * std::size_t(d.source[i]) + k], 1e-6f) << "drawn vertex " << i;
  // The seam copies' tangents follow their own side's uv: dP/du points around the tube (+angle
  // direction) on both sides of the seam at column 0.
  for (std::size_t i = std::size_t(n); i < d.source.size(); ++i) {
    const glm::vec3 tc = glm::normalize(glm::vec3(td[3 * i], td[3 * i + 1], td[3 * i + 2]));
    EXPECT_GT(tc.y, 0.5f) << "copy " << i;  // at angle 0 the tube's +angle direction is +y (the shear tilts it along z)
    const std::size_t s0 = std::size_t(d.source[i]);
    const glm::vec3 ts = glm::normalize(glm::vec3(td[3 * s0], td[3 * s0 + 1], td[3 * s0 + 2]));
    EXPECT_GT(ts.y, 0.5f) << "vertex " << s0;
  }
  // A grid (no corner uvs) is drawn as it is.
  const Mesh g = make_grid(5, 4, 2.0, 1.0);
  const DrawMesh dg = draw_mesh(g);
  EXPECT_EQ(dg.source.size(), std::size_t(g.num_vertices()));
  EXPECT_EQ(dg.triangles, g.triangles);
}

// ---- bad input ------------------------------------------------------------------------------

namespace {
std::string error_of(const std::string& yaml) {
  try {
    Params p = Params::from_string(yaml, "fabric.yaml");
    parse_fabric(p);
    p.check_unused();
  } catch (const InputError& e) {
    return e.what();
  }
  return "";
}
}  // namespace

TEST(GlRendererInput, FabricErrors) {
  EXPECT_NE(error_of("weave: twil_2_1\n").find("did you mean 'twill_2_1'"), std::string::npos) << error_of("weave: twil_2_1\n");
  EXPECT_NE(error_of("weave: tartan\n").find("plain"), std::string::npos);
  EXPECT_NE(error_of("roughness: {along: -0.1}\n").find("roughness.along"), std::string::npos);
  EXPECT_NE(error_of("roughness: {across: 0}\n").find("(0, 1]"), std::string::npos);
  EXPECT_NE(error_of("yarn: {curvature: 0.9}\nfibre: {curvature: 0.6}\n").find("below 1"), std::string::npos);
  EXPECT_NE(error_of("yarn: {curvature: 1.2}\n").find("[0, 1)"), std::string::npos);
  EXPECT_NE(error_of("fibre: {twist: 1.5}\n").find("whole number"), std::string::npos);
  EXPECT_NE(error_of("weave: {n_w: 0, n_pi: 0, n_sigma: 1}\n").find("at least 1"), std::string::npos);
  EXPECT_NE(error_of("weave: {n_w: 2, n_pi: 1}\n").find("n_sigma"), std::string::npos);
  EXPECT_NE(error_of("colors: {weft: [1, 0.5]}\n").find("3 numbers"), std::string::npos);
  EXPECT_NE(error_of("colours: {weft: [1, 0.5, 0]}\n").find("did you mean 'colors'"), std::string::npos);
  EXPECT_NE(error_of("density: -3\n").find("density"), std::string::npos);
  EXPECT_NE(error_of("mdf: beckmann\n").find("ward"), std::string::npos);
  // Errors name the file and line.
  EXPECT_EQ(error_of("weave: plain\nroughness: {along: -1}\n").rfind("fabric.yaml:2", 0), 0u);
  EXPECT_EQ(error_of("weave: plain\nmdf: ashikhmin\nroughness: {along: 0.1, across: 0.7}\n"), "");
}

TEST(GlRendererInput, ShippedFabricsLoad) {
  const fs::path dir = fs::path(LOOM_SOURCE_DIR) / "materials" / "fabrics";
  int n = 0;
  for (const auto& e : fs::directory_iterator(dir))
    if (e.path().extension() == ".yaml") {
      EXPECT_NO_THROW(load_fabric_file(e.path().string())) << e.path();
      ++n;
    }
  EXPECT_GE(n, 5);
}

TEST(GlRendererInput, RenderSectionErrors) {
  auto err = [](const std::string& yaml) -> std::string {
    try {
      Params p = Params::from_string(yaml, "scene.yaml");
      parse_render_settings(p, LOOM_SOURCE_DIR);
      p.check_unused();
    } catch (const InputError& e) {
      return e.what();
    }
    return "";
  };
  EXPECT_NE(err("shading: mdf_rotaton\n").find("did you mean 'mdf_rotation'"), std::string::npos);
  EXPECT_NE(err("supersample: 7\n").find("supersample"), std::string::npos);
  EXPECT_NE(err("fabric: materials/fabrics/nope.yaml\n").find("not found"), std::string::npos);
  EXPECT_NE(err("camera: {fov: 0}\n").find("fov"), std::string::npos);
  EXPECT_NE(err("light: {direction: [0, 0, 0]}\n").find("non-zero"), std::string::npos);
  EXPECT_NE(err("lihgt: {intensity: 2}\n").find("did you mean 'light'"), std::string::npos);
  EXPECT_NE(err("fabric: {weave: plain, roughness: {along: -2}}\n").find("roughness.along"), std::string::npos);
  EXPECT_EQ(err("type: gl\nfabric: materials/fabrics/satin_silk.yaml\nshading: normal_mapping\nrotation: paper\n"
                "camera: {position: [0, 0, 3], target: [0, 0, 0], fov: 30}\nlight: {direction: [0, 1, 1], ambient: 0.2}\n"),
            "");
}

// ---- the CLI ----------------------------------------------------------------------------------

namespace {
int run(const std::string& cmd, std::string& out) {
  const std::string full = cmd + " > /tmp/loom_render_cli_" + std::to_string(::getpid()) + ".txt 2>&1";
  const int rc = std::system(full.c_str());
  std::ifstream in("/tmp/loom_render_cli_" + std::to_string(::getpid()) + ".txt");
  std::stringstream ss;
  ss << in.rdbuf();
  out = ss.str();
  return WIFEXITED(rc) ? WEXITSTATUS(rc) : -1;
}

// A fake run folder: two frames of a small grid, and a scene with a render section.
std::string make_run_dir(const std::string& name) {
  const std::string dir = temp_dir(name);
  const Mesh m = make_grid(8, 8, 1.0, 1.0, GridPlane::XY);
  for (int f = 0; f < 2; ++f) {
    std::ofstream o(dir + "/frame_0000" + std::to_string(f) + ".obj");
    for (Index i = 0; i < m.num_vertices(); ++i)
      o << "v " << m.positions[3 * i] << " " << m.positions[3 * i + 1] << " " << m.positions[3 * i + 2] + 0.05 * f * m.positions[3 * i] << "\n";
    for (Index t = 0; t < m.num_triangles(); ++t)
      o << "f " << m.triangles[3 * t] + 1 << " " << m.triangles[3 * t + 1] + 1 << " " << m.triangles[3 * t + 2] + 1 << "\n";
  }
  std::ofstream s(dir + "/scene.yaml");
  s << "render:\n  type: gl\n  width: 64\n  height: 48\n  supersample: 1\n  video: off\n"
    << "  fabric: {weave: twill_2_1, density: 20}\n";
  return dir;
}
}  // namespace

TEST(GlRendererCli, RendersARunFolder) {
  const std::string dir = make_run_dir("cli");
  std::string out;
  const int rc = run(std::string(LOOM_EXE) + " render " + dir + " --quiet", out);
  if (rc != 0 && out.find("EGL") != std::string::npos) GTEST_SKIP() << "no EGL context: " << out;
  ASSERT_EQ(rc, 0) << out;
  for (const char* f : {"frame_00000.png", "frame_00001.png"}) {
    int w = 0, h = 0;
    const auto img = read_png(dir + "/render/" + f, w, h);
    EXPECT_EQ(w, 64);
    EXPECT_EQ(h, 48);
  }
  fs::remove_all(dir);
}

TEST(GlRendererCli, MissingFramesFolderIsBadInput) {
  std::string out;
  EXPECT_EQ(run(std::string(LOOM_EXE) + " render /nonexistent/loom_run", out), kExitBadInput) << out;
  EXPECT_NE(out.find("not a folder"), std::string::npos) << out;
  const std::string empty = temp_dir("empty");
  EXPECT_EQ(run(std::string(LOOM_EXE) + " render " + empty, out), kExitBadInput) << out;
  EXPECT_NE(out.find("no frame_"), std::string::npos) << out;
  fs::remove_all(empty);
}

TEST(GlRendererCli, UnknownWeaveInTheSceneIsBadInput) {
  const std::string dir = make_run_dir("weave");
  std::string out;
  EXPECT_EQ(run(std::string(LOOM_EXE) + " render " + dir + " --set render.fabric.weave=sattin", out), kExitBadInput) << out;
  EXPECT_NE(out.find("did you mean 'satin'"), std::string::npos) << out;
  fs::remove_all(dir);
}

TEST(GlRendererCli, MissingEglDriverNamesThePackage) {
  // No EGL vendor library: what a machine without libegl-mesa0 sees.
  const std::string dir = make_run_dir("noegl");
  std::string out;
  const int rc = run("__EGL_VENDOR_LIBRARY_FILENAMES=/nonexistent/none.json __EGL_VENDOR_LIBRARY_DIRS=/nonexistent " +
                         std::string(LOOM_EXE) + " render " + dir + " --quiet",
                     out);
  EXPECT_NE(rc, 0);
  EXPECT_NE(out.find("cannot create a headless OpenGL ES 3 context"), std::string::npos) << out;
  EXPECT_NE(out.find("libegl-mesa0"), std::string::npos) << out;
  EXPECT_EQ(std::count(out.begin(), out.end(), '\n'), 1) << "one clear error line: " << out;
  fs::remove_all(dir);
}

TEST(GlRendererCli, VideoOnWithoutFfmpegIsBadInput) {
  // An empty PATH hides ffmpeg whether or not it is installed.
  const std::string dir = make_run_dir("video");
  std::string out;
  EXPECT_EQ(run("PATH=/nonexistent " + std::string(LOOM_EXE) + " render " + dir + " --set render.video=on", out),
            kExitBadInput) << out;
  EXPECT_NE(out.find("apt-get install ffmpeg"), std::string::npos) << out;
  EXPECT_EQ(run(std::string(LOOM_EXE) + " render " + dir + " --set render.video=maybe", out), kExitBadInput) << out;
  fs::remove_all(dir);
}

TEST(GlRendererCli, UsesTheSceneMeshTextureCoordinates) {
  // A scene whose OBJ mesh has vt (here u, v = 2x, 2y): the render differs from the planar-UV one.
  const std::string dir = make_run_dir("uv");
  const Mesh m = make_grid(8, 8, 1.0, 1.0, GridPlane::XY);
  {
    std::ofstream o(dir + "/mesh.obj");
    for (Index i = 0; i < m.num_vertices(); ++i)
      o << "v " << m.positions[3 * i] << " " << m.positions[3 * i + 1] << " " << m.positions[3 * i + 2] << "\n";
    for (Index i = 0; i < m.num_vertices(); ++i) o << "vt " << 2 * m.uvs[2 * i] << " " << 2 * m.uvs[2 * i + 1] << "\n";
    for (Index t = 0; t < m.num_triangles(); ++t) {
      o << "f";
      for (int k = 0; k < 3; ++k) o << " " << m.triangles[3 * t + k] + 1 << "/" << m.triangles[3 * t + k] + 1;
      o << "\n";
    }
  }
  std::string out;
  int rc = run(std::string(LOOM_EXE) + " render " + dir + " --quiet --out " + dir + "/planar", out);
  if (rc != 0 && out.find("EGL") != std::string::npos) GTEST_SKIP() << "no EGL context: " << out;
  ASSERT_EQ(rc, 0) << out;
  {
    std::ofstream s(dir + "/scene2.yaml");
    s << "mesh: {obj: mesh.obj}\nrender:\n  width: 64\n  height: 48\n  supersample: 1\n  video: off\n"
      << "  fabric: {weave: twill_2_1, density: 20}\n";
  }
  rc = run(std::string(LOOM_EXE) + " render " + dir + " --quiet --scene " + dir + "/scene2.yaml --out " + dir + "/vt", out);
  ASSERT_EQ(rc, 0) << out;
  // Same settings, only the UVs differ.
  int w = 0, h = 0;
  const auto a = read_png(dir + "/planar/frame_00000.png", w, h);
  const auto b = read_png(dir + "/vt/frame_00000.png", w, h);
  EXPECT_NE(a, b);
  // And with vt equal to the planar UVs the images are identical.
  {
    std::ofstream o(dir + "/mesh.obj");
    for (Index i = 0; i < m.num_vertices(); ++i)
      o << "v " << m.positions[3 * i] << " " << m.positions[3 * i + 1] << " " << m.positions[3 * i + 2] << "\n";
    for (Index i = 0; i < m.num_vertices(); ++i) o << "vt " << m.uvs[2 * i] << " " << m.uvs[2 * i + 1] << "\n";
    for (Index t = 0; t < m.num_triangles(); ++t) {
      o << "f";
      for (int k = 0; k < 3; ++k) o << " " << m.triangles[3 * t + k] + 1 << "/" << m.triangles[3 * t + k] + 1;
      o << "\n";
    }
  }
  rc = run(std::string(LOOM_EXE) + " render " + dir + " --quiet --scene " + dir + "/scene2.yaml --out " + dir + "/vt1", out);
  ASSERT_EQ(rc, 0) << out;
  EXPECT_EQ(read_png(dir + "/vt1/frame_00000.png", w, h), a);
  fs::remove_all(dir);
}

TEST(GlRendererCli, VideoWithFfmpegWritesAnMp4) {
  if (std::system("command -v ffmpeg > /dev/null 2>&1") != 0) GTEST_SKIP() << "ffmpeg is not installed here";
  const std::string dir = make_run_dir("mp4");
  std::string out;
  const int rc = run(std::string(LOOM_EXE) + " render " + dir + " --quiet --set render.video=on --set render.fps=10", out);
  if (rc != 0 && out.find("EGL") != std::string::npos) GTEST_SKIP() << "no EGL context: " << out;
  ASSERT_EQ(rc, 0) << out;
  ASSERT_TRUE(fs::exists(dir + "/render/render.mp4"));
  EXPECT_GT(fs::file_size(dir + "/render/render.mp4"), 100u);
  if (std::system("command -v ffprobe > /dev/null 2>&1") == 0) {
    run("ffprobe -v error -count_frames -select_streams v:0 -show_entries stream=nb_read_frames -of csv=p=0 " + dir +
            "/render/render.mp4",
        out);
    EXPECT_EQ(std::atoi(out.c_str()), 2) << out;  // the two frames of the run
  }
  fs::remove_all(dir);
}

TEST(GlRendererCli, DrawsTheColliders) {
  // The same frames with and without a sphere collider through the cloth's centre (half of
  // it in front of the cloth whichever side the camera is on): the ball must show.
  const std::string plain = make_run_dir("no_collider");
  const std::string ball = make_run_dir("collider");
  std::ofstream(ball + "/scene.yaml", std::ios::app)
      << "colliders: [{type: sphere, center: [0.5, 0.5, 0.0], radius: 0.3}, {type: plane, point: [0, -0.2, 0]}]\n";
  std::string out;
  int rc = run(std::string(LOOM_EXE) + " render " + plain + " --quiet", out);
  if (rc != 0 && out.find("EGL") != std::string::npos) GTEST_SKIP() << "no EGL context: " << out;
  ASSERT_EQ(rc, 0) << out;
  rc = run(std::string(LOOM_EXE) + " render " + ball + " --quiet", out);
  ASSERT_EQ(rc, 0) << out;
  int w = 0, h = 0, w2 = 0, h2 = 0;
  const auto a = read_png(plain + "/render/frame_00000.png", w, h);
  const auto b = read_png(ball + "/render/frame_00000.png", w2, h2);
  ASSERT_EQ(a.size(), b.size());
  std::size_t differ = 0, grey = 0;
  for (std::size_t p = 0; p + 2 < a.size(); p += 3) {
    differ += a[p] != b[p] || a[p + 1] != b[p + 1] || a[p + 2] != b[p + 2];
    // the colliders' grey (0.55, 0.57, 0.60) x light: nearly equal channels, blue a little higher
    grey += a[p] != b[p] && std::abs(int(b[p]) - int(b[p + 1])) <= 12 && b[p + 2] >= b[p] && b[p] > 20;
  }
  EXPECT_GT(differ, a.size() / 3 / 20) << "the colliders changed fewer than 5% of the pixels";
  EXPECT_GT(grey, differ / 4);
  fs::remove_all(plain);
  fs::remove_all(ball);
}

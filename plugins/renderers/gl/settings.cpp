// Fabric files, the render section, camera, vertex frames, PNG I/O (no GL here).
#include <algorithm>
#include <cmath>
#include <filesystem>

#define STB_IMAGE_WRITE_IMPLEMENTATION
#include <stb/stb_image_write.h>
#define STB_IMAGE_IMPLEMENTATION
#define STBI_ONLY_PNG
#include <stb/stb_image.h>

#include <glm/gtc/matrix_transform.hpp>

#include "gl_renderer.hpp"

#include <map>
#include <tuple>

namespace fs = std::filesystem;

namespace loom::render {

const std::vector<WeavePattern>& weave_patterns() {
  static const std::vector<WeavePattern> w = {
      {"plain", 1, 1, 1},      {"twill_1_2", 1, 2, 1}, {"twill_2_1", 2, 1, 1},
      {"twill_4_1", 4, 1, 1},  {"satin", 5, 1, 2},     {"satin_5", 4, 1, 2},
      {"silk", 0, 100, 1},
  };
  return w;
}

namespace {

glm::vec3 read_vec3(const Params& p, const std::string& key, glm::vec3 def, double lo, double hi) {
  Params c = p.child(key);
  if (!c.valid()) return def;
  std::vector<double> v;
  if (c.is_scalar()) {
    const double s = c.as_double();
    v = {s, s, s};
  } else {
    v = c.as_doubles();
  }
  if (v.size() != 3) c.fail("expected 3 numbers [r, g, b] or [x, y, z], got " + std::to_string(v.size()) + ".");
  for (double d : v)
    if (!std::isfinite(d) || d < lo || d > hi)
      c.fail("value " + std::to_string(d) + " out of range; each component must lie in [" + std::to_string(lo) + ", " +
             std::to_string(hi) + "].");
  return glm::vec3(float(v[0]), float(v[1]), float(v[2]));
}

double read_fraction(const Params& p, const std::string& key, double def, bool open_top) {
  Params c = p.child(key);
  if (!c.valid()) return def;
  const double v = c.as_double();
  if (!std::isfinite(v) || v < 0.0 || (open_top ? v >= 1.0 : v > 1.0))
    c.fail(key + " = " + std::to_string(v) + " is out of range; it must lie in [0, 1" + (open_top ? ")" : "]") + ".");
  return v;
}

int read_count(const Params& p, const std::string& key) {
  Params c = p.child(key);
  if (!c.valid()) p.fail("missing key '" + key + "' in the weave (give n_w, n_pi and n_sigma).");
  const double v = c.as_double();
  if (!std::isfinite(v) || v < 0 || v != std::floor(v) || v > 1000)
    c.fail(key + " must be a whole number in [0, 1000], got " + std::to_string(v) + ".");
  return int(v);
}

}  // namespace

shading::Fabric default_fabric() {
  shading::Fabric f{};
  f.n_w = 1;
  f.n_pi = 1;
  f.n_sigma = 1;
  f.density_u = f.density_v = 64.0f;
  f.yarn_curvature = 0.5f;
  f.fibre_curvature = 0.3f;
  f.fibre_slope = 0.5f;
  f.twists = 1.0f;
  f.mdf = shading::LOOM_MDF_WARD;
  f.alpha_along = 0.2f;
  f.alpha_across = 0.6f;
  f.mode = shading::LOOM_MODE_ROTATE_EXACT;
  f.weft_color = glm::vec3(0.55f, 0.52f, 0.45f);
  f.warp_color = glm::vec3(0.50f, 0.47f, 0.40f);
  f.specular = glm::vec3(0.08f);
  return f;
}

shading::Fabric parse_fabric(const Params& p) {
  if (!p.is_map()) p.fail("a fabric is a mapping (weave, density, yarn, fibre, mdf, roughness, colors, specular).");
  shading::Fabric f = default_fabric();
  p.get("name", std::string());

  Params w = p.child("weave");
  if (w.valid()) {
    if (w.is_map()) {
      f.n_w = float(read_count(w, "n_w"));
      f.n_pi = float(read_count(w, "n_pi"));
      f.n_sigma = float(read_count(w, "n_sigma"));
      if (f.n_w + f.n_pi < 1) w.fail("n_w + n_pi must be at least 1 (a weave row needs one element).");
      w.check_unused();
    } else {
      std::vector<std::string> names;
      for (const auto& pat : weave_patterns()) names.push_back(pat.name);
      const std::string name = p.get_choice("weave", "plain", names);
      for (const auto& pat : weave_patterns())
        if (name == pat.name) {
          f.n_w = float(pat.n_w);
          f.n_pi = float(pat.n_pi);
          f.n_sigma = float(pat.n_sigma);
        }
    }
  }

  Params d = p.child("density");
  if (d.valid()) {
    std::vector<double> v = d.is_scalar() ? std::vector<double>{d.as_double(), d.as_double()} : d.as_doubles();
    if (v.size() != 2 || !(v[0] > 0) || !(v[1] > 0) || !std::isfinite(v[0]) || !std::isfinite(v[1]))
      d.fail("density (weave elements per unit of u and v) must be a positive number or a pair [du, dv] of them.");
    f.density_u = float(v[0]);
    f.density_v = float(v[1]);
  }

  Params yarn = p.child("yarn");
  if (yarn.valid()) {
    f.yarn_curvature = float(read_fraction(yarn, "curvature", f.yarn_curvature, true));
    yarn.check_unused();
  }
  Params fibre = p.child("fibre");
  if (fibre.valid()) {
    const double n = fibre.get_nonnegative("twist", f.twists);
    if (n != std::floor(n))
      fibre.child("twist").fail("twist (N, fibre twists per weave element) must be a whole number, so the twist pattern "
                                "is continuous across elements; got " + std::to_string(n) + ".");
    f.twists = float(n);
    f.fibre_slope = float(read_fraction(fibre, "slope", f.fibre_slope, false));
    f.fibre_curvature = float(read_fraction(fibre, "curvature", f.fibre_curvature, true));
    fibre.check_unused();
  }
  if (double(f.yarn_curvature) * f.yarn_curvature + double(f.fibre_curvature) * f.fibre_curvature >= 1.0)
    p.fail("yarn.curvature^2 + fibre.curvature^2 must be below 1 (else the perturbed normal of eq. 13 leaves the unit "
           "hemisphere); got c_y = " + std::to_string(f.yarn_curvature) + ", c_f = " + std::to_string(f.fibre_curvature) + ".");

  const std::string mdf = p.get_choice("mdf", "ward", {"ward", "ashikhmin"});
  f.mdf = mdf == "ward" ? shading::LOOM_MDF_WARD : shading::LOOM_MDF_ASHIKHMIN;

  Params r = p.child("roughness");
  if (r.valid()) {
    for (const char* key : {"along", "across"}) {
      Params c = r.child(key);
      if (!c.valid()) continue;
      const double a = c.as_double();
      if (!std::isfinite(a) || a <= 0.0 || a > 1.0)
        c.fail(std::string("roughness.") + key + " = " + std::to_string(a) +
               " is out of range; MDF roughness (Ward alpha) must lie in (0, 1] (0.05 glossy ... 1 matte).");
      (std::string(key) == "along" ? f.alpha_along : f.alpha_across) = float(a);
    }
    r.check_unused();
  }

  Params colors = p.child("colors");
  if (colors.valid()) {
    f.weft_color = read_vec3(colors, "weft", f.weft_color, 0.0, 1.0);
    f.warp_color = read_vec3(colors, "warp", f.warp_color, 0.0, 1.0);
    colors.check_unused();
  }
  f.specular = read_vec3(p, "specular", f.specular, 0.0, 1.0);
  return f;
}

shading::Fabric load_fabric_file(const std::string& path) {
  if (!fs::exists(path))
    throw InputError(path + ": fabric file not found. Fix: render.fabric is relative to the scene's folder; the "
                            "shipped fabrics are in materials/fabrics/.");
  Params p = Params::from_file(path);
  shading::Fabric f = parse_fabric(p);
  p.check_unused();
  return f;
}

const ParamSpec& render_spec() {
  static const ParamSpec spec = [] {
    const RenderSettings d;
    auto vec = [](glm::vec3 v) { return std::array<double, 3>{v[0], v[1], v[2]}; };
    ParamSpec s("gl", "woven-fabric renderer: the keys of the render: section");
    s.integer("width", d.width).range(ParamRange::closed(1, 8192)).units("pixels").help("image width");
    s.integer("height", d.height).range(ParamRange::closed(1, 8192)).units("pixels").help("image height");
    s.integer("supersample", d.supersample).range(ParamRange::closed(1, 4)).help(
        "render at supersample x the size and box-filter down");
    s.open_map("fabric").shown_type("string | map").default_text("plain-woven cotton").help(
        "a fabric file (relative to the scene's folder; materials/fabrics/) or a fabric mapping (docs/RENDERING.md)");
    s.choice("shading", "mdf_rotation", {"mdf_rotation", "normal_mapping", "flat"}).help("fabric shading model");
    s.choice("rotation", "exact", {"exact", "paper"}).help("MDF rotation of mdf_rotation shading");
    ParamSpec cam("camera");
    cam.vec3("position", {0, 0, 0}).default_text("framed from the cloth's bounds").units("m").help("eye position");
    cam.vec3("target", {0, 0, 0}).default_text("the cloth's centre").units("m").help("point looked at");
    cam.vec3("up", vec(d.camera.up)).help("up direction (non-zero)");
    cam.number("fov", d.camera.fov_deg).range(ParamRange::closed(1, 170)).units("deg").help("vertical field of view");
    s.map("camera", std::move(cam)).help("the view");
    ParamSpec light("light");
    light.vec3("direction", vec(d.light.direction)).default_text("from the camera").help(
        "towards the light (world space, non-zero)");
    light.vec3("color", vec(d.light.color)).range(ParamRange::closed(0, 1e6)).help("light colour (a number: grey)");
    light.number("intensity", d.light.intensity).range(ParamRange::nonnegative()).help("light intensity");
    light.number("ambient", d.light.ambient).range(ParamRange::nonnegative()).help("ambient term");
    s.map("light", std::move(light)).help("one directional light");
    s.vec3("background", vec(d.background)).range(ParamRange::closed(0, 1)).help("display-space RGB (a number: grey)");
    s.number("exposure", d.exposure).range(ParamRange::positive()).help("multiplies the linear radiance");
    return s;
  }();
  return spec;
}

RenderSettings parse_render_settings(const Params& render, const std::string& base_dir) {
  RenderSettings s;
  if (!render.valid()) return s;
  render.mark_used("type");
  render.mark_used("video");
  render.mark_used("fps");
  render.mark_used("fit");     // read by loom render (render_cmd.cpp): sequence | first_frame
  render.mark_used("ground");  // read by loom render: true | false
  const ParamReader r(render, render_spec());
  s.width = r.int32("width");
  s.height = r.int32("height");
  s.supersample = r.int32("supersample");
  if (std::int64_t(s.width) * s.supersample > 16384 || std::int64_t(s.height) * s.supersample > 16384)
    render.fail("width x supersample and height x supersample must stay below 16384.");

  Params fab = r.node("fabric");
  if (fab.valid()) {
    if (fab.is_scalar()) {
      fs::path fp = fab.as_string();
      if (fp.is_relative() && !base_dir.empty()) fp = fs::path(base_dir) / fp;
      s.fabric = load_fabric_file(fp.string());
    } else {
      s.fabric = parse_fabric(fab);
      fab.check_unused();
    }
  }
  const std::string shading_mode = r.text("shading");
  const std::string rotation = r.text("rotation");
  if (shading_mode == "flat") s.fabric.mode = shading::LOOM_MODE_FLAT;
  else if (shading_mode == "normal_mapping") s.fabric.mode = shading::LOOM_MODE_NORMAL_MAP;
  else s.fabric.mode = rotation == "exact" ? shading::LOOM_MODE_ROTATE_EXACT : shading::LOOM_MODE_ROTATE_PAPER;

  const ParamReader camr = r.section("camera");
  const Params& cam = camr.params();
  if (cam.valid()) {
    const float inf = 1e30f;
    if (cam.has("position")) {
      s.camera.has_position = true;
      s.camera.position = read_vec3(cam, "position", {}, -inf, inf);
    }
    if (cam.has("target")) {
      s.camera.has_target = true;
      s.camera.target = read_vec3(cam, "target", {}, -inf, inf);
    }
    if (cam.has("up")) {
      s.camera.has_up = true;
      s.camera.up = read_vec3(cam, "up", {}, -inf, inf);
      if (glm::length(s.camera.up) < 1e-6f) cam.child("up").fail("up must be a non-zero vector.");
    }
    s.camera.fov_deg = float(camr.number("fov"));
    cam.check_unused();
  }
  const ParamReader lightr = r.section("light");
  const Params& light = lightr.params();
  if (light.valid()) {
    if (light.has("direction")) {
      s.light.has_direction = true;
      s.light.direction = read_vec3(light, "direction", {}, -1e30, 1e30);
      if (glm::length(s.light.direction) < 1e-6f)
        light.child("direction").fail("direction (towards the light) must be a non-zero vector.");
      s.light.direction = glm::normalize(s.light.direction);
    }
    const ParamDecl& color = *lightr.spec().find("color");
    s.light.color = read_vec3(light, "color", s.light.color, color.range.min, color.range.max);
    s.light.intensity = float(lightr.number("intensity"));
    s.light.ambient = float(lightr.number("ambient"));
    light.check_unused();
  }
  const ParamDecl& bg = *r.spec().find("background");
  s.background = read_vec3(r.params(), "background", s.background, bg.range.min, bg.range.max);
  s.exposure = float(r.number("exposure"));
  return s;
}

glm::vec3 Camera::ray(float px, float py) const {
  const glm::vec3 f = glm::normalize(target - eye);
  const glm::vec3 r = glm::normalize(glm::cross(f, up));
  const glm::vec3 u = glm::cross(r, f);
  const float t = std::tan(glm::radians(fov_deg) * 0.5f);
  const float aspect = float(width) / float(height);
  const float nx = 2.0f * px / float(width) - 1.0f;
  const float ny = 1.0f - 2.0f * py / float(height);
  return glm::normalize(f + r * (nx * t * aspect) + u * (ny * t));
}

Camera make_camera(const CameraSpec& spec, glm::vec3 lo, glm::vec3 hi, int width, int height) {
  Camera c;
  c.width = width;
  c.height = height;
  c.fov_deg = spec.fov_deg;
  const glm::vec3 center = 0.5f * (lo + hi);
  const float radius = std::max(0.5f * glm::length(hi - lo), 1e-6f);
  const glm::vec3 ext = hi - lo;
  // Look along the thinnest axis of the box (the cloth's normal for a flat cloth), tilted.
  int thin = 0;
  for (int a = 1; a < 3; ++a)
    if (ext[a] < ext[thin]) thin = a;
  glm::vec3 dir(0.0f);
  dir[thin] = 1.0f;
  if (thin == 1) dir += glm::vec3(0.3f, 0.0f, 0.85f);  // flat cloth: from above and in front
  else dir += glm::vec3(thin == 0 ? 0.0f : 0.25f, 0.3f, thin == 2 ? 0.0f : 0.25f);
  dir = glm::normalize(dir);
  c.target = spec.has_target ? spec.target : center;
  const float half = glm::radians(spec.fov_deg) * 0.5f;
  const float half_min = std::min(half, std::atan(std::tan(half) * float(width) / float(height)));
  c.up = spec.up;
  if (spec.has_position) {
    c.eye = spec.position;
  } else {
    // Closest distance along dir at which all 8 box corners fall inside 90% of the view.
    const glm::vec3 fwd = -dir;
    glm::vec3 up = c.up;
    if (glm::length(glm::cross(fwd, up)) < 1e-4f) up = std::abs(fwd.z) < std::abs(fwd.x) ? glm::vec3(0, 0, 1) : glm::vec3(1, 0, 0);
    const glm::vec3 r = glm::normalize(glm::cross(fwd, up)), u = glm::cross(r, fwd);
    const float ty = 0.9f * std::tan(half), tx = ty * float(width) / float(height);
    float d = 1.05f * radius / std::sin(half_min);
    if (!spec.has_target) {
      d = 0.0f;
      for (int k = 0; k < 8; ++k) {
        const glm::vec3 corner((k & 1) ? hi.x : lo.x, (k & 2) ? hi.y : lo.y, (k & 4) ? hi.z : lo.z);
        const glm::vec3 o = corner - c.target;
        const float depth = glm::dot(o, fwd);  // + is further away
        d = std::max(d, std::abs(glm::dot(o, r)) / tx - depth);
        d = std::max(d, std::abs(glm::dot(o, u)) / ty - depth);
      }
      d = std::max(d, 1.5f * radius);
    }
    c.eye = c.target + dir * d;
  }
  glm::vec3 f = c.target - c.eye;
  if (glm::length(f) < 1e-9f) c.eye = c.target + dir * radius, f = c.target - c.eye;
  if (glm::length(glm::cross(glm::normalize(f), glm::normalize(c.up))) < 1e-4f)
    c.up = std::abs(f.z) < std::abs(f.x) ? glm::vec3(0, 0, 1) : glm::vec3(1, 0, 0);
  c.view = glm::lookAt(c.eye, c.target, c.up);
  const float dist = glm::length(c.target - c.eye);
  c.proj = glm::perspective(glm::radians(spec.fov_deg), float(width) / float(height), std::max(dist * 0.01f, 1e-4f),
                            dist + 10.0f * radius);
  return c;
}

glm::vec3 light_direction(const LightSpec& spec, const Camera& cam) {
  if (spec.has_direction) return spec.direction;
  const glm::vec3 f = glm::normalize(cam.target - cam.eye);
  const glm::vec3 r = glm::normalize(glm::cross(f, cam.up));
  const glm::vec3 u = glm::cross(r, f);
  return glm::normalize(-f + 0.45f * u - 0.35f * r);
}

void vertex_frames(std::span<const float> x, std::span<const float> uv, std::span<const Index> tris,
                   std::span<float> normals, std::span<float> tangents) {
  std::fill(normals.begin(), normals.end(), 0.0f);
  std::fill(tangents.begin(), tangents.end(), 0.0f);
  for (std::size_t t = 0; t + 2 < tris.size(); t += 3) {
    const Index i0 = tris[t], i1 = tris[t + 1], i2 = tris[t + 2];
    const glm::vec3 p0(x[3 * i0], x[3 * i0 + 1], x[3 * i0 + 2]);
    const glm::vec3 e1 = glm::vec3(x[3 * i1], x[3 * i1 + 1], x[3 * i1 + 2]) - p0;
    const glm::vec3 e2 = glm::vec3(x[3 * i2], x[3 * i2 + 1], x[3 * i2 + 2]) - p0;
    const glm::vec3 n = glm::cross(e1, e2);  // |n| = 2 area: area weighting
    const float du1 = uv[2 * i1] - uv[2 * i0], dv1 = uv[2 * i1 + 1] - uv[2 * i0 + 1];
    const float du2 = uv[2 * i2] - uv[2 * i0], dv2 = uv[2 * i2 + 1] - uv[2 * i0 + 1];
    const float det = du1 * dv2 - du2 * dv1;
    // dP/du = (e1 dv2 - e2 dv1) / det, weighted by the triangle's UV area |det|.
    const glm::vec3 tu = (e1 * dv2 - e2 * dv1) * (det >= 0.0f ? 1.0f : -1.0f);
    for (Index i : {i0, i1, i2}) {
      for (int k = 0; k < 3; ++k) {
        normals[3 * i + k] += n[k];
        tangents[3 * i + k] += tu[k];
      }
    }
  }
}

DrawMesh draw_mesh(const Mesh& mesh) {
  DrawMesh d;
  const Index n = mesh.num_vertices();
  d.uv = texture_coords(mesh);
  d.triangles = mesh.triangles;
  d.source.resize(std::size_t(n));
  for (Index i = 0; i < n; ++i) d.source[std::size_t(i)] = i;
  if (mesh.uvs.size() != 2 * std::size_t(n) || mesh.corner_uvs.size() != 2 * mesh.triangles.size()) return d;
  std::map<std::tuple<Index, double, double>, Index> copies;
  for (std::size_t c = 0; c < mesh.triangles.size(); ++c) {
    const Index v = mesh.triangles[c];
    const double* w = &mesh.corner_uvs[2 * c];
    if (w[0] == mesh.uvs[2 * std::size_t(v)] && w[1] == mesh.uvs[2 * std::size_t(v) + 1]) continue;
    const auto [it, fresh] = copies.emplace(std::make_tuple(v, w[0], w[1]), Index(d.source.size()));
    if (fresh) {
      d.source.push_back(v);
      d.uv.push_back(float(w[0]));
      d.uv.push_back(float(w[1]));
    }
    d.triangles[c] = it->second;
  }
  return d;
}

void merge_seam_normals(std::span<const Index> source, Index num_mesh_vertices, std::span<float> normals) {
  const std::size_t n = std::size_t(num_mesh_vertices);
  for (std::size_t i = n; i < source.size(); ++i)
    for (int k = 0; k < 3; ++k) normals[3 * std::size_t(source[i]) + k] += normals[3 * i + k];
  for (std::size_t i = n; i < source.size(); ++i)
    for (int k = 0; k < 3; ++k) normals[3 * i + k] = normals[3 * std::size_t(source[i]) + k];
}

std::vector<float> texture_coords(const Mesh& mesh) {
  const Index n = mesh.num_vertices();
  std::vector<float> uv(2 * std::size_t(n));
  if (mesh.uvs.size() == 2 * std::size_t(n)) {
    for (std::size_t i = 0; i < uv.size(); ++i) uv[i] = float(mesh.uvs[i]);
    return uv;
  }
  glm::dvec3 lo(1e300), hi(-1e300);
  for (Index i = 0; i < n; ++i)
    for (int k = 0; k < 3; ++k) {
      lo[k] = std::min(lo[k], mesh.positions[3 * i + k]);
      hi[k] = std::max(hi[k], mesh.positions[3 * i + k]);
    }
  // The two longest axes, in index order (xy -> (x, y), xz -> (x, z)).
  int thin = 0;
  for (int a = 1; a < 3; ++a)
    if (hi[a] - lo[a] < hi[thin] - lo[thin]) thin = a;
  const int a0 = thin == 0 ? 1 : 0, a1 = thin == 2 ? 1 : 2;
  // Orient (u, v) right-handed about the mean normal (flip v if the map would mirror).
  glm::dvec3 mean_n(0.0);
  for (std::size_t t = 0; t + 2 < mesh.triangles.size(); t += 3) {
    const double* p0 = &mesh.positions[3 * std::size_t(mesh.triangles[t])];
    const double* p1 = &mesh.positions[3 * std::size_t(mesh.triangles[t + 1])];
    const double* p2 = &mesh.positions[3 * std::size_t(mesh.triangles[t + 2])];
    mean_n += glm::cross(glm::dvec3(p1[0] - p0[0], p1[1] - p0[1], p1[2] - p0[2]),
                         glm::dvec3(p2[0] - p0[0], p2[1] - p0[1], p2[2] - p0[2]));
  }
  glm::dvec3 e0(0.0), e1(0.0);
  e0[a0] = 1.0;
  e1[a1] = 1.0;
  const bool flip = glm::dot(glm::cross(e0, e1), mean_n) < 0.0;
  for (Index i = 0; i < n; ++i) {
    uv[2 * i] = float(mesh.positions[3 * i + a0] - lo[a0]);
    const double c = mesh.positions[3 * i + a1];
    uv[2 * i + 1] = float(flip ? hi[a1] - c : c - lo[a1]);
  }
  return uv;
}

void write_png(const std::string& path, int width, int height, const unsigned char* rgb) {
  stbi_write_png_compression_level = 9;
  if (!stbi_write_png(path.c_str(), width, height, 3, rgb, width * 3))
    throw std::runtime_error(path + ": cannot write PNG (is the folder writable?)");
}

std::vector<unsigned char> read_png(const std::string& path, int& width, int& height) {
  int comp = 0;
  unsigned char* data = stbi_load(path.c_str(), &width, &height, &comp, 3);
  if (!data) throw InputError(path + ": cannot read PNG (" + std::string(stbi_failure_reason()) + ")");
  std::vector<unsigned char> out(data, data + std::size_t(width) * height * 3);
  stbi_image_free(data);
  return out;
}

}  // namespace loom::render

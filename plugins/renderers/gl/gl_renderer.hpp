// The `gl` renderer: woven-fabric shading (Kang & Cho 2011, section 4) with OpenGL ES 3
// through a headless EGL context (Mesa llvmpipe on a CPU-only machine), one PNG per frame.
#pragma once

#include <memory>
#include <span>
#include <string>
#include <vector>

#include <glm/glm.hpp>

#include "loom/kernels/shading.hpp"
#include "loom/mesh.hpp"
#include "loom/param_spec.hpp"
#include "loom/params.hpp"
#include "loom/renderer.hpp"

namespace loom::render {

/// Named weave patterns (n_w, n_pi, n_sigma) of section 4.2 / Fig. 10.
struct WeavePattern {
  const char* name;
  int n_w, n_pi, n_sigma;
};
const std::vector<WeavePattern>& weave_patterns();

/// Read one fabric mapping (the contents of a materials/fabrics/*.yaml file). Throws
/// InputError naming file:line for unknown weaves, out-of-range values and unknown keys.
shading::Fabric parse_fabric(const Params& p);
shading::Fabric load_fabric_file(const std::string& path);
/// The fabric used when a scene names none (a plain-woven cotton).
shading::Fabric default_fabric();

struct CameraSpec {
  bool has_position = false, has_target = false, has_up = false;
  glm::vec3 position{0.0f}, target{0.0f}, up{0.0f, 1.0f, 0.0f};
  float fov_deg = 35.0f;  ///< vertical field of view
};

struct LightSpec {
  bool has_direction = false;
  glm::vec3 direction{0.0f, 0.0f, 1.0f};  ///< towards the light (world space)
  glm::vec3 color{1.0f};
  float intensity = 1.0f;
  float ambient = 0.12f;
};

/// Everything the renderer reads from a scene's `render:` section.
struct RenderSettings {
  int width = 1280, height = 720;
  int supersample = 2;   ///< render at supersample x the size and box-filter down
  shading::Fabric fabric = default_fabric();
  CameraSpec camera;
  LightSpec light;
  glm::vec3 background{1.0f, 1.0f, 1.0f};  ///< display-space RGB
  float exposure = 1.0f;
};

/// The keys of the `render:` section the gl renderer reads (the fabric mapping's keys are
/// checked by parse_fabric, which also reads fabric files).
const ParamSpec& render_spec();
/// Parse the `render:` section through render_spec(); relative fabric paths are resolved
/// against base_dir.
RenderSettings parse_render_settings(const Params& render, const std::string& base_dir);

struct Camera {
  glm::vec3 eye{0.0f}, target{0.0f}, up{0.0f, 1.0f, 0.0f};
  float fov_deg = 35.0f;
  int width = 1, height = 1;
  glm::mat4 view{1.0f}, proj{1.0f};
  /// Unit direction of the ray through image point (px, py), pixels from the top-left corner.
  glm::vec3 ray(float px, float py) const;
};

/// The camera a spec gives for a cloth with the given bounding box: unset position/target
/// frame the box (looking along its thinnest axis, tilted), the sphere around it filling the view.
Camera make_camera(const CameraSpec& spec, glm::vec3 box_min, glm::vec3 box_max, int width, int height);
/// Unit direction towards the light (default: over the viewer's left shoulder).
glm::vec3 light_direction(const LightSpec& spec, const Camera& cam);

/// Per-vertex area-weighted normals and UV tangents (dP/du) of a triangle mesh, written into
/// normals/tangents (3n floats each). No allocation.
void vertex_frames(std::span<const float> x, std::span<const float> uv, std::span<const Index> tris,
                   std::span<float> normals, std::span<float> tangents);
/// Texture coordinates: the mesh's if it has them, else planar from the positions (the two
/// longest bounding-box axes, in the mesh's units, origin at the box corner).
std::vector<float> texture_coords(const Mesh& mesh);
/// The mesh as drawn: one drawn vertex per mesh vertex (the first num_vertices, in order, with
/// texture_coords' uv), then one per distinct (vertex, corner uv) where a corner's uv differs
/// from its vertex's (a UV seam: each side keeps its own texture coordinates). `source[i]` is
/// the mesh vertex of drawn vertex i; `triangles` are the mesh's, renumbered per corner.
struct DrawMesh {
  std::vector<float> uv;
  std::vector<Index> triangles, source;
};
DrawMesh draw_mesh(const Mesh& mesh);
/// After vertex_frames on a DrawMesh: every drawn copy of a mesh vertex gets the sum of the
/// copies' normals (the surface is continuous across a seam: no shading edge there); the
/// tangents stay per copy (they follow each side's uv). No allocation.
void merge_seam_normals(std::span<const Index> source, Index num_mesh_vertices, std::span<float> normals);

class EglContext;

class GlRenderer final : public Renderer {
 public:
  explicit GlRenderer(RenderSettings settings);
  /// external_context: draw with the caller's current OpenGL ES 3 context (the `loom view`
  /// window) instead of an own headless EGL one; no offscreen framebuffer is made.
  GlRenderer(RenderSettings settings, bool external_context);
  ~GlRenderer() override;
  std::string name() const override { return "gl"; }
  void begin(const Mesh& mesh) override;
  void render(std::span<const double> x, const std::string& png_path) override;
  /// Colliders to draw (plain grey, Lambert) with the following frames (the module's
  /// loom_renderer_set_obstacles; see renderer.hpp).
  void set_obstacles(std::span<const float> positions, std::span<const float> normals);
  /// Fit the default camera (and the light that follows it) to a box, e.g. the bounds of a
  /// whole sequence (loom render), instead of the first frame given to begin().
  void fit_camera(glm::vec3 lo, glm::vec3 hi);
  /// Draw a ground: the square of half size `half_size` around `point` on the plane with
  /// `normal` (pointing up), and the cloth's shadow on it (ground.cpp).
  void set_ground(glm::vec3 point, glm::vec3 normal, float half_size);
  /// The ground's reflectance (linear RGB).
  static constexpr glm::vec3 kGroundAlbedo{0.80f, 0.78f, 0.74f};

  /// Render positions x into the RGB image returned (width*height*3 bytes, top row first).
  const std::vector<unsigned char>& render_image(std::span<const double> x);
  const RenderSettings& settings() const { return settings_; }
  const Camera& camera() const { return camera_; }
  glm::vec3 light_dir() const { return light_dir_; }
  /// Upload positions x (3n) and their normals and tangents for draw().
  void upload(std::span<const double> x);
  /// Draw the uploaded frame into framebuffer fbo (0: the window) with a w x h viewport.
  void draw(unsigned fbo, int w, int h);
  /// Replace the camera (the light keeps the direction begin() gave it).
  void set_camera(const Camera& cam);
  /// GL_RENDERER string of the context (e.g. "llvmpipe (LLVM 15.0.6, 256 bits)").
  std::string gl_renderer() const;

 private:
  void create_gl_objects();
  void set_uniforms();
  void update_light();
  void draw_ground();
  void make_current();  ///< the headless context, when this renderer owns one
  RenderSettings settings_;
  std::unique_ptr<EglContext> egl_;
  Camera camera_;
  glm::vec3 light_dir_{0.0f, 0.0f, 1.0f};
  Index num_vertices_ = 0;
  std::vector<Index> triangles_;    ///< DrawMesh::triangles
  std::vector<Index> draw_source_;  ///< DrawMesh::source
  std::vector<float> uv_, pos_, normals_, tangents_;
  std::vector<unsigned char> readback_, image_;
  unsigned program_ = 0, vao_ = 0, vbo_[4] = {0, 0, 0, 0}, ebo_ = 0, fbo_ = 0, rb_color_ = 0, rb_depth_ = 0;
  unsigned obstacle_program_ = 0, obstacle_vao_ = 0, obstacle_vbo_[2] = {0, 0};
  unsigned ground_program_ = 0, ground_vao_ = 0, ground_vbo_ = 0;
  bool ground_ = false;
  glm::vec3 ground_point_{0.0f}, ground_normal_{0.0f, 1.0f, 0.0f};
  float ground_size_ = 1.0f;
  std::size_t obstacle_vertices_ = 0;
  bool begun_ = false;
  bool external_context_ = false;
};

/// PNG I/O (stb): RGB, 8 bit, top row first.
void write_png(const std::string& path, int width, int height, const unsigned char* rgb);
std::vector<unsigned char> read_png(const std::string& path, int& width, int& height);

}  // namespace loom::render

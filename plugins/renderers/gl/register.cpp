#include <loom/plugin.hpp>

#include "gl_renderer.hpp"

static void register_gl(loom::Registry& r) {
  r.add_renderer({loom::PluginKind::Renderer, "gl", "cpu", "1.0",
                  "woven-fabric renderer (Kang & Cho 2011 sec. 4): OpenGL ES 3 via headless EGL, PNG per frame", "",
                  &loom::render::render_spec()},
                 [](const loom::Params& p, const std::string& base_dir) {
                   return std::make_unique<loom::render::GlRenderer>(loom::render::parse_render_settings(p, base_dir));
                 });
}
LOOM_PLUGIN(register_gl)

// Colliders for `loom render` (renderer.hpp: kRendererObstaclesSymbol), found by dlsym.
LOOM_PLUGIN_EXPORT void loom_renderer_set_obstacles(loom::Renderer* r, const float* positions,
                                                       const float* normals, std::size_t floats) {
  if (auto* gl = dynamic_cast<loom::render::GlRenderer*>(r))
    gl->set_obstacles({positions, floats}, {normals, floats});
}

// Framing for `loom render` (renderer.hpp: kRendererFitCameraSymbol, kRendererGroundSymbol).
LOOM_PLUGIN_EXPORT void loom_renderer_fit_camera(loom::Renderer* r, const float* lo, const float* hi) {
  if (auto* gl = dynamic_cast<loom::render::GlRenderer*>(r))
    gl->fit_camera(glm::vec3(lo[0], lo[1], lo[2]), glm::vec3(hi[0], hi[1], hi[2]));
}
LOOM_PLUGIN_EXPORT void loom_renderer_set_ground(loom::Renderer* r, const float* point, const float* normal,
                                                    float half_size) {
  if (auto* gl = dynamic_cast<loom::render::GlRenderer*>(r))
    gl->set_ground(glm::vec3(point[0], point[1], point[2]), glm::vec3(normal[0], normal[1], normal[2]), half_size);
}

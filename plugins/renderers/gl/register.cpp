#include <loom/plugin.hpp>

#include "gl_renderer.hpp"

static void register_gl(loom::Registry& r) {
  r.add_renderer({loom::PluginKind::Renderer, "gl", "cpu", "1.0",
                  "woven-fabric renderer (Kang & Cho 2011 sec. 4): OpenGL ES 3 via headless EGL, PNG per frame", ""},
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

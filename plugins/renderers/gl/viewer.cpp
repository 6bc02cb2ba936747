// `loom view`: an interactive GLFW window that plays the frames of a run with the `gl`
// renderer's shading (the same shaders as `loom render`, drawn into the window instead of an
// offscreen framebuffer). Built into the loom_renderer_gl module only when GLFW is found;
// the CLI finds loom_renderer_view by dlsym.
#define GLFW_INCLUDE_ES3
#include <GLFW/glfw3.h>

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <glm/gtc/quaternion.hpp>
#include <string>

#include <loom/plugin.hpp>

#include "gl_renderer.hpp"

namespace {

using loom::render::Camera;
using loom::render::CameraSpec;
using loom::render::GlRenderer;

std::string glfw_error_text;

void on_glfw_error(int code, const char* text) {
  char buf[32];
  std::snprintf(buf, sizeof(buf), " (GLFW error 0x%x)", unsigned(code));
  glfw_error_text = std::string(text ? text : "unknown") + buf;
}

struct ViewState {
  GlRenderer* renderer = nullptr;
  glm::vec3 target{0.0f}, up{0.0f, 1.0f, 0.0f}, offset{0.0f, 0.0f, 1.0f};  ///< eye = target + offset
  glm::vec3 lo{0.0f}, hi{1.0f};
  float fov = 35.0f;
  bool playing = true, dragging = false, quit = false;
  int frame = 0, num_frames = 1, step = 0;  ///< step: +-1 requested by the arrow keys
  double last_x = 0.0, last_y = 0.0;
  bool camera_dirty = true;
};

void on_key(GLFWwindow* w, int key, int, int action, int) {
  auto* s = static_cast<ViewState*>(glfwGetWindowUserPointer(w));
  if (action != GLFW_PRESS && action != GLFW_REPEAT) return;
  if (key == GLFW_KEY_ESCAPE || key == GLFW_KEY_Q) s->quit = true;
  else if (key == GLFW_KEY_SPACE && action == GLFW_PRESS) s->playing = !s->playing;
  else if (key == GLFW_KEY_RIGHT) s->playing = false, s->step += 1;
  else if (key == GLFW_KEY_LEFT) s->playing = false, s->step -= 1;
}

void on_mouse_button(GLFWwindow* w, int button, int action, int) {
  auto* s = static_cast<ViewState*>(glfwGetWindowUserPointer(w));
  if (button != GLFW_MOUSE_BUTTON_LEFT) return;
  s->dragging = action == GLFW_PRESS;
  glfwGetCursorPos(w, &s->last_x, &s->last_y);
}

void on_cursor(GLFWwindow* w, double x, double y) {
  auto* s = static_cast<ViewState*>(glfwGetWindowUserPointer(w));
  if (!s->dragging) return;
  const float dx = float(x - s->last_x), dy = float(y - s->last_y);
  s->last_x = x, s->last_y = y;
  const float k = 0.01f;  // radians per pixel
  // Yaw about the up axis, then pitch about the camera's right axis (kept off the poles).
  glm::vec3 off = glm::angleAxis(-dx * k, s->up) * s->offset;
  const glm::vec3 right = glm::normalize(glm::cross(-off, s->up));
  const glm::vec3 pitched = glm::angleAxis(-dy * k, right) * off;
  const float c = glm::dot(glm::normalize(pitched), s->up);
  if (std::abs(c) < 0.995f) off = pitched;
  s->offset = off;
  s->camera_dirty = true;
}

void on_scroll(GLFWwindow* w, double, double dy) {
  auto* s = static_cast<ViewState*>(glfwGetWindowUserPointer(w));
  s->offset *= std::pow(0.9f, float(dy));
  s->camera_dirty = true;
}

}  // namespace

LOOM_PLUGIN_EXPORT int loom_renderer_view(const loom::RendererViewArgs& args) {
  using loom::InputError;
  auto settings = loom::render::parse_render_settings(*args.render, args.base_dir);
  if (args.num_frames < 1 || !args.mesh) throw InputError("loom view: no frames to show");
  glfwSetErrorCallback(on_glfw_error);
  if (!glfwInit())
    throw InputError("loom view: cannot open a window: glfwInit failed: " + glfw_error_text +
                     ". Fix: run it where a display exists (a desktop session, or ssh -X), or draw images "
                     "with 'loom render' instead.");
  struct Terminate {
    ~Terminate() { glfwTerminate(); }
  } terminate_guard;
  GLFWwindow* window = nullptr;
  // An OpenGL ES 3.0 context (the renderer's shaders are GLSL ES 3.00): native first, then EGL;
  // multisampling stands in for `supersample`.
  const int samples = std::min(16, settings.supersample * settings.supersample);
  for (int attempt = 0; attempt < 4 && !window; ++attempt) {
    glfwDefaultWindowHints();
    glfwWindowHint(GLFW_CLIENT_API, GLFW_OPENGL_ES_API);
    glfwWindowHint(GLFW_CONTEXT_VERSION_MAJOR, 3);
    glfwWindowHint(GLFW_CONTEXT_VERSION_MINOR, 0);
    glfwWindowHint(GLFW_CONTEXT_CREATION_API, attempt % 2 == 0 ? GLFW_NATIVE_CONTEXT_API : GLFW_EGL_CONTEXT_API);
    glfwWindowHint(GLFW_SAMPLES, attempt < 2 && samples > 1 ? samples : 0);
    glfwWindowHint(GLFW_DEPTH_BITS, 24);
    window = glfwCreateWindow(settings.width, settings.height, "loom view", nullptr, nullptr);
  }
  if (!window)
    throw InputError("loom view: cannot create an OpenGL ES 3 window: " + glfw_error_text +
                     ". Fix: run it where a display with OpenGL ES 3 exists (Mesa: apt-get install libgl1-mesa-dri "
                     "libegl-mesa0), or draw images with 'loom render' instead.");
  struct Destroy {
    GLFWwindow* w;
    ~Destroy() { glfwDestroyWindow(w); }
  } destroy_guard{window};
  glfwMakeContextCurrent(window);
  glfwSwapInterval(1);

  ViewState state;
  state.num_frames = args.num_frames;
  {
    GlRenderer renderer(settings, true);
    renderer.begin(*args.mesh);
    state.renderer = &renderer;
    // The whole sequence's box (loom render's framing), else the first frame's.
    float box_lo[3] = {1e30f, 1e30f, 1e30f}, box_hi[3] = {-1e30f, -1e30f, -1e30f};
    if (args.prepare) {
      args.prepare(&renderer, box_lo, box_hi);
    } else {
      for (loom::Index i = 0; i < args.mesh->num_vertices(); ++i)
        for (int k = 0; k < 3; ++k) {
          box_lo[k] = std::min(box_lo[k], float(args.mesh->positions[3 * i + k]));
          box_hi[k] = std::max(box_hi[k], float(args.mesh->positions[3 * i + k]));
        }
    }
    state.lo = glm::vec3(box_lo[0], box_lo[1], box_lo[2]);
    state.hi = glm::vec3(box_hi[0], box_hi[1], box_hi[2]);
    const Camera& c0 = renderer.camera();
    state.target = c0.target;
    state.up = glm::length(c0.up) > 0.0f ? glm::normalize(c0.up) : glm::vec3(0, 1, 0);
    state.offset = c0.eye - c0.target;
    state.fov = c0.fov_deg;
    glfwSetWindowUserPointer(window, &state);
    glfwSetKeyCallback(window, on_key);
    glfwSetMouseButtonCallback(window, on_mouse_button);
    glfwSetCursorPosCallback(window, on_cursor);
    glfwSetScrollCallback(window, on_scroll);

    std::vector<double> x;
    int loaded = -1, last_w = -1, last_h = -1;
    bool shown_playing = !state.playing;
    int title_frame = -1;
    const double frame_time = 1.0 / (args.fps > 0.0 ? args.fps : 30.0);
    double next_advance = glfwGetTime() + frame_time;
    while (!glfwWindowShouldClose(window) && !state.quit) {
      glfwWaitEventsTimeout(state.playing ? 0.002 : 0.05);
      if (state.step != 0) {
        state.frame = ((state.frame + state.step) % state.num_frames + state.num_frames) % state.num_frames;
        state.step = 0;
      }
      const double now = glfwGetTime();
      if (state.playing && now >= next_advance) {
        state.frame = (state.frame + 1) % state.num_frames;
        next_advance = std::max(next_advance + frame_time, now);
      }
      int w = 0, h = 0;
      glfwGetFramebufferSize(window, &w, &h);
      if (w <= 0 || h <= 0) continue;  // minimised
      if (state.camera_dirty || w != last_w || h != last_h) {
        CameraSpec spec;
        spec.has_position = spec.has_target = spec.has_up = true;
        spec.position = state.target + state.offset;
        spec.target = state.target;
        spec.up = state.up;
        spec.fov_deg = state.fov;
        renderer.set_camera(loom::render::make_camera(spec, state.lo, state.hi, w, h));
        state.camera_dirty = false;
        last_w = w, last_h = h;
      }
      if (loaded != state.frame) {
        args.load_frame(state.frame, x);
        renderer.upload(x);
        loaded = state.frame;
      }
      if (loaded == state.frame && (shown_playing != state.playing || title_frame != loaded)) {
        shown_playing = state.playing;
        title_frame = loaded;
        char title[512];
        std::snprintf(title, sizeof(title), "loom view: %s (%d/%d)%s",
                      state.frame < int(args.frame_names.size()) ? args.frame_names[state.frame].c_str() : "",
                      state.frame + 1, state.num_frames, state.playing ? "" : " [paused]");
        glfwSetWindowTitle(window, title);
      }
      renderer.draw(0, w, h);
      glfwSwapBuffers(window);
    }
    state.renderer = nullptr;
  }
  return 0;
}

// Renderer: draws cloth frames to images. Used by `loom render`; not part of a run.
#pragma once

#include <functional>
#include <span>
#include <string>
#include <vector>

#include "loom/mesh.hpp"
#include "loom/params.hpp"

namespace loom {

class Renderer {
 public:
  virtual ~Renderer() = default;
  virtual std::string name() const = 0;
  /// Called once with the mesh of the first frame (topology is fixed for a run).
  virtual void begin(const Mesh& mesh) = 0;
  /// Render positions x (3n) of the mesh given to begin() into an image file at png_path.
  virtual void render(std::span<const double> x, const std::string& png_path) = 0;
};

/// Optional: a renderer module that can draw rigid obstacles (the scene's colliders) exports
/// `extern "C" void loom_renderer_set_obstacles(loom::Renderer*, const float* positions,
/// const float* normals, std::size_t floats)` (found by dlsym, like the viewer; no change to
/// the plugin ABI): a triangle soup, 9 floats per triangle, a unit normal per vertex, drawn with
/// the following render() calls of that renderer. Modules without it draw the cloth only.
using RendererObstaclesFn = void (*)(Renderer*, const float*, const float*, std::size_t);
inline constexpr const char* kRendererObstaclesSymbol = "loom_renderer_set_obstacles";

/// Optional framing entry points of a renderer module, found by dlsym like the obstacles:
/// `extern "C" void loom_renderer_fit_camera(loom::Renderer*, const float lo[3], const float hi[3])`
/// fits the default camera to a box (loom render passes the bounds of the whole sequence), and
/// `extern "C" void loom_renderer_set_ground(loom::Renderer*, const float point[3],
/// const float normal[3], float half_size)` draws a ground square with the cloth's shadow.
/// Both are called after begin().
using RendererFitCameraFn = void (*)(Renderer*, const float*, const float*);
inline constexpr const char* kRendererFitCameraSymbol = "loom_renderer_fit_camera";
using RendererGroundFn = void (*)(Renderer*, const float*, const float*, float);
inline constexpr const char* kRendererGroundSymbol = "loom_renderer_set_ground";

/// What `loom view` hands a renderer module's optional interactive viewer. A module that has
/// one exports `extern "C" int loom_renderer_view(const loom::RendererViewArgs&)` (found by
/// dlsym; see kRendererViewSymbol); it returns an exit code and throws InputError on bad input.
struct RendererViewArgs {
  const Params* render = nullptr;  ///< the scene's `render:` section (may be invalid: defaults)
  std::string base_dir;            ///< folder relative paths in it are resolved against
  const Mesh* mesh = nullptr;      ///< topology (and UVs) of the first frame
  int num_frames = 0;
  std::vector<std::string> frame_names;                    ///< for the window title
  std::function<void(int, std::vector<double>&)> load_frame;  ///< positions (3n) of frame k
  double fps = 30.0;               ///< playback rate
  /// Optional (empty for older callers): called once after begin() with the viewer's renderer.
  /// It frames the run as `loom render` does (the camera fitted to every frame of the sequence,
  /// the ground and the colliders' entry points above) and returns the box it fitted in lo/hi;
  /// the viewer orbits about that box instead of the first frame's. load_frame then also places
  /// the colliders at the frame's time. Appended last, so older viewer modules stay compatible.
  std::function<void(Renderer*, float lo[3], float hi[3])> prepare;
};
using RendererViewFn = int (*)(const RendererViewArgs&);
inline constexpr const char* kRendererViewSymbol = "loom_renderer_view";

}  // namespace loom

#pragma once

#include <string>
#include <vector>

namespace loom::cli {

struct RenderArgs {
  std::string run_dir;            ///< output folder of `loom run`
  std::string scene;              ///< optional scene file with a `render:` section
  std::string out;                ///< image folder (default RUN_DIR/render)
  std::vector<std::string> sets;  ///< --set overrides (render.camera.distance=3, ...)
  bool quiet = false;
};

/// Render every frame_*.obj of a run to PNG with the renderer plugin named by render.type
/// (default "gl"). Throws InputError on bad input.
int render_command(const RenderArgs& args);

/// `loom view RUN_DIR`: play the frames in an interactive window (the renderer module's
/// optional viewer, GLFW). Throws InputError on bad input, without a display, or when the
/// viewer was not built.
int view_command(const RenderArgs& args);

}  // namespace loom::cli

// `loom render RUN_DIR`: draw the OBJ frames of a run with a renderer plugin.
#include "render_cmd.hpp"

#include <dlfcn.h>
#include <unistd.h>

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <filesystem>
#include <fstream>
#include <iostream>
#include <sstream>

#include "loom/collider_geometry.hpp"
#include "loom/output.hpp"
#include "loom/registry.hpp"
#include "loom/renderer.hpp"
#include "loom/spawn.hpp"
#include "render_framing.hpp"

namespace fs = std::filesystem;

namespace loom::cli {

namespace {

// Positions of an OBJ frame written by `loom run` (only 'v' lines are read: simulated
// frames may contain crumpled triangles, which are fine to draw).
void read_frame_positions(const std::string& path, std::vector<double>& x, double* time = nullptr) {
  std::ifstream in(path);
  if (!in) throw InputError(path + ": cannot open frame");
  x.clear();
  std::string line;
  int lineno = 0;
  while (std::getline(in, line)) {
    ++lineno;
    // `loom run` writes "# Loom frame: t = 0.25 s" first: the time the colliders are placed at.
    if (time && lineno == 1 && line.rfind("# Loom frame: t = ", 0) == 0) *time = std::atof(line.c_str() + 18);
    if (line.size() < 2 || line[0] != 'v' || line[1] != ' ') continue;
    std::istringstream ls(line.substr(2));
    double a, b, c;
    if (!(ls >> a >> b >> c)) throw InputError(path + ":" + std::to_string(lineno) + ": bad vertex line");
    x.insert(x.end(), {a, b, c});
  }
}

// The frames, scene and `render:` section of a run folder (shared by render and view).
struct RunInput {
  std::vector<fs::path> frames;
  Params root;
  Params render;
  std::string base_dir;
  std::string type;
};

RunInput load_run(const std::string& run_dir_arg, const std::string& scene_arg, const std::vector<std::string>& sets) {
  RunInput in;
  const fs::path run_dir = run_dir_arg;
  if (!fs::is_directory(run_dir))
    throw InputError(run_dir_arg + ": not a folder. Fix: give the output folder of 'loom run' (it holds frame_*.obj).");
  for (const auto& e : fs::directory_iterator(run_dir)) {
    const std::string f = e.path().filename().string();
    if (f.rfind("frame_", 0) == 0 && e.path().extension() == ".obj") in.frames.push_back(e.path());
  }
  std::sort(in.frames.begin(), in.frames.end());
  if (in.frames.empty()) throw InputError(run_dir_arg + ": no frame_*.obj files. Fix: run 'loom run SCENE --out " + run_dir_arg + "' first.");

  // The render settings come from the scene: --scene, else the copy `loom run` left in the folder.
  const std::string scene_path = scene_arg.empty() ? (run_dir / "scene.yaml").string() : scene_arg;
  in.root = fs::exists(scene_path) ? Params::from_file(scene_path) : Params::from_string("{}", "<defaults>");
  for (const auto& o : sets) {
    const auto eq = o.find('=');
    if (eq == std::string::npos || eq == 0) throw InputError("--set " + o + ": expected key=value");
    in.root.set_path(o.substr(0, eq), o.substr(eq + 1));
  }
  in.base_dir = fs::path(scene_path).parent_path().string();
  if (scene_arg.empty() && fs::exists(scene_path)) {
    std::ifstream f(scene_path);
    std::string line;
    while (std::getline(f, line))
      if (line.rfind("# loom-scene-dir: ", 0) == 0) in.base_dir = line.substr(18);
  }
  in.render = in.root.child("render");
  in.type = in.render.valid() ? in.render.get("type", std::string("gl")) : std::string("gl");
  return in;
}

// Topology from the first frame (a full, validated OBJ read). Frames carry no texture
// coordinates: take the scene mesh's own (an OBJ with vt, per vertex and per corner) when it
// has them for the same vertices; otherwise the renderer derives planar ones.
Mesh first_frame_mesh(const RunInput& in) {
  Mesh mesh = read_obj(in.frames.front().string(), 0.0);
  Params mesh_spec = in.root.child("mesh");
  if (mesh_spec.valid() && mesh_spec.is_map() && mesh_spec.has("obj")) {
    fs::path obj = mesh_spec.child("obj").as_string();
    if (obj.is_relative() && !in.base_dir.empty()) obj = fs::path(in.base_dir) / obj;
    if (fs::exists(obj)) {
      Mesh source = read_obj(obj.string());
      if (source.num_vertices() == mesh.num_vertices() && source.uvs.size() == 2 * std::size_t(mesh.num_vertices())) {
        mesh.uvs = std::move(source.uvs);
        // Per-corner uvs (UV seams) when the triangles are the same: the renderer splits the
        // seam vertices so that each side keeps its texture coordinates.
        mesh.corner_uvs.clear();
        if (source.triangles == mesh.triangles) mesh.corner_uvs = std::move(source.corner_uvs);
      }
    }
  }
  return mesh;
}

void check_frame_size(const fs::path& f, const std::vector<double>& x, const Mesh& mesh) {
  if (x.size() != mesh.positions.size())
    throw InputError(f.string() + ": has " + std::to_string(x.size() / 3) + " vertices, the first frame has " +
                     std::to_string(mesh.positions.size() / 3) + ". Fix: render the frames of one run only.");
}

// The renderer module's optional obstacle entry point (renderer.hpp), or null: the cloth only.
RendererObstaclesFn obstacles_entry(const Registry& registry, const std::string& type) {
  RendererObstaclesFn f = nullptr;
  for (const auto& info : registry.list())
    if (info.kind == PluginKind::Renderer && info.name == type && !info.module_path.empty())
      if (void* h = ::dlopen(info.module_path.c_str(), RTLD_NOW | RTLD_NOLOAD)) {
        f = reinterpret_cast<RendererObstaclesFn>(::dlsym(h, kRendererObstaclesSymbol));
        ::dlclose(h);
      }
  return f;
}

}  // namespace

int render_command(const RenderArgs& args) {
  RunInput in = load_run(args.run_dir, args.scene, args.sets);
  const fs::path run_dir = args.run_dir;
  const auto& frames = in.frames;
  const std::string& base_dir = in.base_dir;
  const std::string& type = in.type;
  Params& render = in.render;
  // MP4 of the frames through ffmpeg: auto (when ffmpeg is on the PATH), on, off.
  std::string video = "auto";
  double fps = 30.0;
  if (render.valid()) {
    Params v = render.child("video");
    if (v.valid()) {
      const std::string s = v.as_string();
      if (s == "auto") video = "auto";
      else if (s == "on" || s == "true" || s == "yes") video = "on";
      else if (s == "off" || s == "false" || s == "no") video = "off";
      else v.fail("unknown value '" + s + "'. Choose one of: auto, on, off.");
    }
    fps = render.get_positive("fps", fps);
  }
  const bool have_ffmpeg = program_on_path("ffmpeg");
  if (video == "on" && !have_ffmpeg)
    throw InputError("render.video is on but ffmpeg is not installed. Fix: apt-get install ffmpeg, or set render.video: off.");

  Registry registry;
  PluginLoader loader(registry);
  loader.ensure(PluginKind::Renderer, type);
  auto renderer = registry.make_renderer(type, render, base_dir);

  const fs::path out_dir = args.out.empty() ? run_dir / "render" : fs::path(args.out);
  prepare_output_dir(out_dir.string());

  Mesh mesh = first_frame_mesh(in);
  renderer->begin(mesh);
  // The scene's colliders, drawn with the cloth at each frame's time (a plane as a square
  // around the sequence's cloth).
  ColliderSet colliders;
  if (Params cp = in.root.child("colliders"); cp.valid()) colliders = ColliderSet::parse(cp, in.base_dir);
  // Framing (render_framing.cpp): the camera fits the whole sequence, a ground with the
  // cloth's shadow lies under its lowest point.
  const Framing framing = frame_sequence(
      in.frames, [](const fs::path& f, std::vector<double>& x, double* t) { read_frame_positions(f.string(), x, t); },
      in.root, render, colliders, registry, type, renderer.get());
  const double* focus = framing.center;
  const double plane_size = framing.plane_size;
  const RendererObstaclesFn set_obstacles = colliders.empty() ? nullptr : obstacles_entry(registry, type);
  std::vector<float> obstacle_pos, obstacle_nrm;
  std::vector<double> x;
  int k = 0;
  for (const auto& f : frames) {
    double t = 0;
    read_frame_positions(f.string(), x, &t);
    check_frame_size(f, x, mesh);
    if (set_obstacles) {
      obstacle_pos.clear();
      obstacle_nrm.clear();
      collider_triangles(colliders, t, focus, plane_size, obstacle_pos, obstacle_nrm);
      set_obstacles(renderer.get(), obstacle_pos.data(), obstacle_nrm.data(), obstacle_pos.size());
    }
    const std::string png = (out_dir / (f.stem().string() + ".png")).string();
    renderer->render(x, png);
    ++k;
    if (!args.quiet && ::isatty(STDOUT_FILENO)) {
      std::printf("\rrendered %d/%zu frames", k, frames.size());
      std::fflush(stdout);
    }
  }
  if (!args.quiet) std::printf("\nloom: wrote %d images to %s\n", k, out_dir.string().c_str());
  if (video != "off" && have_ffmpeg) {
    const std::string mp4 = (out_dir / "render.mp4").string();
    char rate[32];
    std::snprintf(rate, sizeof(rate), "%g", fps);
    const std::vector<std::string> argv = {"ffmpeg", "-y", "-loglevel", "error", "-framerate", rate, "-pattern_type",
                                           "glob", "-i", (out_dir / "frame_*.png").string(), "-vf",
                                           "pad=ceil(iw/2)*2:ceil(ih/2)*2", "-pix_fmt", "yuv420p", "-c:v", "libx264", mp4};
    const SpawnResult r = run_program(argv, /*quiet=*/false);
    if (!r.ok()) throw std::runtime_error("ffmpeg failed to write " + mp4 + ": " + r.error);
    if (!args.quiet) std::printf("loom: wrote %s\n", mp4.c_str());
  }
  return 0;
}

int view_command(const RenderArgs& args) {
  RunInput in = load_run(args.run_dir, args.scene, args.sets);
  const char* x11 = std::getenv("DISPLAY");
  const char* wayland = std::getenv("WAYLAND_DISPLAY");
  if ((!x11 || !*x11) && (!wayland || !*wayland))
    throw InputError("loom view needs a display (DISPLAY and WAYLAND_DISPLAY are unset). Fix: run it where a display "
                     "exists (a desktop session, or ssh -X), or draw images with 'loom render " + args.run_dir + "'.");
  double fps = 30.0;
  if (in.render.valid()) fps = in.render.get_positive("fps", fps);

  Registry registry;
  PluginLoader loader(registry);
  loader.ensure(PluginKind::Renderer, in.type);
  std::string module;
  for (const auto& info : registry.list())
    if (info.kind == PluginKind::Renderer && info.name == in.type) module = info.module_path;
  RendererViewFn view = nullptr;
  if (!module.empty()) {
    // Already loaded by ensure(): RTLD_NOLOAD returns the same handle.
    if (void* h = ::dlopen(module.c_str(), RTLD_NOW | RTLD_NOLOAD)) {
      view = reinterpret_cast<RendererViewFn>(::dlsym(h, kRendererViewSymbol));
      ::dlclose(h);
    }
  }
  if (!view)
    throw InputError("the renderer '" + in.type + "' (" + (module.empty() ? std::string("built in") : module) +
                     ") has no interactive viewer: this Loom was built without GLFW. Fix: apt-get install "
                     "libglfw3-dev and rebuild (cmake, then ninja), or draw images with 'loom render'.");

  const Mesh mesh = first_frame_mesh(in);
  RendererViewArgs va;
  va.render = &in.render;
  va.base_dir = in.base_dir;
  va.mesh = &mesh;
  va.num_frames = int(in.frames.size());
  for (const auto& f : in.frames) va.frame_names.push_back(f.filename().string());
  va.fps = fps;
  // Framing as in `loom render` (render_framing.cpp): the camera fits every frame (render.fit),
  // a ground with the cloth's shadow, and the colliders drawn at each frame's time.
  ColliderSet colliders;
  if (Params cp = in.root.child("colliders"); cp.valid()) colliders = ColliderSet::parse(cp, in.base_dir);
  const RendererObstaclesFn set_obstacles = colliders.empty() ? nullptr : obstacles_entry(registry, in.type);
  Renderer* view_renderer = nullptr;
  Framing framing;
  const bool fit_sequence =
      !in.render.valid() || in.render.get_choice("fit", std::string("sequence"), {"sequence", "first_frame"}) == "sequence";
  va.prepare = [&](Renderer* r, float lo[3], float hi[3]) {
    view_renderer = r;
    framing = frame_sequence(
        in.frames, [](const fs::path& f, std::vector<double>& x, double* t) { read_frame_positions(f.string(), x, t); },
        in.root, in.render, colliders, registry, in.type, r);
    for (int c = 0; c < 3; ++c) {
      lo[c] = float(framing.lo[c]);
      hi[c] = float(framing.hi[c]);
    }
    if (!fit_sequence)  // render.fit: first_frame: the first frame's box
      for (Index i = 0; i < mesh.num_vertices(); ++i)
        for (int c = 0; c < 3; ++c) {
          lo[c] = std::min(i ? lo[c] : 1e30f, float(mesh.positions[3 * i + c]));
          hi[c] = std::max(i ? hi[c] : -1e30f, float(mesh.positions[3 * i + c]));
        }
  };
  std::vector<float> obstacle_pos, obstacle_nrm;
  va.load_frame = [&](int k, std::vector<double>& x) {
    const fs::path& f = in.frames.at(std::size_t(k));
    double t = 0;
    read_frame_positions(f.string(), x, &t);
    check_frame_size(f, x, mesh);
    if (set_obstacles && view_renderer) {
      obstacle_pos.clear();
      obstacle_nrm.clear();
      collider_triangles(colliders, t, framing.center, framing.plane_size, obstacle_pos, obstacle_nrm);
      set_obstacles(view_renderer, obstacle_pos.data(), obstacle_nrm.data(), obstacle_pos.size());
    }
  };
  if (!args.quiet)
    std::printf("loom: viewing %zu frames of %s (drag: rotate, scroll: zoom, space: play/pause, "
                "left/right: step, Esc/q: quit)\n", in.frames.size(), args.run_dir.c_str());
  std::fflush(stdout);
  return view(va);
}

}  // namespace loom::cli

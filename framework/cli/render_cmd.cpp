// `loom render RUN_DIR`: draw the OBJ frames of a run with a renderer plugin.
#include "render_cmd.hpp"

#include <unistd.h>

#include <algorithm>
#include <cstdio>
#include <cstdlib>
#include <filesystem>
#include <fstream>
#include <iostream>
#include <sstream>

#include "loom/output.hpp"
#include "loom/registry.hpp"

namespace fs = std::filesystem;

namespace loom::cli {

namespace {

// Positions of an OBJ frame written by `loom run` (only 'v' lines are read: simulated
// frames may contain crumpled triangles, which are fine to draw).
void read_frame_positions(const std::string& path, std::vector<double>& x) {
  std::ifstream in(path);
  if (!in) throw InputError(path + ": cannot open frame");
  x.clear();
  std::string line;
  int lineno = 0;
  while (std::getline(in, line)) {
    ++lineno;
    if (line.size() < 2 || line[0] != 'v' || line[1] != ' ') continue;
    std::istringstream ls(line.substr(2));
    double a, b, c;
    if (!(ls >> a >> b >> c)) throw InputError(path + ":" + std::to_string(lineno) + ": bad vertex line");
    x.insert(x.end(), {a, b, c});
  }
}

}  // namespace

int render_command(const RenderArgs& args) {
  const fs::path run_dir = args.run_dir;
  if (!fs::is_directory(run_dir))
    throw InputError(args.run_dir + ": not a folder. Fix: give the output folder of 'loom run' (it holds frame_*.obj).");
  std::vector<fs::path> frames;
  for (const auto& e : fs::directory_iterator(run_dir)) {
    const std::string f = e.path().filename().string();
    if (f.rfind("frame_", 0) == 0 && e.path().extension() == ".obj") frames.push_back(e.path());
  }
  std::sort(frames.begin(), frames.end());
  if (frames.empty()) throw InputError(args.run_dir + ": no frame_*.obj files. Fix: run 'loom run SCENE --out " + args.run_dir + "' first.");

  // The render settings come from the scene: --scene, else the copy `loom run` left in the folder.
  const std::string scene_path = args.scene.empty() ? (run_dir / "scene.yaml").string() : args.scene;
  Params root = fs::exists(scene_path) ? Params::from_file(scene_path) : Params::from_string("{}", "<defaults>");
  for (const auto& o : args.sets) {
    const auto eq = o.find('=');
    if (eq == std::string::npos || eq == 0) throw InputError("--set " + o + ": expected key=value");
    root.set_path(o.substr(0, eq), o.substr(eq + 1));
  }
  std::string base_dir = fs::path(scene_path).parent_path().string();
  if (args.scene.empty() && fs::exists(scene_path)) {
    std::ifstream in(scene_path);
    std::string line;
    while (std::getline(in, line))
      if (line.rfind("# loom-scene-dir: ", 0) == 0) base_dir = line.substr(18);
  }
  Params render = root.child("render");
  const std::string type = render.valid() ? render.get("type", std::string("gl")) : std::string("gl");
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
  const bool have_ffmpeg = std::system("command -v ffmpeg > /dev/null 2>&1") == 0;
  if (video == "on" && !have_ffmpeg)
    throw InputError("render.video is on but ffmpeg is not installed. Fix: apt-get install ffmpeg, or set render.video: off.");

  Registry registry;
  PluginLoader loader(registry);
  loader.ensure(PluginKind::Renderer, type);
  auto renderer = registry.make_renderer(type, render, base_dir);

  const fs::path out_dir = args.out.empty() ? run_dir / "render" : fs::path(args.out);
  prepare_output_dir(out_dir.string());

  // Topology from the first frame (a full, validated OBJ read).
  Mesh mesh = read_obj(frames.front().string(), 0.0);
  // Frames carry no texture coordinates: take the scene mesh's own (an OBJ with vt) when it
  // has them for the same vertices; otherwise the renderer derives planar ones.
  Params mesh_spec = root.child("mesh");
  if (mesh_spec.valid() && mesh_spec.is_map() && mesh_spec.has("obj")) {
    fs::path obj = mesh_spec.child("obj").as_string();
    if (obj.is_relative() && !base_dir.empty()) obj = fs::path(base_dir) / obj;
    if (fs::exists(obj)) {
      Mesh source = read_obj(obj.string());
      if (source.num_vertices() == mesh.num_vertices() && source.uvs.size() == 2 * std::size_t(mesh.num_vertices()))
        mesh.uvs = std::move(source.uvs);
    }
  }
  renderer->begin(mesh);
  std::vector<double> x;
  int k = 0;
  for (const auto& f : frames) {
    read_frame_positions(f.string(), x);
    if (x.size() != mesh.positions.size())
      throw InputError(f.string() + ": has " + std::to_string(x.size() / 3) + " vertices, the first frame has " +
                       std::to_string(mesh.positions.size() / 3) + ". Fix: render the frames of one run only.");
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
    auto quote = [](const std::string& t) {
      std::string q = "'";
      for (char c : t) q += c == '\'' ? std::string("'\\''") : std::string(1, c);
      return q + "'";
    };
    const std::string cmd = "ffmpeg -y -loglevel error -framerate " + std::string(rate) + " -pattern_type glob -i " +
                            quote((out_dir / "frame_*.png").string()) +
                            " -vf 'pad=ceil(iw/2)*2:ceil(ih/2)*2' -pix_fmt yuv420p -c:v libx264 " + quote(mp4);
    if (std::system(cmd.c_str()) != 0)
      throw std::runtime_error("ffmpeg failed to write " + mp4 + " (command: " + cmd + ")");
    if (!args.quiet) std::printf("loom: wrote %s\n", mp4.c_str());
  }
  return 0;
}

}  // namespace loom::cli

#include "resume_cmd.hpp"

#include <cstdio>
#include <filesystem>
#include <fstream>
#include <iterator>

#include "loom/common.hpp"
#include "loom/output.hpp"

namespace fs = std::filesystem;

namespace loom::cli {

std::unique_ptr<Simulation> load_run_scene(const std::string& run_dir, PluginLoader& loader) {
  if (!fs::is_directory(run_dir))
    throw InputError(run_dir + ": not a folder. Fix: --resume takes the output folder of a stopped 'loom run'.");
  const fs::path scene = fs::path(run_dir) / "scene.yaml";
  std::ifstream in(scene, std::ios::binary);
  if (!in)
    throw InputError(scene.string() + ": missing. Fix: --resume takes the output folder of a stopped 'loom run' "
                     "(it holds scene.yaml, stats.csv and restart.bin).");
  const std::string text((std::istreambuf_iterator<char>(in)), {});
  auto tagged = [&](const std::string& tag, const std::string& fallback) {
    const auto p = text.find(tag);
    if (p == std::string::npos) return fallback;
    const auto e = text.find('\n', p);
    return text.substr(p + tag.size(), e == std::string::npos ? std::string::npos : e - p - tag.size());
  };
  // Relative paths resolve against the original scene's folder, as when the run started; the
  // source name is the original scene file (plugins resolve their files against it).
  const std::string base_dir = tagged("# loom-scene-dir: ", run_dir);
  const std::string source = tagged("# loom-scene-file: ", scene.string());
  // The file holds the scene as it ran (overrides applied): no --set needed, none allowed.
  std::unique_ptr<Simulation> sim;
  try {
    sim = Simulation::from_string(text, source, base_dir, {}, loader);
  } catch (const InputError& e) {
    if (source == scene.string()) throw;
    throw InputError(std::string(e.what()) + " (line numbers refer to " + scene.string() +
                     ", the copy of the scene the run left)");
  }
  return sim;
}

std::unique_ptr<Simulation> load_for_resume(const std::string& run_dir, int frames, PluginLoader& loader) {
  std::unique_ptr<Simulation> sim = load_run_scene(run_dir, loader);
  sim->output().dir = run_dir;
  sim->resume(frames);
  // What continues from the exact state but not bit for bit (docs/OUTPUT.md).
  std::string why;
  if (sim->scene().self_collision) why = "self-collision reuses the last step's broad phase";
  else if (sim->scene().backend != "cpu") why = "the " + sim->scene().backend + " backend's integrators keep device state";
  if (!why.empty() && is_output_rank())
    std::fprintf(stderr, "loom: note: this run continues from its exact state, but %s: it is not guaranteed to "
                         "match an uninterrupted run bit for bit (docs/OUTPUT.md).\n", why.c_str());
  return sim;
}

}  // namespace loom::cli

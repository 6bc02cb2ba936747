#include "resume_cmd.hpp"

#include <filesystem>
#include <fstream>
#include <iterator>

#include "loom/common.hpp"

namespace fs = std::filesystem;

namespace loom::cli {

std::unique_ptr<Simulation> load_for_resume(const std::string& run_dir, int frames, PluginLoader& loader) {
  if (!fs::is_directory(run_dir))
    throw InputError(run_dir + ": not a folder. Fix: --resume takes the output folder of a stopped 'loom run'.");
  const fs::path scene = fs::path(run_dir) / "scene.yaml";
  std::ifstream in(scene, std::ios::binary);
  if (!in)
    throw InputError(scene.string() + ": missing. Fix: --resume takes the output folder of a stopped 'loom run' "
                     "(it holds scene.yaml, stats.csv and restart.bin).");
  const std::string text((std::istreambuf_iterator<char>(in)), {});
  std::string base_dir = run_dir;
  const std::string tag = "# loom-scene-dir: ";
  if (const auto p = text.find(tag); p != std::string::npos) {
    const auto e = text.find('\n', p);
    base_dir = text.substr(p + tag.size(), e == std::string::npos ? std::string::npos : e - p - tag.size());
  }
  // The file holds the scene as it ran (overrides applied): no --set needed, none allowed.
  auto sim = Simulation::from_string(text, scene.string(), base_dir, {}, loader);
  sim->output().dir = run_dir;
  sim->resume(frames);
  return sim;
}

}  // namespace loom::cli

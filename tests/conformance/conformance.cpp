#include "conformance.hpp"

#include <algorithm>
#include <filesystem>

namespace loom::conformance {

Loaded& plugins() {
  static Loaded l = [] {
    Loaded x;
    x.loader = std::make_unique<PluginLoader>(x.reg, std::vector<std::string>{LOOM_PLUGIN_DIR});
    x.loader->load_all(x.errors);
    return x;
  }();
  return l;
}

std::vector<std::string> plugin_names(PluginKind kind) {
  std::vector<std::string> names;
  for (const auto& info : plugins().reg.list())
    if (info.kind == kind && info.backend == "cpu") names.push_back(info.name);
  const std::filesystem::path folder =
      std::filesystem::path(LOOM_SOURCE_DIR) / "plugins" / (std::string(to_string(kind)) + "s");
  std::error_code ec;
  for (const auto& d : std::filesystem::directory_iterator(folder, ec))
    if (d.is_directory()) names.push_back(d.path().filename().string());
  std::sort(names.begin(), names.end());
  names.erase(std::unique(names.begin(), names.end()), names.end());
  return names;
}

std::string required_keys(const std::string& name) {
  if (name == "gnatv") return "material_file: " + std::string(LOOM_SOURCE_DIR) + "/materials/wool.yaml\n";
  return "";
}

}  // namespace loom::conformance

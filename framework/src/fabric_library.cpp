#include "loom/fabric_library.hpp"

#include <unistd.h>

#include <algorithm>
#include <cstdlib>
#include <filesystem>
#include <system_error>

namespace fs = std::filesystem;

namespace loom {

std::vector<std::string> fabric_search_path() {
  std::vector<std::string> path;
  if (const char* env = std::getenv("LOOM_FABRIC_PATH")) {
    const std::string s(env);
    std::size_t start = 0;
    for (;;) {
      const std::size_t end = s.find(':', start);
      const std::string part = s.substr(start, end == std::string::npos ? std::string::npos : end - start);
      if (!part.empty()) path.push_back(part);
      if (end == std::string::npos) break;
      start = end + 1;
    }
  }
  path.push_back(std::string(LOOM_SOURCE_MATERIALS_DIR) + "/wang2011");
  std::error_code ec;
  const fs::path exe = fs::read_symlink("/proc/self/exe", ec);
  if (!ec) path.push_back((exe.parent_path().parent_path() / "share/loom/materials/wang2011").string());
  return path;
}

std::vector<std::string> list_fabrics() {
  std::vector<std::string> names;
  for (const auto& dir : fabric_search_path()) {
    std::error_code ec;
    for (fs::directory_iterator it(dir, ec), end; !ec && it != end; it.increment(ec))
      if (it->is_regular_file() && it->path().extension() == ".yaml") names.push_back(it->path().stem().string());
  }
  std::sort(names.begin(), names.end());
  names.erase(std::unique(names.begin(), names.end()), names.end());
  return names;
}

std::string resolve_fabric(const Params& name_node) {
  const std::string name = name_node.as_string();
  if (name.find('/') == std::string::npos && !name.empty())
    for (const auto& dir : fabric_search_path()) {
      const fs::path p = fs::path(dir) / (name + ".yaml");
      std::error_code ec;
      if (fs::is_regular_file(p, ec)) return p.string();
    }
  const auto names = list_fabrics();
  std::string list;
  for (const auto& n : names) list += (list.empty() ? "" : ", ") + n;
  const std::string hint = closest_match(name, names);
  name_node.fail("unknown fabric '" + name + "'" + (hint.empty() ? "" : " (did you mean '" + hint + "'?)") +
                 ". Fabrics: " + (list.empty() ? "none found" : list) +
                 " (materials/wang2011/; more folders with LOOM_FABRIC_PATH).");
}

Params apply_fabric(const Params& material, const std::string& type) {
  if (!material.has("fabric")) return Params();
  const Params node = material.child("fabric");
  if (type != "gnatv")
    node.fail("a measured fabric sets a gnatv material (its curves and bending), but the type is '" + type +
              "'. Fix: type: gnatv, or remove 'fabric'.");
  if (material.has("material_file"))
    node.fail("give either 'fabric' (a library name) or 'material_file', not both.");
  const std::string path = resolve_fabric(node);
  std::string quoted = "\"";
  for (char c : path) {
    if (c == '"' || c == '\\') quoted += '\\';
    quoted += c;
  }
  quoted += "\"";
  Params writable = material;  // a handle on the same YAML node
  writable.set_path("material_file", quoted);
  const Params file = Params::from_file(path);
  return file.has("bending") ? file.child("bending") : Params();
}

}  // namespace loom

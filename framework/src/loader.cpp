#include <dlfcn.h>
#include <unistd.h>

#include <algorithm>
#include <cstdlib>
#include <filesystem>
#include <limits.h>

#include "loom/blas_kernels.hpp"
#include "loom/registry.hpp"

namespace fs = std::filesystem;

namespace loom {

namespace {

std::string exe_dir() {
  char buf[PATH_MAX];
  const ssize_t n = ::readlink("/proc/self/exe", buf, sizeof(buf) - 1);
  if (n <= 0) return {};
  buf[n] = '\0';
  return fs::path(buf).parent_path().string();
}

std::string module_prefix(PluginKind k) { return std::string("loom_") + to_string(k) + "_"; }

}  // namespace

std::vector<std::string> PluginLoader::default_search_path() {
  std::vector<std::string> path;
  if (const char* env = std::getenv("LOOM_PLUGIN_PATH")) {
    std::string s(env);
    std::size_t start = 0;
    while (start <= s.size()) {
      const std::size_t end = s.find(':', start);
      const std::string part = s.substr(start, end == std::string::npos ? std::string::npos : end - start);
      if (!part.empty()) path.push_back(part);
      if (end == std::string::npos) break;
      start = end + 1;
    }
  }
  const std::string exe = exe_dir();
  // Build tree: the executable lives in <build>/bin, plugins in <build>/lib/loom/plugins.
  if (!exe.empty()) {
    const fs::path build_dir = fs::path(exe).parent_path() / "lib" / "loom" / "plugins";
    path.push_back(build_dir.string());
  }
  path.push_back(LOOM_BUILD_PLUGIN_DIR);
  // Install tree: <prefix>/bin/loom and <prefix>/<libdir>/loom/plugins.
  if (!exe.empty()) path.push_back((fs::path(exe).parent_path() / LOOM_INSTALL_PLUGIN_DIR_REL).string());
  // Deduplicate, keeping the first occurrence.
  std::vector<std::string> out;
  for (const auto& p : path) {
    std::error_code ec;
    const std::string canon = fs::weakly_canonical(p, ec).string();
    const std::string key = ec ? p : canon;
    if (std::find(out.begin(), out.end(), key) == out.end()) out.push_back(key);
  }
  return out;
}

PluginLoader::PluginLoader(Registry& registry, std::vector<std::string> search_path)
    : registry_(registry), search_path_(std::move(search_path)) {}

PluginLoader::~PluginLoader() {
  // Modules stay loaded for the life of the process: objects they created (and their
  // vtables) may outlive the loader. The OS unloads them at exit.
}

std::string PluginLoader::find_module(PluginKind kind, const std::string& name) const {
  const std::string file = module_prefix(kind) + name + ".so";
  for (const auto& dir : search_path_) {
    std::error_code ec;
    const fs::path p = fs::path(dir) / file;
    if (fs::exists(p, ec)) return p.string();
  }
  return {};
}

bool PluginLoader::available(PluginKind kind, const std::string& name) const {
  return registry_.has(kind, name, "cpu") || !registry_.backends(kind, name).empty() || !find_module(kind, name).empty();
}

std::vector<std::string> PluginLoader::names(PluginKind kind) const {
  std::vector<std::string> out;
  const std::string prefix = module_prefix(kind);
  for (const auto& dir : search_path_) {
    std::error_code ec;
    if (!fs::is_directory(dir, ec)) continue;
    for (const auto& entry : fs::directory_iterator(dir, ec)) {
      const std::string f = entry.path().filename().string();
      if (f.rfind(prefix, 0) == 0 && f.size() > prefix.size() + 3 && f.substr(f.size() - 3) == ".so")
        out.push_back(f.substr(prefix.size(), f.size() - prefix.size() - 3));
    }
  }
  for (const auto& info : registry_.list())
    if (info.kind == kind) out.push_back(info.name);
  std::sort(out.begin(), out.end());
  out.erase(std::unique(out.begin(), out.end()), out.end());
  return out;
}

void PluginLoader::load_file(const std::string& path) {
  if (std::find(loaded_.begin(), loaded_.end(), path) != loaded_.end()) return;
  // Before the first plugin brings in OpenBLAS (cholmod, petsc): its kernels by the CPU's
  // instructions unless the user chose them (loom/blas_kernels.hpp).
  static const char* const blas_kernels [[maybe_unused]] = choose_openblas_kernels();
  void* h = ::dlopen(path.c_str(), RTLD_NOW | RTLD_LOCAL);
  if (!h) {
    const char* err = ::dlerror();
    throw InputError("cannot load plugin module " + path + ": " + (err ? err : "unknown dlopen error") +
                     ". Fix: rebuild it against this Loom (cmake --build), or remove it from the plugin path.");
  }
  using AbiFn = int (*)();
  using RegFn = void (*)(Registry&);
  auto abi = reinterpret_cast<AbiFn>(::dlsym(h, "loom_plugin_abi_version"));
  auto reg = reinterpret_cast<RegFn>(::dlsym(h, "loom_register_plugin"));
  if (!abi || !reg) {
    ::dlclose(h);
    throw InputError("plugin module " + path +
                     " does not export loom_plugin_abi_version/loom_register_plugin. Fix: end the plugin's "
                     "registration file with LOOM_PLUGIN(your_register_function).");
  }
  const int v = abi();
  if (v != kPluginAbiVersion) {
    ::dlclose(h);
    throw InputError("plugin module " + path + " was built for plugin ABI version " + std::to_string(v) +
                     ", this Loom has version " + std::to_string(kPluginAbiVersion) +
                     ". Fix: rebuild the plugin against this Loom's headers.");
  }
  registry_.set_current_module(path);
  reg(registry_);
  registry_.set_current_module("");
  handles_.push_back(h);
  loaded_.push_back(path);
}

void PluginLoader::ensure(PluginKind kind, const std::string& name) {
  if (!registry_.backends(kind, name).empty()) return;
  const std::string path = find_module(kind, name);
  if (path.empty()) {
    const auto avail = names(kind);
    std::string list;
    for (const auto& n : avail) list += (list.empty() ? "" : ", ") + n;
    const std::string hint = closest_match(name, avail);
    std::string dirs;
    for (const auto& d : search_path_) dirs += (dirs.empty() ? "" : ":") + d;
    const std::string shown = name.size() > 64 ? name.substr(0, 64) + "...(" + std::to_string(name.size()) + " characters)" : name;
    throw InputError(std::string("unknown ") + to_string(kind) + " '" + shown + "'" +
                     (hint.empty() ? "" : " (did you mean '" + hint + "'?)") +
                     ". Available: " + (list.empty() ? "none" : list) + ". Searched for " + module_prefix(kind) + shown +
                     ".so in " + dirs + " (set LOOM_PLUGIN_PATH to add folders).");
  }
  load_file(path);
  if (registry_.backends(kind, name).empty())
    throw InputError("plugin module " + path + " loaded but did not register " + to_string(kind) + " '" + name +
                     "'. Fix: the registered name must match the module file name.");
}

void PluginLoader::ensure_backend(const std::string& backend) {
  if (backend == "cpu") return;
  const std::string file = "loom_backend_" + backend + ".so";
  for (const auto& dir : search_path_) {
    std::error_code ec;
    const fs::path p = fs::path(dir) / file;
    if (fs::exists(p, ec)) {
      load_file(p.string());
      return;
    }
  }
  std::string dirs;
  for (const auto& d : search_path_) dirs += (dirs.empty() ? "" : ":") + d;
  throw InputError("backend '" + backend + "' is not in this build: " + file + " was not found in " + dirs +
                   (backend == "cuda" ? ". It is built only when CMake finds the CUDA toolkit (nvcc); "
                                        "rebuild with CUDA, or set backend: cpu."
                                      : ". Fix: set backend: cpu."));
}

void PluginLoader::load_all(std::vector<std::string>& errors) {
  for (const auto& dir : search_path_) {
    std::error_code ec;
    if (!fs::is_directory(dir, ec)) continue;
    std::vector<fs::path> files;
    for (const auto& entry : fs::directory_iterator(dir, ec)) {
      const std::string f = entry.path().filename().string();
      if (f.rfind("loom_", 0) == 0 && f.size() > 3 && f.substr(f.size() - 3) == ".so") files.push_back(entry.path());
    }
    std::sort(files.begin(), files.end());
    for (const auto& f : files) {
      try {
        load_file(f.string());
      } catch (const std::exception& e) {
        errors.push_back(e.what());
      }
    }
  }
}

}  // namespace loom

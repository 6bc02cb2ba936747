// The plugin registry and loader.
//
// A plugin is a shared module named loom_<kind>_<name>.so (kind: material, integrator,
// solver, renderer) exporting the entry points defined by LOOM_PLUGIN (loom/plugin.hpp). The loader
// finds modules on the plugin path: $LOOM_PLUGIN_PATH (colon separated), then the build
// tree's plugin folder, then the install tree's (<prefix>/lib/loom/plugins). Only modules
// that a scene names are loaded.
#pragma once

#include <functional>
#include <map>
#include <memory>
#include <string>
#include <tuple>
#include <variant>
#include <vector>

#include "loom/common.hpp"
#include "loom/integrator.hpp"
#include "loom/linear_solver.hpp"
#include "loom/material.hpp"
#include "loom/mesh.hpp"
#include "loom/param_spec.hpp"
#include "loom/params.hpp"
#include "loom/renderer.hpp"

namespace loom {

/// Bumped whenever an interface in framework/include/loom changes incompatibly.
constexpr int kPluginAbiVersion = 6;  // 2: LinearSolver::set_coordinates; 3: Integrator::restart_state; 4: Material::describe_device; 5: PluginInfo::params; 6: Integrator::sync_to_host, first_unguarded_vertex

enum class PluginKind { Material, Integrator, Solver, Renderer };
const char* to_string(PluginKind k);

struct PluginInfo {
  PluginKind kind = PluginKind::Material;
  std::string name;
  std::string backend = "cpu";
  std::string version = "1.0";
  std::string description;
  std::string module_path;   ///< filled in by the loader
  /// The plugin's declared parameters (loom/param_spec.hpp), in static storage of the module;
  /// the cpu and device variants of a plugin share one. The registry merges the framework's
  /// keys of the section in front, attaches the result to the Params the factory reads and
  /// rejects reads of undeclared keys. nullptr: an undeclared plugin (keys are not checked
  /// against a spec, only by check_unused).
  const ParamSpec* params = nullptr;
};

using MaterialFactory = std::function<std::unique_ptr<Material>(const Params&, const Mesh&)>;
using IntegratorFactory = std::function<std::unique_ptr<Integrator>(const Params&)>;
using SolverFactory = std::function<std::unique_ptr<LinearSolver>(const Params&)>;
/// Renderer factories get the `render:` section of the scene (camera, light, fabric, ...)
/// and the scene file's folder for resolving relative paths.
using RendererFactory = std::function<std::unique_ptr<Renderer>(const Params&, const std::string& base_dir)>;

class Registry {
 public:
  void add_material(PluginInfo info, MaterialFactory f);
  void add_integrator(PluginInfo info, IntegratorFactory f);
  void add_solver(PluginInfo info, SolverFactory f);
  void add_renderer(PluginInfo info, RendererFactory f);

  bool has(PluginKind kind, const std::string& name, const std::string& backend = "cpu") const;
  /// Create; params.check_unused() is called after the factory returns.
  std::unique_ptr<Material> make_material(const std::string& name, const std::string& backend,
                                          const Params& params, const Mesh& mesh) const;
  std::unique_ptr<Integrator> make_integrator(const std::string& name, const std::string& backend,
                                              const Params& params) const;
  std::unique_ptr<LinearSolver> make_solver(const std::string& name, const std::string& backend,
                                            const Params& params) const;
  std::unique_ptr<Renderer> make_renderer(const std::string& name, const Params& params,
                                          const std::string& base_dir) const;
  std::vector<PluginInfo> list() const;
  /// The parameters a (kind, name, backend) plugin accepts: the framework's keys of its scene
  /// section, then the plugin's own; nullptr when the plugin declares none.
  const ParamSpec* params(PluginKind kind, const std::string& name, const std::string& backend = "cpu") const;
  /// Backends registered for (kind, name).
  std::vector<std::string> backends(PluginKind kind, const std::string& name) const;
  void set_current_module(const std::string& path) { current_module_ = path; }

 private:
  struct Entry {
    PluginInfo info;
    std::shared_ptr<const ParamSpec> spec;  ///< section keys + the plugin's (nullptr: none declared)
    /// The one factory of the entry's kind (info.kind).
    std::variant<MaterialFactory, IntegratorFactory, SolverFactory, RendererFactory> factory;
  };
  const Entry& find(PluginKind kind, const std::string& name, const std::string& backend) const;
  std::map<std::tuple<int, std::string, std::string>, Entry> entries_;
  std::string current_module_;
};

/// `loom plugins --params NAME`: for each kind with a plugin NAME, its kind, backends,
/// description and parameter table (ParamSpec::table); `markdown`: the table only, as in
/// docs/plugins/*.md. Throws InputError (with "did you mean") for an unknown name.
std::string params_table(const Registry& registry, const std::string& name, bool markdown);

class PluginLoader {
 public:
  explicit PluginLoader(Registry& registry, std::vector<std::string> search_path = default_search_path());
  ~PluginLoader();
  PluginLoader(const PluginLoader&) = delete;
  PluginLoader& operator=(const PluginLoader&) = delete;

  /// $LOOM_PLUGIN_PATH entries, then the build tree, then the install tree.
  static std::vector<std::string> default_search_path();
  const std::vector<std::string>& search_path() const { return search_path_; }

  /// Load the module providing (kind, name) unless it is already registered. Throws
  /// InputError naming what is available (with "did you mean") when no module is found,
  /// and a clear error when dlopen fails or the ABI version differs.
  void ensure(PluginKind kind, const std::string& name);
  /// Load the execution-backend module loom_backend_<backend>.so (for backends other than
  /// "cpu"), which registers the (kind, name, backend) plugins it implements. Throws
  /// InputError naming what is missing when the module is not on the path.
  void ensure_backend(const std::string& backend);
  /// Whether a module for (kind, name) exists on the path (or is already registered).
  bool available(PluginKind kind, const std::string& name) const;
  /// Names of all modules of a kind on the path.
  std::vector<std::string> names(PluginKind kind) const;
  /// Load every module on the path (for `loom plugins`); failures go to errors.
  void load_all(std::vector<std::string>& errors);
  /// Load one module file by path.
  void load_file(const std::string& path);
  Registry& registry() { return registry_; }

 private:
  std::string find_module(PluginKind kind, const std::string& name) const;
  Registry& registry_;
  std::vector<std::string> search_path_;
  std::vector<void*> handles_;
  std::vector<std::string> loaded_;
};

}  // namespace loom

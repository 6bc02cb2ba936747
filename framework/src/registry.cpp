#include "loom/registry.hpp"

#include <algorithm>

namespace loom {

const char* to_string(PluginKind k) {
  switch (k) {
    case PluginKind::Material: return "material";
    case PluginKind::Integrator: return "integrator";
    case PluginKind::Solver: return "solver";
    case PluginKind::Renderer: return "renderer";
  }
  return "?";
}

namespace {
auto key(PluginKind k, const std::string& name, const std::string& backend) {
  return std::make_tuple(static_cast<int>(k), name, backend);
}
}  // namespace

void Registry::add_material(PluginInfo info, MaterialFactory f) {
  info.kind = PluginKind::Material;
  if (info.module_path.empty()) info.module_path = current_module_;
  Entry e{info, std::move(f), {}, {}, {}};
  entries_[key(info.kind, info.name, info.backend)] = std::move(e);
}
void Registry::add_integrator(PluginInfo info, IntegratorFactory f) {
  info.kind = PluginKind::Integrator;
  if (info.module_path.empty()) info.module_path = current_module_;
  Entry e{info, {}, std::move(f), {}, {}};
  entries_[key(info.kind, info.name, info.backend)] = std::move(e);
}
void Registry::add_solver(PluginInfo info, SolverFactory f) {
  info.kind = PluginKind::Solver;
  if (info.module_path.empty()) info.module_path = current_module_;
  Entry e{info, {}, {}, std::move(f), {}};
  entries_[key(info.kind, info.name, info.backend)] = std::move(e);
}

void Registry::add_renderer(PluginInfo info, RendererFactory f) {
  info.kind = PluginKind::Renderer;
  if (info.module_path.empty()) info.module_path = current_module_;
  Entry e{info, {}, {}, {}, std::move(f)};
  entries_[key(info.kind, info.name, info.backend)] = std::move(e);
}

bool Registry::has(PluginKind kind, const std::string& name, const std::string& backend) const {
  return entries_.count(key(kind, name, backend)) > 0;
}

std::vector<std::string> Registry::backends(PluginKind kind, const std::string& name) const {
  std::vector<std::string> out;
  for (const auto& [k, e] : entries_)
    if (e.info.kind == kind && e.info.name == name) out.push_back(e.info.backend);
  return out;
}

const Registry::Entry& Registry::find(PluginKind kind, const std::string& name, const std::string& backend) const {
  auto it = entries_.find(key(kind, name, backend));
  if (it != entries_.end()) return it->second;
  const auto bs = backends(kind, name);
  if (!bs.empty()) {
    std::string list;
    for (const auto& b : bs) list += (list.empty() ? "" : ", ") + b;
    throw InputError(std::string(to_string(kind)) + " '" + name + "' has no '" + backend +
                     "' backend in this build (available: " + list + "). Fix: set backend to one of those.");
  }
  std::vector<std::string> names;
  for (const auto& [k, e] : entries_)
    if (e.info.kind == kind) names.push_back(e.info.name);
  std::string list;
  for (const auto& nm : names) list += (list.empty() ? "" : ", ") + nm;
  throw InputError(std::string("unknown ") + to_string(kind) + " '" + name + "'" +
                   (list.empty() ? "" : " (registered: " + list + ")"));
}

std::unique_ptr<Material> Registry::make_material(const std::string& name, const std::string& backend,
                                                  const Params& params, const Mesh& mesh) const {
  auto m = find(PluginKind::Material, name, backend).material(params, mesh);
  params.check_unused({"type"});
  return m;
}
std::unique_ptr<Integrator> Registry::make_integrator(const std::string& name, const std::string& backend,
                                                      const Params& params) const {
  auto m = find(PluginKind::Integrator, name, backend).integrator(params);
  params.check_unused({"type", "dt", "substeps", "frame_time"});
  return m;
}
std::unique_ptr<LinearSolver> Registry::make_solver(const std::string& name, const std::string& backend,
                                                    const Params& params) const {
  auto m = find(PluginKind::Solver, name, backend).solver(params);
  params.check_unused();
  return m;
}

std::unique_ptr<Renderer> Registry::make_renderer(const std::string& name, const Params& params,
                                                  const std::string& base_dir) const {
  auto r = find(PluginKind::Renderer, name, "cpu").renderer(params, base_dir);
  params.check_unused({"type"});
  return r;
}

std::vector<PluginInfo> Registry::list() const {
  std::vector<PluginInfo> out;
  for (const auto& [k, e] : entries_) out.push_back(e.info);
  return out;
}

}  // namespace loom

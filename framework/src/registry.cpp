#include "loom/registry.hpp"
#include "loom/section_specs.hpp"

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

/// The framework's keys of a plugin kind's scene section (none for solvers: a solver's block
/// holds only its own keys).
const ParamSpec* section_spec(PluginKind k) {
  switch (k) {
    case PluginKind::Material: return &material_section_spec();
    case PluginKind::Integrator: return &integrator_section_spec();
    case PluginKind::Renderer: return &render_section_spec();
    case PluginKind::Solver: return nullptr;
  }
  return nullptr;
}

std::shared_ptr<const ParamSpec> effective_spec(const PluginInfo& info) {
  if (!info.params) return nullptr;
  auto s = std::make_shared<ParamSpec>(info.name, info.params->summary());
  if (const ParamSpec* sec = section_spec(info.kind)) s->append(*sec);
  s->append(*info.params);
  return s;
}

std::vector<std::string> section_keys(PluginKind k) {
  const ParamSpec* sec = section_spec(k);
  return sec ? sec->keys() : std::vector<std::string>{};
}

/// Files a plugin of `kind` under its (kind, name, backend), replacing one filed before under
/// the same key; its module is the one being loaded unless it names its own.
template <class Entries, class Factory>
void add_entry(Entries& entries, PluginKind kind, PluginInfo info, const std::string& module, Factory f) {
  info.kind = kind;
  if (info.module_path.empty()) info.module_path = module;
  typename Entries::mapped_type e{info, effective_spec(info), std::move(f)};
  entries[key(info.kind, info.name, info.backend)] = std::move(e);
}

/// The Params a factory reads: with the plugin's spec attached when it declares one, and with
/// none when it does not (not the framework section's spec the scene builder read through).
Params view(const Params& p, const std::shared_ptr<const ParamSpec>& spec) { return p.with_spec(spec.get()); }
}  // namespace

void Registry::add_material(PluginInfo info, MaterialFactory f) {
  add_entry(entries_, PluginKind::Material, std::move(info), current_module_, std::move(f));
}
void Registry::add_integrator(PluginInfo info, IntegratorFactory f) {
  add_entry(entries_, PluginKind::Integrator, std::move(info), current_module_, std::move(f));
}
void Registry::add_solver(PluginInfo info, SolverFactory f) {
  add_entry(entries_, PluginKind::Solver, std::move(info), current_module_, std::move(f));
}

void Registry::add_renderer(PluginInfo info, RendererFactory f) {
  add_entry(entries_, PluginKind::Renderer, std::move(info), current_module_, std::move(f));
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
  const Entry& e = find(PluginKind::Material, name, backend);
  const Params p = view(params, e.spec);
  auto m = std::get<MaterialFactory>(e.factory)(p, mesh);
  p.check_unused(section_keys(PluginKind::Material));
  return m;
}
std::unique_ptr<Integrator> Registry::make_integrator(const std::string& name, const std::string& backend,
                                                      const Params& params) const {
  const Entry& e = find(PluginKind::Integrator, name, backend);
  const Params p = view(params, e.spec);
  auto m = std::get<IntegratorFactory>(e.factory)(p);
  p.check_unused(section_keys(PluginKind::Integrator));
  return m;
}
std::unique_ptr<LinearSolver> Registry::make_solver(const std::string& name, const std::string& backend,
                                                    const Params& params) const {
  const Entry& e = find(PluginKind::Solver, name, backend);
  const Params p = view(params, e.spec);
  auto m = std::get<SolverFactory>(e.factory)(p);
  p.check_unused();
  return m;
}

std::unique_ptr<Renderer> Registry::make_renderer(const std::string& name, const Params& params,
                                                  const std::string& base_dir) const {
  const Entry& e = find(PluginKind::Renderer, name, "cpu");
  const Params p = view(params, e.spec);
  auto r = std::get<RendererFactory>(e.factory)(p, base_dir);
  p.check_unused(section_keys(PluginKind::Renderer));
  return r;
}

const ParamSpec* Registry::params(PluginKind kind, const std::string& name, const std::string& backend) const {
  return find(kind, name, backend).spec.get();
}

std::vector<PluginInfo> Registry::list() const {
  std::vector<PluginInfo> out;
  for (const auto& [k, e] : entries_) out.push_back(e.info);
  return out;
}

std::string params_table(const Registry& registry, const std::string& name, bool markdown) {
  std::string out;
  std::vector<std::string> names;
  for (PluginKind kind : {PluginKind::Material, PluginKind::Integrator, PluginKind::Solver, PluginKind::Renderer}) {
    std::vector<std::string> bs = registry.backends(kind, name);
    if (bs.empty()) continue;
    // One spec serves every backend of a plugin: show the cpu variant's when there is one.
    const std::string backend = std::find(bs.begin(), bs.end(), "cpu") != bs.end() ? "cpu" : bs.front();
    const ParamSpec* spec = registry.params(kind, name, backend);
    std::string info_text;
    for (const auto& i : registry.list())
      if (i.kind == kind && i.name == name && i.backend == backend) info_text = i.description;
    if (!markdown) {
      std::string list;
      for (const auto& b : bs) list += (list.empty() ? "" : ", ") + b;
      out += name + " (" + to_string(kind) + "; backends " + list + "): " + info_text + "\n\n";
    }
    if (spec) out += spec->table(markdown);
    else out += "(this plugin declares no parameter spec)\n";
    if (!markdown) out += "\n";
  }
  if (!out.empty()) return out;
  // The framework's own sections (loom/section_specs.hpp) when no plugin has the name.
  if (const ParamSpec* sec = framework_section_spec(name)) {
    if (!markdown) out += name + " (framework section): " + sec->summary() + "\n\n";
    out += sec->table(markdown);
    if (!markdown) out += "\n";
    return out;
  }
  for (const auto& i : registry.list()) names.push_back(i.name);
  for (const auto& [n, spec] : framework_section_specs()) names.push_back(n);
  std::sort(names.begin(), names.end());
  names.erase(std::unique(names.begin(), names.end()), names.end());
  const std::string hint = closest_match(name, names);
  std::string list;
  for (const auto& n : names) list += (list.empty() ? "" : ", ") + n;
  throw InputError("no plugin named '" + name + "'" + (hint.empty() ? "" : " (did you mean '" + hint + "'?)") +
                   ". Plugins and framework sections: " + list + ".");
}

}  // namespace loom

// The declarative parameter specs (loom/param_spec.hpp): reading through a spec, validation,
// and, over every plugin module of the build, that the keys a plugin reads are the keys its
// spec declares and that docs/ shows the table the spec generates.
#include <gtest/gtest.h>

#include <cmath>
#include <filesystem>
#include <fstream>
#include <functional>
#include <iostream>
#include <limits>
#include <map>
#include <regex>
#include <set>
#include <sstream>
#include <stdexcept>

#include "loom/mesh.hpp"
#include "loom/param_fields.hpp"
#include "loom/param_spec.hpp"
#include "loom/registry.hpp"
#include "loom/section_specs.hpp"
#include "loom/simulation.hpp"
#include "common/input_error.hpp"
#include "loom/study.hpp"

namespace fs = std::filesystem;
using loom::InputError;
using loom::ParamRange;
using loom::ParamReader;
using loom::Params;
using loom::ParamSpec;

namespace {

using loom_test::error_of;

ParamSpec example_spec() {
  ParamSpec s("example");
  s.number("tolerance", 1e-6).range(ParamRange::closed(1e-16, 0.5)).help("relative residual");
  s.integer("max_iterations", 100).range(ParamRange::at_least(1)).help("iterations");
  s.number("stiffness", 2000).range(ParamRange::positive()).units("N/m").help("spring constant");
  s.flag("warm_start", true).help("warm start");
  s.choice("preconditioner", "jacobi", {"none", "jacobi", "block_jacobi"}).help("preconditioner");
  s.vec3("up", {0, 1, 0}).help("up direction");
  ParamSpec sub("rayleigh");
  sub.number("alpha", 0).range(ParamRange::nonnegative()).units("1/s").help("mass damping");
  s.map("rayleigh", std::move(sub)).help("Rayleigh damping");
  s.choice("precision", "double", {"double", "float"}).backends({"cuda"}).help("device precision");
  return s;
}

}  // namespace

// ---- the mechanism ----

TEST(ParamSpec, DefaultsComeFromTheSpec) {
  const ParamSpec s = example_spec();
  const Params p = Params::from_string("{}", "scene.yaml");
  const ParamReader r(p, s);
  EXPECT_EQ(r.number("tolerance"), 1e-6);
  EXPECT_EQ(r.integer("max_iterations"), 100);
  EXPECT_TRUE(r.flag("warm_start"));
  EXPECT_EQ(r.text("preconditioner"), "jacobi");
  EXPECT_EQ(r.vec3("up")[1], 1.0);
  EXPECT_EQ(r.section("rayleigh").number("alpha"), 0.0);
}

TEST(ParamSpec, ReadsGivenValues) {
  const ParamSpec s = example_spec();
  const Params p = Params::from_string(
      "tolerance: 0.001\nmax_iterations: 7\nwarm_start: false\npreconditioner: none\nup: [0, 0, 1]\n"
      "rayleigh: {alpha: 0.5}\n",
      "scene.yaml");
  const ParamReader r(p, s);
  EXPECT_EQ(r.number("tolerance"), 0.001);
  EXPECT_EQ(r.integer("max_iterations"), 7);
  EXPECT_FALSE(r.flag("warm_start"));
  EXPECT_EQ(r.text("preconditioner"), "none");
  EXPECT_EQ(r.vec3("up")[2], 1.0);
  EXPECT_EQ(r.section("rayleigh").number("alpha"), 0.5);
  EXPECT_NO_THROW(p.check_unused());
}

TEST(ParamSpec, RangeErrorsNameFileLineKeyAndRange) {
  const ParamSpec s = example_spec();
  const Params p = Params::from_string("tolerance: 0.7\nmax_iterations: 0\nstiffness: -1\n", "scene.yaml");
  const ParamReader r(p, s);
  std::string e = error_of([&] { r.number("tolerance"); });
  EXPECT_NE(e.find("scene.yaml:1"), std::string::npos) << e;
  EXPECT_NE(e.find("tolerance"), std::string::npos) << e;
  EXPECT_NE(e.find("[1e-16, 0.5]"), std::string::npos) << e;
  e = error_of([&] { r.integer("max_iterations"); });
  EXPECT_NE(e.find("scene.yaml:2"), std::string::npos) << e;
  EXPECT_NE(e.find("an integer >= 1"), std::string::npos) << e;
  e = error_of([&] { r.number("stiffness"); });
  EXPECT_NE(e.find("scene.yaml:3"), std::string::npos) << e;
  EXPECT_NE(e.find("> 0"), std::string::npos) << e;
}

TEST(ParamSpec, RangeEnds) {
  EXPECT_TRUE(ParamRange::positive().contains(1e-300));
  EXPECT_FALSE(ParamRange::positive().contains(0.0));
  EXPECT_TRUE(ParamRange::nonnegative().contains(0.0));
  EXPECT_FALSE(ParamRange::nonnegative().contains(-1e-300));
  EXPECT_TRUE(ParamRange::closed(1, 20).contains(20));
  EXPECT_FALSE(ParamRange::closed(1, 20).contains(20.5));
  EXPECT_FALSE(ParamRange::at_least(1).contains(std::numeric_limits<double>::quiet_NaN()));
  EXPECT_FALSE(ParamRange::at_least(1).contains(std::numeric_limits<double>::infinity()));
  const ParamRange half_open{0.0, 1.0, false, true};
  EXPECT_EQ(half_open.text(), "[0, 1)");
  EXPECT_EQ(ParamRange::positive().text(), "> 0");
  EXPECT_EQ(ParamRange().text(), "");
}

TEST(ParamSpec, EnumSuggestsTheClosestChoice) {
  const ParamSpec s = example_spec();
  const Params p = Params::from_string("preconditioner: jacobbi\n", "scene.yaml");
  const std::string e = error_of([&] { ParamReader(p, s).text("preconditioner"); });
  EXPECT_NE(e.find("did you mean 'jacobi'"), std::string::npos) << e;
  EXPECT_NE(e.find("none, jacobi, block_jacobi"), std::string::npos) << e;
}

TEST(ParamSpec, UnknownKeySuggestsADeclaredKeyThatWasNotRead) {
  const ParamSpec s = example_spec();
  // Only tolerance is read; the typo is closest to a declared key that was not read.
  const Params p = Params::from_string("tolerance: 0.1\nwarm_strat: true\n", "scene.yaml").with_spec(&s);
  ParamReader(p, s).number("tolerance");
  const std::string e = error_of([&] { p.check_unused(); });
  EXPECT_NE(e.find("scene.yaml:2"), std::string::npos) << e;
  EXPECT_NE(e.find("did you mean 'warm_start'"), std::string::npos) << e;
}

// check_params reads a whole block as a plugin's factory would, without the plugin (a fallback
// solver's block): every error kind of the reader, with the key's own line, and unknown keys.
TEST(ParamSpec, CheckParamsReportsWhatTheReaderWould) {
  const ParamSpec s = example_spec();
  auto check = [&](const std::string& yaml) {
    const Params p = Params::from_string(yaml, "scene.yaml").with_spec(&s);
    return error_of([&] { loom::check_params(p, s); });
  };
  EXPECT_EQ(check("tolerance: 0.1\nmax_iterations: 5\nwarm_start: false\npreconditioner: none\nup: [1, 0, 0]\n"
                  "rayleigh: {alpha: 0.5}\nprecision: float\n"),
            "");
  EXPECT_EQ(check("{}"), "");
  std::string e = check("warm_start: true\ntolerance: 0.7\n");
  EXPECT_NE(e.find("scene.yaml:2"), std::string::npos) << e;
  EXPECT_NE(e.find("[1e-16, 0.5]"), std::string::npos) << e;
  e = check("max_iterations: 2.5\n");
  EXPECT_NE(e.find("integer"), std::string::npos) << e;
  e = check("preconditioner: jacobbi\n");
  EXPECT_NE(e.find("did you mean 'jacobi'"), std::string::npos) << e;
  e = check("up: [0, 1]\n");
  EXPECT_NE(e.find("3 numbers"), std::string::npos) << e;
  e = check("warm_start: maybe\n");
  EXPECT_NE(e.find("scene.yaml:1"), std::string::npos) << e;
  e = check("tolerance: 0.1\nrayleigh: {alpha: -1}\n");  // a nested map's keys, with their line
  EXPECT_NE(e.find("scene.yaml:2"), std::string::npos) << e;
  EXPECT_NE(e.find(">= 0"), std::string::npos) << e;
  e = check("rayleigh: {alhpa: 1}\n");
  EXPECT_NE(e.find("did you mean 'alpha'"), std::string::npos) << e;
  e = check("tolerance: 0.1\ntolerence: 0.1\n");  // unknown keys, suggested from the declared ones
  EXPECT_NE(e.find("scene.yaml:2"), std::string::npos) << e;
  EXPECT_NE(e.find("unknown key 'tolerence'"), std::string::npos) << e;
  e = check("5\n");
  EXPECT_NE(e.find("expected a mapping"), std::string::npos) << e;
  ParamSpec req("needs_one");
  req.number("width", 0).required().help("required");
  const Params empty = Params::from_string("{other: 1}\n", "scene.yaml").with_spec(&req);
  e = error_of([&] { loom::check_params(empty, req); });
  EXPECT_NE(e.find("missing required key 'width'"), std::string::npos) << e;
}

TEST(ParamSpec, KeyOfAnotherBackendIsNamedAsSuch) {
  const ParamSpec s = example_spec();
  const Params p = Params::from_string("precision: float\n", "scene.yaml").with_spec(&s);
  const std::string e = error_of([&] { p.check_unused(); });
  EXPECT_NE(e.find("honoured only by the cuda backend"), std::string::npos) << e;
}

TEST(ParamSpec, ReadingAnUndeclaredKeyIsABug) {
  const ParamSpec s = example_spec();
  const Params p = Params::from_string("{}", "scene.yaml");
  const ParamReader r(p, s);
  EXPECT_THROW(r.number("tolerence"), std::logic_error);
  EXPECT_THROW(r.flag("tolerance"), std::logic_error);  // declared as another type
  // Raw reads through a Params with a spec attached are checked too, nested ones included.
  EXPECT_THROW(r.params().get("not_declared", 1.0), std::logic_error);
  EXPECT_THROW(r.params().mark_used("not_declared"), std::logic_error);
  EXPECT_THROW(r.node("rayleigh").get("beta", 0.0), std::logic_error);
  EXPECT_NO_THROW(r.node("rayleigh").get("alpha", 0.0));
}

TEST(ParamSpec, DuplicateDeclarationIsABug) {
  ParamSpec s("dup");
  s.number("a", 1);
  EXPECT_THROW(s.number("a", 2), std::logic_error);
  EXPECT_THROW(s.choice("c", "x", {"y", "z"}), std::logic_error);  // default not among the choices
}

TEST(ParamSpec, TableListsEveryKeyWithDefaultRangeUnitsAndHelp) {
  const std::string t = example_spec().table();
  for (const char* k : {"tolerance", "max_iterations", "stiffness", "warm_start", "preconditioner", "up",
                        "rayleigh.alpha", "precision", "N/m", "[1e-16, 0.5]", "none | jacobi | block_jacobi",
                        "spring constant", "cuda", "[0, 1, 0]"})
    EXPECT_NE(t.find(k), std::string::npos) << k << "\n" << t;
  const std::string md = example_spec().table(true);
  EXPECT_EQ(md.rfind("| key | type | default | range | units | backends | help |\n", 0), 0u) << md;
  EXPECT_NE(md.find("| `rayleigh.alpha` | number | `0` | >= 0 | 1/s | all | mass damping |"), std::string::npos) << md;
}

// ---- every plugin of the build ----

namespace {

struct Loaded {
  loom::Registry reg;
  std::unique_ptr<loom::PluginLoader> loader;
  std::vector<std::string> errors;
  Loaded() {
    loader = std::make_unique<loom::PluginLoader>(reg, std::vector<std::string>{LOOM_PLUGIN_DIR});
    loader->load_all(errors);
  }
};

Loaded& plugins() {
  static Loaded l;
  return l;
}

std::string build_scene(const std::string& yaml);  // below

// A YAML value for a declared key: its default, or a value inside its range.
std::string value_for(const loom::ParamDecl& d) {
  using loom::ParamType;
  std::ostringstream os;
  os.precision(17);
  auto number = [&]() {
    if (d.has_default) return d.default_number;
    if (std::isfinite(d.range.min)) return d.range.min + (d.range.min_open ? 1.0 : 0.0);
    return 1.0;
  };
  switch (d.type) {
    case ParamType::Number: os << number(); break;
    case ParamType::Int: os << static_cast<long long>(number()); break;
    case ParamType::Bool: os << (d.default_bool ? "true" : "false"); break;
    case ParamType::String:
    case ParamType::Enum: os << "'" << d.default_string << "'"; break;
    case ParamType::Vec3: os << "[" << d.default_vec[0] << ", " << d.default_vec[1] << ", " << d.default_vec[2] << "]"; break;
    case ParamType::List: os << "[]"; break;
    case ParamType::Map:
      if (d.number_or_map) os << number();
      else os << "{}";
      break;
  }
  return os.str();
}

// Keys that another key must enable (the plugin says so when it is missing).
const std::map<std::string, std::string> kCompanions = {
    {"eigen_pcg.sa_amg", "preconditioner: sa_amg\n"},
    {"filtered_pcg.sa_amg", "preconditioner: sa_amg\n"},
};

std::string required_keys(const loom::PluginInfo& info) {
  if (info.name == "gnatv") return "material_file: " + std::string(LOOM_SOURCE_DIR) + "/materials/wool.yaml\n";
  return "";
}

// Build the plugin from `yaml` through the registry (which attaches its spec and calls
// check_unused). Returns "" or the error; a std::logic_error (an undeclared key read) fails.
std::string construct(const loom::PluginInfo& info, const std::string& yaml) {
  const loom::Registry& reg = plugins().reg;
  const Params p = Params::from_string(yaml, "scene.yaml");
  static const loom::Mesh mesh = loom::make_grid(3, 3, 1.0, 1.0);
  try {
    switch (info.kind) {
      case loom::PluginKind::Material: reg.make_material(info.name, info.backend, p, mesh); break;
      case loom::PluginKind::Integrator: reg.make_integrator(info.name, info.backend, p); break;
      case loom::PluginKind::Solver: reg.make_solver(info.name, info.backend, p); break;
      case loom::PluginKind::Renderer: reg.make_renderer(info.name, p, LOOM_SOURCE_DIR); break;
    }
  } catch (const InputError& e) {
    return e.what();
  } catch (const std::logic_error& e) {
    ADD_FAILURE() << info.name << " with {" << yaml << "}: " << e.what();
  }
  return "";
}

}  // namespace

TEST(PluginSpecs, EveryPluginOfTheBuildDeclaresItsKeys) {
  auto& l = plugins();
  ASSERT_FALSE(l.reg.list().empty());
  for (const auto& info : l.reg.list()) {
    EXPECT_NE(info.params, nullptr) << info.name << " (" << info.backend << ") declares no parameter spec";
    EXPECT_NE(l.reg.params(info.kind, info.name, info.backend), nullptr);
  }
}

// Every declared key is read (given alone at its default, or at a value in its range, the plugin
// accepts it: a declared key the plugin ignored would be an unknown key), and no read key is
// undeclared (the registry's spec would throw std::logic_error in construct()).
TEST(PluginSpecs, EveryDeclaredKeyIsReadAndNoOtherKey) {
  auto& l = plugins();
  for (const auto& info : l.reg.list()) {
    if (!info.params) continue;
    const std::string base = required_keys(info);
    EXPECT_EQ(construct(info, base.empty() ? "{}" : base), "") << info.name << " with its defaults";
    for (const auto& d : info.params->decls()) {
      if (base.rfind(d.name + ":", 0) == 0) continue;  // given in base already
      const std::string id = info.name + "." + d.name;
      const std::string comp = kCompanions.count(id) ? kCompanions.at(id) : "";
      const std::string yaml = base + comp + d.name + ": " + value_for(d) + "\n";
      const std::string err = construct(info, yaml);
      if (d.honoured_by(info.backend)) {
        EXPECT_EQ(err, "") << id << ": " << yaml;
      } else {
        EXPECT_NE(err.find("honoured only by"), std::string::npos) << id << ": " << err;
      }
      if (d.fields && !d.number_or_map && d.honoured_by(info.backend))
        for (const auto& f : d.fields->decls()) {
          const std::string y = base + comp + d.name + ": {" + f.name + ": " + value_for(f) + "}\n";
          EXPECT_EQ(construct(info, y), "") << id << "." << f.name << ": " << y;
        }
    }
    // and a key no spec declares is refused with a suggestion
    const std::string err = construct(info, base + "definitely_not_a_key: 1\n");
    EXPECT_NE(err.find("unknown key 'definitely_not_a_key'"), std::string::npos) << info.name << ": " << err;
  }
}

// check_params (what `solver:` applies to the blocks of the solvers a run does not use) accepts
// every declared key that the plugin itself accepts, and refuses a key no spec declares: it is
// never stricter than the plugin, and it catches what check_unused would.
TEST(PluginSpecs, CheckParamsAcceptsWhatThePluginAccepts) {
  auto& l = plugins();
  int checked = 0;
  for (const auto& info : l.reg.list()) {
    const ParamSpec* spec = l.reg.params(info.kind, info.name, info.backend);
    if (!spec) continue;
    auto check = [&](const std::string& yaml) {
      const Params p = Params::from_string(yaml, "scene.yaml").with_spec(spec);
      return error_of([&] { loom::check_params(p, *spec); });
    };
    const std::string base = required_keys(info);
    EXPECT_EQ(check(base.empty() ? "{}" : base), "") << info.name;
    for (const auto& d : info.params->decls()) {
      if (base.rfind(d.name + ":", 0) == 0) continue;
      const std::string id = info.name + "." + d.name;
      const std::string comp = kCompanions.count(id) ? kCompanions.at(id) : "";
      const std::string yaml = base + comp + d.name + ": " + value_for(d) + "\n";
      if (construct(info, yaml).empty()) {
        EXPECT_EQ(check(yaml), "") << id << ": " << yaml;
        ++checked;
      }
    }
    const std::string err = check(base + "definitely_not_a_key: 1\n");
    EXPECT_NE(err.find("unknown key 'definitely_not_a_key'"), std::string::npos) << info.name << ": " << err;
  }
  EXPECT_GT(checked, 20);
}

TEST(PluginSpecs, TypoGetsDidYouMean) {
  auto& l = plugins();
  if (!l.reg.has(loom::PluginKind::Solver, "eigen_pcg")) GTEST_SKIP() << "eigen_pcg not in this build";
  loom::PluginInfo info;
  for (const auto& i : l.reg.list())
    if (i.name == "eigen_pcg") info = i;
  const std::string err = construct(info, "tolerence: 1e-6\n");
  EXPECT_NE(err.find("did you mean 'tolerance'"), std::string::npos) << err;
}

// docs/plugins/*.md and docs/RENDERING.md carry each plugin's table between
//   <!-- loom-params: NAME -->  and  <!-- /loom-params -->
// generated by `loom plugins --params NAME --markdown`.
TEST(PluginSpecs, DocsShowTheGeneratedTables) {
  auto& l = plugins();
  std::map<std::string, std::string> blocks;  // name -> table in the docs
  std::map<std::string, std::string> where;
  const std::regex open(R"(<!-- loom-params: ([a-z0-9_]+) -->)");
  std::vector<fs::path> files;
  for (const auto& e : fs::directory_iterator(fs::path(LOOM_SOURCE_DIR) / "docs" / "plugins"))
    if (e.path().extension() == ".md") files.push_back(e.path());
  files.push_back(fs::path(LOOM_SOURCE_DIR) / "docs" / "RENDERING.md");
  files.push_back(fs::path(LOOM_SOURCE_DIR) / "docs" / "SCENE_KEYS.md");  // the framework's own sections
  for (const auto& f : files) {
    std::ifstream in(f);
    std::stringstream ss;
    ss << in.rdbuf();
    const std::string text = ss.str();
    for (auto it = std::sregex_iterator(text.begin(), text.end(), open); it != std::sregex_iterator(); ++it) {
      const std::string name = (*it)[1];
      const std::size_t begin = it->position(0) + it->length(0) + 1;  // after the marker's newline
      const std::size_t end = text.find("<!-- /loom-params -->", begin);
      ASSERT_NE(end, std::string::npos) << f << ": the block of " << name << " is not closed";
      EXPECT_EQ(blocks.count(name), 0u) << name << " has two blocks (" << where[name] << ", " << f.string() << ")";
      blocks[name] = text.substr(begin, end - begin);
      where[name] = f.filename().string();
    }
  }
  std::set<std::string> names;
  for (const auto& info : l.reg.list()) names.insert(info.name);
  for (const auto& name : names) {
    ASSERT_EQ(blocks.count(name), 1u) << "no <!-- loom-params: " << name << " --> block in docs/plugins/*.md. Fix: add "
                                      << "one with the output of `loom plugins --params " << name << " --markdown`";
    EXPECT_EQ(blocks[name], loom::params_table(l.reg, name, true))
        << where[name] << ": the table of " << name << " differs from the spec. Fix: replace it with the output of "
        << "`loom plugins --params " << name << " --markdown`";
  }
  // The framework's own sections (loom/section_specs.hpp), in docs/SCENE_KEYS.md.
  for (const auto& [name, spec] : loom::framework_section_specs()) {
    names.insert(name);
    ASSERT_EQ(blocks.count(name), 1u) << "no <!-- loom-params: " << name << " --> block for the framework section";
    EXPECT_EQ(blocks[name], loom::params_table(l.reg, name, true))
        << where[name] << ": the table of section " << name << " differs from its spec. Fix: run "
        << "scripts/update_param_docs.py";
  }
  // Blocks of plugins this build lacks (e.g. cusparse_pcg without nvcc) are not checked here.
  for (const auto& [name, text] : blocks)
    if (!names.count(name)) std::cout << "note: " << name << " (" << where[name] << ") is not in this build\n";
}

// The framework's own sections (loom/section_specs.hpp): every declared key of output, guard,
// mesh (grid and obj forms) and self_collision, given alone at its default or a value in its
// range, is accepted by the scene builder, and an undeclared key is refused; so the printed spec
// and the stage that reads the section (framework/src/scene_build.cpp) agree.
TEST(SectionSpecs, EveryDeclaredKeyIsReadAndNoOtherKey) {
  auto& l = plugins();
  if (!l.reg.has(loom::PluginKind::Material, "mass_spring") || !l.reg.has(loom::PluginKind::Integrator, "symplectic_euler"))
    GTEST_SKIP() << "needs the mass_spring and symplectic_euler plugins";
  const fs::path obj = fs::temp_directory_path() / "loom_section_specs_square.obj";
  std::ofstream(obj) << "v 0 0 0\nv 1 0 0\nv 1 1 0\nv 0 1 0\nf 1 2 3\nf 1 3 4\n";
  loom::Simulation::set_notes(false);
  auto build = build_scene;
  const std::string rest = "material: {type: mass_spring}\nintegrator: {type: symplectic_euler, dt: 0.001}\n";
  const std::string grid = "mesh: {grid: {nx: 4, ny: 4}}\n";
  struct Section {
    const loom::ParamSpec* spec;
    std::function<std::string(const std::string&)> scene;  // the scene with "key: value" in the section
  };
  const std::vector<Section> sections = {
      {&loom::output_section_spec(), [&](const std::string& kv) { return grid + rest + "output: {" + kv + "}\n"; }},
      {&loom::guard_section_spec(), [&](const std::string& kv) { return grid + rest + "guard: {" + kv + "}\n"; }},
      {&loom::self_collision_section_spec(),
       [&](const std::string& kv) {
         // thickness is required and has no default: 0.01 m, below the 4 x 4 grid's spacing
         return grid + rest + "self_collision: {" + (kv.rfind("thickness:", 0) == 0 ? "thickness: 0.01" : "thickness: 0.01, " + kv) + "}\n";
       }},
      {loom::mesh_section_spec().decls()[0].fields.get(),  // mesh.grid
       [&](const std::string& kv) {
         std::string keys = kv;
         if (kv.rfind("nx:", 0) != 0) keys = "nx: 4, " + keys;
         if (kv.rfind("ny:", 0) != 0) keys = "ny: 4, " + keys;
         return "mesh: {grid: {" + keys + "}}\n" + rest;
       }},
      {&loom::mesh_section_spec(),
       [&](const std::string& kv) {
         if (kv.rfind("grid:", 0) == 0) return grid + rest;
         if (kv.rfind("obj:", 0) == 0) return "mesh: {obj: " + obj.string() + "}\n" + rest;
         return "mesh: {obj: " + obj.string() + ", " + kv + "}\n" + rest;
       }},
  };
  for (const Section& sec : sections) {
    ASSERT_NE(sec.spec, nullptr);
    for (const auto& d : sec.spec->decls()) {
      const std::string kv = d.name + ": " + value_for(d);
      EXPECT_EQ(build(sec.scene(kv)), "") << sec.spec->name() << "." << d.name << ":\n" << sec.scene(kv);
    }
    const std::string err = build(sec.scene("definitely_not_a_key: 1"));
    EXPECT_NE(err.find("definitely_not_a_key"), std::string::npos) << sec.spec->name() << ": " << err;
  }
}

// ---- the framework sections whose entries depend on each other (lists, types, motions) ----

namespace {

// Builds a scene; "" or the InputError. A std::logic_error (a stage read a key that its
// section's spec does not declare) fails the test.
std::string build_scene(const std::string& yaml) {
  try {
    loom::Simulation::from_string(yaml, "scene.yaml", LOOM_SOURCE_DIR, {}, *plugins().loader);
  } catch (const InputError& e) {
    return e.what();
  } catch (const std::logic_error& e) {
    ADD_FAILURE() << "undeclared read: " << e.what() << "\n" << yaml;
  }
  return "";
}

// For every key of `spec` (nested keys as parent.key), the cases that give it: each case is
// built and must be accepted. A declared key without a case fails, so a new key needs one.
void check_cases(const ParamSpec& spec, const std::map<std::string, std::vector<std::string>>& cases,
                 const std::function<std::string(const std::string&)>& scene, const std::string& bad_case) {
  std::function<void(const ParamSpec&, const std::string&)> each = [&](const ParamSpec& s, const std::string& prefix) {
    for (const auto& d : s.decls()) {
      const std::string key = prefix + d.name;
      const auto it = cases.find(key);
      if (it == cases.end()) {
        ADD_FAILURE() << spec.name() << ": the declared key " << key << " has no case in this test";
        continue;
      }
      for (const auto& c : it->second) EXPECT_EQ(build_scene(scene(c)), "") << spec.name() << "." << key << ":\n" << scene(c);
      if (d.fields) each(*d.fields, key + ".");
    }
  };
  each(spec, "");
  auto declared = [&](const std::string& key) -> const loom::ParamDecl* {
    const ParamSpec* s = &spec;
    std::string rest = key;
    while (s) {
      const auto dot = rest.find('.');
      const loom::ParamDecl* d = s->find(rest.substr(0, dot));
      if (!d || dot == std::string::npos) return d;
      s = d->fields.get();
      rest = rest.substr(dot + 1);
    }
    return nullptr;
  };
  for (const auto& [key, unused] : cases)  // a case for a key the spec does not declare would test nothing
    EXPECT_NE(declared(key), nullptr) << spec.name() << ": the case " << key << " names no declared key";
  const std::string err = build_scene(scene(bad_case));
  EXPECT_NE(err.find("unknown key 'definitely_not_a_key'"), std::string::npos) << spec.name() << ": " << err;
}

bool has_plugins(std::initializer_list<std::pair<loom::PluginKind, const char*>> needed) {
  for (const auto& [k, n] : needed)
    if (!plugins().reg.has(k, n)) return false;
  return true;
}

const std::string kRest = "material: {type: mass_spring}\nintegrator: {type: symplectic_euler, dt: 0.001}\n";
const std::string kGrid = "mesh: {grid: {nx: 4, ny: 4}}\n";

}  // namespace

TEST(SectionSpecs, ListEntriesAndMotionsReadOnlyTheirDeclaredKeys) {
  using loom::PluginKind;
  if (!has_plugins({{PluginKind::Material, "mass_spring"}, {PluginKind::Integrator, "symplectic_euler"}}))
    GTEST_SKIP() << "needs the mass_spring and symplectic_euler plugins";
  loom::Simulation::set_notes(false);
  const std::string ico = std::string(LOOM_SOURCE_DIR) + "/scenes/meshes/icosphere1.obj";
  const std::string plane = "type: plane, point: [0, -1, 0]";
  const std::string keyframes =
      "type: keyframes, axis: [0, 0, 1], interpolation: smooth, keys: [{t: 0}, {t: 1, translate: [0, 0.1, 0], angle: 0.5}]";
  const std::map<std::string, std::vector<std::string>> motion = {
      {"motion", {"motion: {type: fixed}"}},
      {"motion.type", {"motion: {type: fixed}"}},
      {"motion.velocity", {"motion: {type: translate, velocity: [0, 0.1, 0]}"}},
      {"motion.axis", {"motion: {type: rotate, axis: [0, 0, 1], angular_velocity: 1}"}},
      {"motion.angular_velocity", {"motion: {type: rotate, angular_velocity: 1}"}},
      {"motion.interpolation", {"motion: {" + keyframes + "}"}},
      {"motion.keys", {"motion: {" + keyframes + "}"}},
  };
  // colliders
  std::map<std::string, std::vector<std::string>> colliders = {
      {"type", {plane, "type: sphere, center: [0, 0, -5], radius: 0.5", "type: mesh, obj: " + ico}},
      {"name", {plane + ", name: floor"}},
      {"center", {"type: sphere, center: [0, 0, -5], radius: 0.5"}},
      {"radius", {"type: sphere, center: [0, 0, -5], radius: 0.5"}},
      {"point", {plane}},
      {"normal", {plane + ", normal: [0, 2, 0]"}},
      {"obj", {"type: mesh, obj: " + ico}},
      {"scale", {"type: mesh, obj: " + ico + ", scale: 0.5"}},
      {"offset", {"type: mesh, obj: " + ico + ", offset: [0, 0, -5]"}},
      {"pivot", {"type: mesh, obj: " + ico + ", pivot: [0, 0, 0]"}},
      {"thickness", {plane + ", thickness: 0.001"}},
      {"friction", {plane + ", friction: 0.3", plane + ", friction: {static: 0.5, kinetic: 0.3}"}},
      {"friction.static", {plane + ", friction: {static: 0.5}"}},
      {"friction.kinetic", {plane + ", friction: {static: 0.5, kinetic: 0.3}"}},
  };
  for (const auto& [k, v] : motion)
    for (const auto& c : v) colliders[k].push_back(plane + ", " + c);
  check_cases(loom::collider_entry_spec(), colliders,
              [&](const std::string& e) { return kGrid + kRest + "colliders: [{" + e + "}]\n"; },
              plane + ", definitely_not_a_key: 1");
  // pins (and the selection keys pins share with mass_scale)
  const std::string box = "box: {min: [-5, -5, -5], max: [5, 5, 5]}";
  std::map<std::string, std::vector<std::string>> pins = {
      {"name", {"group: top_edge, name: clamp"}},
      {"group", {"group: top_edge"}},
      {"vertices", {"vertices: [0, 3]"}},
      {"box", {box}},
      {"box.min", {box}},
      {"box.max", {box}},
      {"motion.center", {"vertices: [0, 3], motion: {type: rotate, angular_velocity: 1, center: [0, 0, 0]}"}},
  };
  for (const auto& [k, v] : motion)
    for (const auto& c : v) pins[k].push_back("group: top_edge, " + c);
  check_cases(loom::pin_entry_spec(), pins, [&](const std::string& e) { return kGrid + kRest + "pins: [{" + e + "}]\n"; },
              "group: top_edge, definitely_not_a_key: 1");
  // the keys of a keyframe
  check_cases(loom::motion_key_spec(), {{"t", {"t: 0"}}, {"translate", {"t: 0, translate: [0, 1, 0]"}}, {"angle", {"t: 0, angle: 1"}}},
              [&](const std::string& e) { return kGrid + kRest + "pins: [{group: top_edge, motion: {type: keyframes, keys: [{" + e + "}]}}]\n"; },
              "t: 0, definitely_not_a_key: 1");
  // mass_scale
  check_cases(loom::mass_scale_entry_spec(),
              {{"factor", {"group: corners, factor: 2"}}, {"group", {"group: corners"}}, {"vertices", {"vertices: [1]"}},
               {"box", {box}}, {"box.min", {box}}, {"box.max", {box}}},
              [&](const std::string& e) { return kGrid + kRest + "mass_scale: [{" + e + "}]\n"; },
              "vertices: [1], definitely_not_a_key: 1");
  // material.bending
  check_cases(loom::bending_section_spec(),
              {{"stiffness", {"stiffness: 1.0e-5"}},
               {"stiffness.weft", {"stiffness: {weft: 1.0e-5, warp: 1.0e-5}"}},
               {"stiffness.warp", {"stiffness: {weft: 1.0e-5, warp: 1.0e-5}"}},
               {"stiffness.bias", {"stiffness: {weft: 1.0e-5, warp: 1.0e-5, bias: 1.0e-5}"}},
               {"jacobian", {"stiffness: 1.0e-5, jacobian: exact"}},
               {"non_manifold", {"stiffness: 1.0e-5, non_manifold: skip"}},
               {"weft_angle", {"stiffness: 1.0e-5, weft_angle: 0.5"}}},
              [&](const std::string& e) {
                return kGrid + "material: {type: mass_spring, bending: {" + e + "}}\n" +
                       "integrator: {type: symplectic_euler, dt: 0.001}\n";
              },
              "stiffness: 1.0e-5, definitely_not_a_key: 1");
}

TEST(SectionSpecs, TopLevelAndSolverReadOnlyTheirDeclaredKeys) {
  using loom::PluginKind;
  if (!has_plugins({{PluginKind::Material, "mass_spring"}, {PluginKind::Integrator, "symplectic_euler"},
                    {PluginKind::Integrator, "baraff_witkin"}, {PluginKind::Solver, "eigen_ldlt"}}))
    GTEST_SKIP() << "needs mass_spring, symplectic_euler, baraff_witkin and eigen_ldlt";
  loom::Simulation::set_notes(false);
  const std::string implicit = kGrid + "material: {type: mass_spring}\nintegrator: {type: baraff_witkin, dt: 0.001}\n";
  // every top-level key (the scene's required sections are always there)
  check_cases(loom::scene_section_spec(),
              {{"mesh", {""}}, {"material", {""}}, {"integrator", {""}},
               {"solver", {"solver: {type: eigen_ldlt}"}},  // ignored by an explicit integrator
               {"frames", {"frames: 3"}}, {"gravity", {"gravity: [0, 0, -9.81]"}},
               {"pins", {"pins: [top_corners]"}}, {"mass_scale", {"mass_scale: [{group: corners, factor: 3}]"}},
               {"initial_scale", {"initial_scale: 0.9"}}, {"initial_velocity", {"initial_velocity: [0, 1, 0]"}},
               {"colliders", {"colliders: [{type: plane, point: [0, -1, 0]}]"}},
               {"self_collision", {"self_collision: {thickness: 0.01}"}}, {"output", {"output: {every: 2}"}},
               {"guard", {"guard: {max_strain: 5}"}}, {"backend", {"backend: cpu"}}, {"threads", {"threads: 1", "threads: auto"}},
               {"description", {"description: a test"}}, {"name", {"name: t"}}, {"render", {"render: {fps: 24}"}},
               {"kawabata", {"kawabata: {gauge: 0.05}"}}},
              [&](const std::string& kv) { return kGrid + kRest + kv + "\n"; }, "definitely_not_a_key: 1");
  // solver: type, as a name, a list, or a mapping with the chosen solver's block and other solvers' blocks
  check_cases(loom::solver_section_spec(),
              {{"type", {"{type: eigen_ldlt}", "{type: [not_a_solver_here, eigen_ldlt], not_a_solver_here: {x: 1}}",
                         "eigen_ldlt", "[eigen_ldlt]", "{type: eigen_ldlt, eigen_ldlt: {}}"}}},
              [&](const std::string& v) { return implicit + "solver: " + v + "\n"; },
              "{type: eigen_ldlt, definitely_not_a_key: 1}");
}

// The block of a solver that the run does not use (a fallback of the type list, or a block kept
// for --set solver.type=...) is checked against that solver's declared keys: a typo or a value
// out of range is an error at its own line, as if that solver ran. A block of a solver that is
// not in this build cannot be checked and stays allowed.
TEST(SectionSpecs, BlocksOfSolversNotChosenAreChecked) {
  using loom::PluginKind;
  if (!has_plugins({{PluginKind::Material, "mass_spring"}, {PluginKind::Integrator, "baraff_witkin"},
                    {PluginKind::Solver, "eigen_ldlt"}, {PluginKind::Solver, "filtered_pcg"}}))
    GTEST_SKIP() << "needs mass_spring, baraff_witkin, eigen_ldlt and filtered_pcg";
  loom::Simulation::set_notes(false);
  const std::string implicit = kGrid + "material: {type: mass_spring}\nintegrator: {type: baraff_witkin, dt: 0.001}\n";
  auto error = [&](const std::string& solver) { return build_scene(implicit + "solver:\n" + solver); };
  // valid fallback blocks build; the chosen solver is the first of the list
  EXPECT_EQ(error("  type: [eigen_ldlt, filtered_pcg]\n  filtered_pcg: {tolerance: 1.0e-6, preconditioner: sa_amg, "
                  "sa_amg: {smoothing_sweeps: 2}}\n"),
            "");
  EXPECT_EQ(error("  type: [not_a_solver_here, eigen_ldlt]\n  not_a_solver_here: {anything: 1}\n"), "");
  const std::string head = "  type: [eigen_ldlt, filtered_pcg]\n";
  const int line = static_cast<int>(std::count(implicit.begin(), implicit.end(), '\n')) + 3;  // the block's line
  const std::string at = "scene.yaml:" + std::to_string(line);
  std::string e = error(head + "  filtered_pcg: {tolerence: 1.0e-6}\n");
  EXPECT_NE(e.find(at), std::string::npos) << e;
  EXPECT_NE(e.find("did you mean 'tolerance'"), std::string::npos) << e;
  e = error(head + "  filtered_pcg: {tolerance: 5}\n");
  EXPECT_NE(e.find(at), std::string::npos) << e;
  EXPECT_NE(e.find("solver.filtered_pcg.tolerance"), std::string::npos) << e;
  EXPECT_NE(e.find("[1e-16, 0.5]"), std::string::npos) << e;
  e = error(head + "  filtered_pcg: {preconditioner: sa_amgg}\n");
  EXPECT_NE(e.find("did you mean 'sa_amg'"), std::string::npos) << e;
  e = error(head + "  filtered_pcg: {sa_amg: {smoothing_sweeps: 50}}\n");
  EXPECT_NE(e.find("smoothing_sweeps"), std::string::npos) << e;
  // a block kept for another solver of the build, not in the list
  e = error("  type: filtered_pcg\n  eigen_ldlt: {pivot_tolerence: 1e-12}\n");
  EXPECT_NE(e.find("did you mean 'pivot_tolerance'"), std::string::npos) << e;
  e = error("  type: filtered_pcg\n  eigen_ldlt: 5\n");
  EXPECT_NE(e.find("expected a mapping"), std::string::npos) << e;
}

// Every shipped scene builds without a read of an undeclared key (each stage reads through the
// spec of its section, so such a read throws std::logic_error, which fails here).
TEST(SectionSpecs, ShippedScenesReadOnlyDeclaredKeys) {
  auto& l = plugins();
  loom::Simulation::set_notes(false);
  int built = 0;
  for (const auto& e : fs::recursive_directory_iterator(fs::path(LOOM_SOURCE_DIR) / "scenes")) {
    if (e.path().extension() != ".yaml") continue;
    const Params p = Params::from_file(e.path().string());
    if (!p.has("mesh")) continue;  // a material file (scenes/kawabata/wang2011)
    try {
      loom::Simulation sim(e.path().string(), {}, *l.loader);
      ++built;
    } catch (const InputError& err) {
      // a plugin this build lacks (e.g. without CHOLMOD): not this test's business
      EXPECT_NE(std::string(err.what()).find("available"), std::string::npos) << e.path() << ": " << err.what();
    } catch (const std::logic_error& err) {
      ADD_FAILURE() << e.path() << ": " << err.what();
    }
  }
  EXPECT_GT(built, 0);
}

// A study file's keys (loom study) and its stability section (loom study --stability).
TEST(SectionSpecs, StudyFilesReadOnlyTheirDeclaredKeys) {
  const fs::path file = fs::temp_directory_path() / "loom_section_specs_study.yaml";
  const std::string base = "times: [0.1]\nsteps: {h0: 0.001, levels: 2}\ncombos: [{name: a, set: {integrator.type: rk4}}]\n";
  const std::string stab = "stability: {combos: [{name: a}]";
  auto parse = [&](const std::string& yaml, bool stability) -> std::string {
    std::ofstream(file) << yaml;
    try {
      if (stability) loom::parse_stability(file.string());
      else loom::parse_study(file.string());
    } catch (const InputError& e) {
      return e.what();
    } catch (const std::logic_error& e) {
      ADD_FAILURE() << "undeclared read: " << e.what() << "\n" << yaml;
    }
    return "";
  };
  const std::map<std::string, std::string> study = {
      {"description", "description: d"}, {"times", ""}, {"steps", ""}, {"steps.h0", ""}, {"steps.levels", ""},
      {"reference", "reference: {integrator: rk4, dt: 1.0e-6, set: {integrator.dt: 1.0e-6}}"},
      {"reference.integrator", "reference: {integrator: rk4}"}, {"reference.dt", "reference: {dt: 1.0e-6}"},
      {"reference.set", "reference: {set: {frames: 2}}"}, {"max_seconds_per_run", "max_seconds_per_run: 10"},
      {"max_strain", "max_strain: 2"}, {"combos", ""}, {"stability", stab + "}"}};
  for (const auto& d : loom::study_file_spec().decls()) EXPECT_TRUE(study.count(d.name)) << d.name << " has no case";
  for (const auto& [key, kv] : study) EXPECT_EQ(parse(base + kv + "\n", false), "") << key;
  EXPECT_NE(parse(base + "definitely_not_a_key: 1\n", false).find("definitely_not_a_key"), std::string::npos);
  EXPECT_NE(parse("times: [0.1]\nsteps: {h0: 0.001}\ncombos: [{name: a, definitely_not_a_key: 1}]\n", false)
                .find("definitely_not_a_key"),
            std::string::npos);
  const std::map<std::string, std::string> stability = {
      {"horizon", "horizon: 0.2"}, {"h_min", "h_min: 1.0e-6"}, {"h_max", "h_max: 0.01"}, {"bisections", "bisections: 4"},
      {"max_strain", "max_strain: 2"}, {"max_seconds_per_run", "max_seconds_per_run: 5"}, {"combos", ""},
      {"sweep", "sweep: {key: material.stiffness, values: [1, 2]}"}};
  for (const auto& d : loom::stability_section_spec().decls()) EXPECT_TRUE(stability.count(d.name)) << d.name << " has no case";
  for (const auto& [key, kv] : stability)
    EXPECT_EQ(parse(base + stab + (kv.empty() ? "" : ", " + kv) + "}\n", true), "") << key;
  EXPECT_NE(parse(base + stab + ", definitely_not_a_key: 1}\n", true).find("definitely_not_a_key"), std::string::npos);
  fs::remove(file);
}

// The mechanism the stages rely on: a section with its spec attached refuses a read of an
// undeclared key, nested maps and list entries included.
TEST(SectionSpecs, AnUndeclaredReadOfAFrameworkSectionThrows) {
  const Params p = Params::from_string("output: {every: 2}\ncolliders: [{type: plane, friction: {static: 1}}]\n", "s.yaml");
  const Params root = loom::with_section_spec(p, "scene");
  EXPECT_THROW(root.child("not_declared"), std::logic_error);
  EXPECT_THROW(loom::with_section_spec(root.child("output"), "output").get("not_declared", 1), std::logic_error);
  EXPECT_NO_THROW(loom::with_section_spec(root.child("output"), "output").get("every", 1));
  const Params collider = loom::with_section_spec(root.child("colliders").at(0), "colliders");
  EXPECT_THROW(collider.child("friction").get("dynamic", 0.0), std::logic_error);
  EXPECT_NO_THROW(collider.child("friction").get("kinetic", 0.0));
  EXPECT_THROW(loom::with_section_spec(p, "no_such_section"), std::logic_error);
  // and `loom plugins --params SECTION` prints a section's table
  const std::string t = loom::params_table(plugins().reg, "colliders", false);
  for (const char* k : {"radius", "friction.kinetic", "motion.angular_velocity", "rad/s"})
    EXPECT_NE(t.find(k), std::string::npos) << k << "\n" << t;
}

// ParamFields (loom/param_fields.hpp): one line declares a key (default = the member's default)
// and reads it into the member; read(p, o) leaves the members it does not bind alone.
TEST(ParamFields, DeclaresFromTheMembersAndReadsIntoThem) {
  struct Opts {
    double tolerance = 1e-6;
    int iterations = 50;
    bool warm = true;
    std::string name = "x";
    std::string mode = "fast";
    int not_a_key = 7;
  };
  loom::ParamFields<Opts> f("opts");
  f.number("tolerance", &Opts::tolerance).range(ParamRange::positive());
  f.integer("iterations", &Opts::iterations).range(ParamRange::closed(1, 100));
  f.flag("warm", &Opts::warm);
  f.text("name", &Opts::name);
  f.choice("mode", &Opts::mode, {"fast", "exact"});
  const ParamSpec& s = f.spec();
  ASSERT_EQ(s.keys(), (std::vector<std::string>{"tolerance", "iterations", "warm", "name", "mode"}));
  EXPECT_EQ(s.find("tolerance")->default_number, 1e-6);
  EXPECT_EQ(s.find("iterations")->default_number, 50);
  EXPECT_TRUE(s.find("warm")->default_bool);
  EXPECT_EQ(s.find("mode")->default_string, "fast");
  const Opts d = f.read(Params::from_string("{}", "o.yaml"));
  EXPECT_EQ(d.tolerance, 1e-6);
  EXPECT_EQ(d.iterations, 50);
  Opts o;
  o.not_a_key = 3;
  f.read(Params::from_string("tolerance: 0.5\niterations: 9\nwarm: false\nname: y\nmode: exact\n", "o.yaml"), o);
  EXPECT_EQ(o.tolerance, 0.5);
  EXPECT_EQ(o.iterations, 9);
  EXPECT_FALSE(o.warm);
  EXPECT_EQ(o.name, "y");
  EXPECT_EQ(o.mode, "exact");
  EXPECT_EQ(o.not_a_key, 3);
  const std::string e = error_of([&] { f.read(Params::from_string("iterations: 0\n", "o.yaml")); });
  EXPECT_NE(e.find("o.yaml:1"), std::string::npos) << e;
  EXPECT_NE(e.find("[1, 100]"), std::string::npos) << e;
  EXPECT_NE(error_of([&] { f.read(Params::from_string("mode: slow\n", "o.yaml")); }).find("fast, exact"), std::string::npos);
}

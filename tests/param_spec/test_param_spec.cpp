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
#include "loom/param_spec.hpp"
#include "loom/registry.hpp"
#include "loom/section_specs.hpp"
#include "loom/simulation.hpp"

namespace fs = std::filesystem;
using loom::InputError;
using loom::ParamRange;
using loom::ParamReader;
using loom::Params;
using loom::ParamSpec;

namespace {

std::string error_of(const std::function<void()>& f) {
  try {
    f();
  } catch (const InputError& e) {
    return e.what();
  }
  return "";
}

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
  auto build = [&](const std::string& yaml) -> std::string {
    try {
      loom::Simulation::from_string(yaml, "scene.yaml", LOOM_SOURCE_DIR, {}, *l.loader);
    } catch (const InputError& e) {
      return e.what();
    }
    return "";
  };
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

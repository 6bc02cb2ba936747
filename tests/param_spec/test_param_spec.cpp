// The declarative parameter specs (loom/param_spec.hpp): reading through a spec, validation.
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

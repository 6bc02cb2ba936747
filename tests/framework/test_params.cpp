#include <gtest/gtest.h>

#include <cmath>

#include "common/input_error.hpp"
#include "loom/params.hpp"

using loom::InputError;
using loom::Params;

using loom_test::error_of;

TEST(Params, TypedReadsAndDefaults) {
  Params p = Params::from_string("a: 1.5\nb: 3\nc: true\nd: hello\ne: [1, 2, 3]\n", "t.yaml");
  EXPECT_DOUBLE_EQ(p.get("a", 0.0), 1.5);
  EXPECT_EQ(p.get("b", 0), 3);
  EXPECT_TRUE(p.get("c", false));
  EXPECT_EQ(p.get("d", "x"), "hello");
  EXPECT_EQ(p.child("e").as_doubles().size(), 3u);
  EXPECT_DOUBLE_EQ(p.get("missing", 7.0), 7.0);
  EXPECT_FALSE(p.child("missing").valid());
  EXPECT_EQ(p.keys(), (std::vector<std::string>{"a", "b", "c", "d", "e"}));
}

TEST(Params, WrongTypeNamesFileLineAndPath) {
  Params p = Params::from_string("x: 1\nsection:\n  dt: abc\n", "scene.yaml");
  const std::string e = error_of([&] { p.child("section").get("dt", 0.1); });
  EXPECT_NE(e.find("scene.yaml:3"), std::string::npos) << e;
  EXPECT_NE(e.find("section.dt"), std::string::npos) << e;
  EXPECT_NE(e.find("expected a number"), std::string::npos) << e;
  const std::string e2 = error_of([&] { p.get("x", std::string("s")); p.child("section").get("dt", 3); });
  EXPECT_NE(e2.find("expected an integer"), std::string::npos) << e2;
}

TEST(Params, RangeChecksRejectZeroNegativeNanInf) {
  Params p = Params::from_string("a: 0\nb: -1\nc: .nan\nd: .inf\ne: 2\n", "r.yaml");
  EXPECT_NE(error_of([&] { p.get_positive("a", 1.0); }).find("r.yaml:1"), std::string::npos);
  EXPECT_NE(error_of([&] { p.get_positive("b", 1.0); }).find("> 0"), std::string::npos);
  EXPECT_NE(error_of([&] { p.get_positive("c", 1.0); }).find("r.yaml:3"), std::string::npos);
  EXPECT_NE(error_of([&] { p.get_nonnegative("d", 1.0); }).find("finite"), std::string::npos);
  EXPECT_NE(error_of([&] { p.get_in_range("e", 0.0, 0.0, 1.0); }).find("[0, 1]"), std::string::npos);
  EXPECT_DOUBLE_EQ(p.get_positive("e", 1.0), 2.0);
}

TEST(Params, UnknownKeyGetsDidYouMean) {
  Params p = Params::from_string("stifness: 10\ndensity: 1\n", "m.yaml");
  p.get("stiffness", 1.0);
  p.get("density", 1.0);
  const std::string e = error_of([&] { p.check_unused({"type"}); });
  EXPECT_NE(e.find("m.yaml:1"), std::string::npos) << e;
  EXPECT_NE(e.find("unknown key 'stifness'"), std::string::npos) << e;
  EXPECT_NE(e.find("did you mean 'stiffness'"), std::string::npos) << e;
}

TEST(Params, NullValueRemovesAKey) {
  Params p = Params::from_string("a: 1\nb: 2\n", "n.yaml");
  p.set_path("b", "null");
  p.get("a", 0.0);
  EXPECT_NO_THROW(p.check_unused());
  EXPECT_DOUBLE_EQ(p.get("b", 7.0), 7.0);
}

TEST(Params, ChoiceSuggestsClosest) {
  Params p = Params::from_string("variant: velocty\n", "c.yaml");
  const std::string e = error_of([&] { p.get_choice("variant", "velocity", {"velocity", "analytic_position"}); });
  EXPECT_NE(e.find("did you mean 'velocity'"), std::string::npos) << e;
  EXPECT_NE(e.find("analytic_position"), std::string::npos) << e;
}

TEST(Params, SyntaxErrorHasLine) {
  const std::string e = error_of([] { Params::from_string("a: 1\nb: [1, 2\nc: 3\n", "bad.yaml"); });
  EXPECT_NE(e.find("bad.yaml:"), std::string::npos) << e;
  EXPECT_NE(e.find("YAML syntax error"), std::string::npos) << e;
}

TEST(Params, MissingFile) {
  const std::string e = error_of([] { Params::from_file("/nonexistent/scene.yaml"); });
  EXPECT_NE(e.find("/nonexistent/scene.yaml"), std::string::npos) << e;
}

TEST(Params, SetPathOverridesAndCreates) {
  Params p = Params::from_string("integrator:\n  dt: 0.001\n", "s.yaml");
  p.set_path("integrator.dt", "0.0005");
  p.set_path("material.stiffness.bend", "12");
  p.set_path("gravity", "[0, 0, -9.81]");
  EXPECT_DOUBLE_EQ(p.child("integrator").get("dt", 0.0), 0.0005);
  EXPECT_DOUBLE_EQ(p.child("material").child("stiffness").get("bend", 0.0), 12.0);
  EXPECT_DOUBLE_EQ(p.child("gravity").as_doubles()[2], -9.81);
  EXPECT_NE(error_of([&] { p.set_path("integrator.dt.x", "1"); }).find("not a section"), std::string::npos);
  EXPECT_NE(error_of([&] { p.set_path("a..b", "1"); }).find("empty component"), std::string::npos);
}

// A bad value or key given with --set is named by the --set that gave it, not by a line of the
// file (the node has no line there; it used to read "scene.yaml:1"). Keys of the file keep
// their file:line, also next to an override.
TEST(Params, ErrorsFromSetNameTheSetNotALineOfTheFile) {
  Params p = Params::from_string("# a comment\nintegrator:\n  dt: 0.001\n  substeps: x\n", "scene.yaml");
  p.set_path("integrator.dt", "abc");
  p.set_path("material", "{type: mass_spring, densty: 2}");
  const std::string e = error_of([&] { p.child("integrator").get("dt", 0.1); });
  EXPECT_EQ(e.rfind("--set integrator.dt=abc: ", 0), 0u) << e;
  EXPECT_NE(e.find("expected a number"), std::string::npos) << e;
  EXPECT_EQ(e.find("scene.yaml"), std::string::npos) << e;
  // A key of the file beside the override keeps its line.
  const std::string e2 = error_of([&] { p.child("integrator").get("substeps", 1); });
  EXPECT_EQ(e2.rfind("scene.yaml:4: ", 0), 0u) << e2;
  // A key inside a section that --set gave: that --set, for its values and its unknown keys.
  Params mat = p.child("material");
  mat.get("type", std::string());
  const std::string e3 = error_of([&] { mat.check_unused(); });
  EXPECT_EQ(e3.rfind("--set material={type: mass_spring, densty: 2}: unknown key 'densty'", 0), 0u) << e3;
  // A later --set of the same key is the one named.
  p.set_path("integrator.dt", "[1]");
  const std::string e4 = error_of([&] { p.child("integrator").get("dt", 0.1); });
  EXPECT_EQ(e4.rfind("--set integrator.dt=[1]: ", 0), 0u) << e4;
  // An unknown key added by --set next to the file's keys.
  p.set_path("integrator.dtt", "0.1");
  Params integ = p.child("integrator");
  integ.child("dt");
  integ.child("substeps");
  const std::string e5 = error_of([&] { integ.check_unused(); });
  EXPECT_EQ(e5.rfind("--set integrator.dtt=0.1: unknown key 'dtt'", 0), 0u) << e5;
}

// --set reaches into lists by index (colliders.0.radius): the entry of a list, a scalar of a
// list, with errors naming that --set and the entry's path; an index out of range, a component
// that is not an index, and removing an entry are refused with the fix.
TEST(Params, SetPathIndexesLists) {
  Params p = Params::from_string(
      "gravity: [0, -9.81, 0]\ncolliders:\n  - {type: sphere, radius: 0.3, motion: {type: rotate, angular_velocity: 2}}\n",
      "scene.yaml");
  p.set_path("colliders.0.motion.angular_velocity", "8");
  p.set_path("colliders.0.friction", "{static: 0.5}");
  p.set_path("gravity.1", "-3");
  const Params c0 = p.child("colliders").at(0);
  EXPECT_DOUBLE_EQ(c0.child("motion").get("angular_velocity", 0.0), 8.0);
  EXPECT_DOUBLE_EQ(c0.child("friction").get("static", 0.0), 0.5);
  EXPECT_DOUBLE_EQ(c0.get("radius", 0.0), 0.3);   // the rest of the entry is kept
  EXPECT_EQ(p.child("gravity").as_doubles(), (std::vector<double>{0, -3, 0}));
  p.set_path("colliders.0.radius", "abc");
  const std::string e = error_of([&] { p.child("colliders").at(0).get("radius", 1.0); });
  EXPECT_EQ(e.rfind("--set colliders.0.radius=abc: colliders[0].radius: expected a number", 0), 0u) << e;
  const std::string e2 = error_of([&] { p.set_path("colliders.1.radius", "1"); });
  EXPECT_NE(e2.find("'colliders' has 1 entry (indices from 0), so there is no entry 1"), std::string::npos) << e2;
  const std::string e3 = error_of([&] { p.set_path("colliders.ball.radius", "1"); });
  EXPECT_NE(e3.find("must be the index of one of its 1 entries"), std::string::npos) << e3;
  EXPECT_NE(e3.find("--set colliders.0.radius=1"), std::string::npos) << e3;
  const std::string e4 = error_of([&] { p.set_path("colliders.0", "null"); });
  EXPECT_NE(e4.find("cannot be removed"), std::string::npos) << e4;
  const std::string e5 = error_of([&] { p.set_path("colliders.0.radius.x", "1"); });
  EXPECT_NE(e5.find("'colliders.0.radius' is a value"), std::string::npos) << e5;
  const std::string e6 = error_of([&] { p.set_path("gravity.3", "1"); });
  EXPECT_NE(e6.find("'gravity' has 3 entries"), std::string::npos) << e6;
  // A section that --set had to create is that --set's, also where it is read as a whole.
  p.set_path("pins.0.motion", "{type: translate}");
  const std::string e7 = error_of([&] { p.child("pins").fail("must be a list"); });
  EXPECT_EQ(e7.rfind("--set pins.0.motion={type: translate}: pins: must be a list", 0), 0u) << e7;
}

TEST(Params, ClosestMatch) {
  EXPECT_EQ(loom::closest_match("mas_spring", {"mass_spring", "gnatv"}), "mass_spring");
  EXPECT_EQ(loom::closest_match("zzzzzz", {"mass_spring", "gnatv"}), "");
}

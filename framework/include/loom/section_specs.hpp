// Declared keys of the framework's own scene sections (mesh, output, guard, self_collision and
// the scene's top level), in the same ParamSpec form as the plugins' (loom/param_spec.hpp), so
// that `loom plugins --params output` prints them and docs/SCENE_KEYS.md carries generated tables.
// The scene builder's stages (framework/src/scene_build.cpp) read these keys; tests/param_spec
// builds a scene with every declared key and checks that an undeclared one is refused, so the
// two cannot drift apart.
#pragma once

#include <string>
#include <utility>
#include <vector>

#include "loom/param_spec.hpp"

namespace loom {

const ParamSpec& scene_section_spec();          ///< the top-level keys
const ParamSpec& mesh_section_spec();
const ParamSpec& output_section_spec();
const ParamSpec& guard_section_spec();
const ParamSpec& self_collision_section_spec();

/// (section name, spec) for every framework section with a spec: "scene", "mesh", "material",
/// "integrator", "output", "guard", "self_collision", "render".
const std::vector<std::pair<std::string, const ParamSpec*>>& framework_section_specs();

/// The spec of framework section `name`, or nullptr.
const ParamSpec* framework_section_spec(const std::string& name);

}  // namespace loom

// Declared keys of the framework's own scene sections (the scene's top level, mesh, material,
// bending, integrator, solver, the entries of pins, mass_scale and colliders with their motions,
// self_collision, output, guard) and of study files, in the same ParamSpec form as the plugins'
// (loom/param_spec.hpp), so that `loom plugins --params SECTION` prints them and
// docs/SCENE_KEYS.md carries generated tables.
//
// The code that reads a section reads it through its spec: Simulation::build attaches the
// scene's spec to the root, each stage (framework/src/scene_build.cpp) and parser (pins.cpp,
// collider.cpp, motion.cpp, study.cpp, and self_collision / bending through their call sites)
// attaches its section's with with_section_spec, so a read of an undeclared key throws
// std::logic_error. tests/param_spec builds every shipped scene and a scene with each declared
// key (and one with an undeclared key, which is refused), so declarations and reads cannot drift.
#pragma once

#include <string>
#include <utility>
#include <vector>

#include "loom/param_fields.hpp"
#include "loom/param_spec.hpp"

namespace loom {

struct OutputOptions;  // loom/simulation.hpp
struct GuardOptions;

const ParamSpec& scene_section_spec();          ///< the top-level keys
const ParamSpec& mesh_section_spec();
const ParamSpec& output_section_spec();
const ParamSpec& guard_section_spec();
/// The output and guard keys bound to their options' members (the spec and the reader in one).
const ParamFields<OutputOptions>& output_section_fields();
const ParamFields<GuardOptions>& guard_section_fields();
const ParamSpec& self_collision_section_spec();
const ParamSpec& solver_section_spec();         ///< `type`; the builder adds one open block per solver name
const ParamSpec& bending_section_spec();        ///< material.bending (loom/bending.hpp)
const ParamSpec& pin_entry_spec();              ///< an entry of pins: (loom/pins.hpp)
const ParamSpec& mass_scale_entry_spec();       ///< an entry of mass_scale:
const ParamSpec& collider_entry_spec();         ///< an entry of colliders: (loom/collider.hpp)
const ParamSpec& motion_key_spec();             ///< an entry of motion.keys (keyframes)
const ParamSpec& study_file_spec();             ///< a study file's top level (loom/study.hpp)
const ParamSpec& study_combo_spec();            ///< an entry of a study's combos
const ParamSpec& stability_section_spec();      ///< a study file's stability: section (loom study --stability)

/// `p` with the spec of framework section `name` attached (framework_section_spec): every read
/// of a key the spec does not declare throws std::logic_error (a bug in the reading code, found
/// by tests/param_spec), and check_unused() suggests the declared keys.
Params with_section_spec(const Params& p, const std::string& name);

/// (section name, spec) for every framework section with a spec: "scene", "mesh", "material",
/// "integrator", "solver", "bending", "pins", "mass_scale", "colliders", "motion_keys",
/// "self_collision", "output", "guard", "render", "study", "study_combos", "stability".
const std::vector<std::pair<std::string, const ParamSpec*>>& framework_section_specs();

/// The spec of framework section `name`, or nullptr.
const ParamSpec* framework_section_spec(const std::string& name);

}  // namespace loom

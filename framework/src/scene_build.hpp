// The stages of Simulation::build (framework-internal). Each reads one part of the scene file,
// checks it (Params::fail names the file, line and fix) and fills its part of the Scene:
//   mesh -> material -> state and initial conditions -> selections (mass_scale, pins) ->
//   colliders (and self-collision) -> integrator -> solver -> frames, output and guards.
// Vertex selections (pins, mass_scale) all go through select_vertices (loom/pins.hpp).
#pragma once

#include <functional>
#include <memory>
#include <string>
#include <vector>

#include "loom/integrator.hpp"
#include "loom/output.hpp"
#include "loom/params.hpp"
#include "loom/registry.hpp"
#include "loom/scene.hpp"
#include "loom/simulation.hpp"

namespace loom::scene_build {

/// `--set key=value` overrides, applied to the parsed scene before any stage reads it.
void apply_overrides(Params& root, const std::vector<std::string>& overrides);

/// The run's peak-memory estimate against the machine's, as the line `loom validate` prints;
/// refuses (mesh: ... fails) a run that cannot fit. Parses only the combo's names.
std::string memory_line(const Params& root, long long vertices);

/// mesh: {grid: {...}} or {obj: file, scale: s}. `before_allocating(vertices)` runs once the
/// vertex count is known and before a grid is allocated (the memory check).
Mesh mesh(const Params& root, const std::string& base_dir, const std::function<void(long long)>& before_allocating);

/// material: loads the plugin (and the execution backend's module), applies a library fabric
/// and wraps the material in hinge bending when asked. Returns the material's name.
std::string material(const Params& root, Scene& sc, PluginLoader& loader);

/// Positions, masses (checked finite and > 0), initial_scale, initial_velocity and gravity.
void state(const Params& root, Scene& sc, const std::string& material_name);

/// Everything that selects vertices: mass_scale factors, then pins (which zero the inverse
/// masses of their vertices), through the one parser select_vertices.
void selections(const Params& root, Scene& sc);

/// colliders (with the thickness-versus-cloth-size check) and self_collision.
void colliders(const Params& root, Scene& sc, const std::string& base_dir);

struct IntegratorChoice {
  std::string name;
  double dt = 1e-3;
  int substeps = 1;
  std::unique_ptr<Integrator> integrator;
};
/// integrator: type, dt, substeps or frame_time; checks that the material offers what the
/// integrator needs (springs, Jacobians).
IntegratorChoice integrator(const Params& root, Scene& sc, PluginLoader& loader, const std::string& material_name);

/// solver: the first available of the listed solvers when the integrator needs one (notes on
/// stderr name skipped ones); an ignored section for explicit integrators. Returns the chosen
/// name ("" when none).
std::string solver(const Params& root, Scene& sc, PluginLoader& loader, const IntegratorNeeds& needs,
                   const std::string& integrator_name, bool notes);

/// frames, output and guard.
void output_and_guards(const Params& root, int& frames, OutputOptions& output, GuardOptions& guard);

}  // namespace loom::scene_build

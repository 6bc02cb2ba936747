// `loom run --resume RUN_DIR`: rebuild a stopped run's simulation from its folder.
#pragma once

#include <memory>
#include <string>

#include "loom/simulation.hpp"

namespace loom::cli {

/// The simulation of the run in run_dir, built from the scene.yaml `loom run` left there
/// (relative paths resolve against the original scene's folder, recorded in it) and restored
/// to its last complete frame (Simulation::resume). frames >= 0 replaces the run's frame count.
std::unique_ptr<Simulation> load_for_resume(const std::string& run_dir, int frames, PluginLoader& loader);

/// The same simulation at its initial state (not restored): the scene the run in run_dir ran.
std::unique_ptr<Simulation> load_run_scene(const std::string& run_dir, PluginLoader& loader);

}  // namespace loom::cli

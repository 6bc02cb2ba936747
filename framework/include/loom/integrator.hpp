// Integrator: time stepping. Coarse interface: one virtual call per step.
#pragma once

#include <string>
#include <vector>

#include "loom/common.hpp"
#include "loom/scene.hpp"

namespace loom {

/// What an integrator needs from the combo; checked when the scene is built.
struct IntegratorNeeds {
  bool springs = false;        ///< material must expose a SpringSet (HO)
  bool jacobian = false;       ///< material must provide force Jacobians
  bool linear_solver = false;  ///< a LinearSolver must be configured
};

/// Per-step counters, read by the stats writer and by `loom study`.
struct StepStats {
  int force_evaluations = 0;
  int linear_iterations = 0;     ///< summed over solves in the step
  double linear_residual = 0;    ///< of the last solve
  double assemble_seconds = 0;
  double solve_seconds = 0;
  int retries = 0;               ///< step halvings after failed solves
  Index self_contacts = 0;       ///< self-contacts entered into the step's last solve (baraff_witkin)
};

class Integrator {
 public:
  virtual ~Integrator() = default;
  virtual std::string name() const = 0;
  virtual IntegratorNeeds needs() const { return {}; }
  /// Called before the first step and again whenever h or a mass changes: check the
  /// combo (throw InputError with the fix), precompute, allocate all work arrays.
  virtual void prepare(Scene& scene, double h) = 0;
  /// Advance scene.state by h. Must not allocate. Updates state.time and state.step.
  virtual void step(Scene& scene, double h) = 0;
  virtual StepStats last_step() const { return {}; }
  /// True when step() honours scene.colliders itself (as constraints, like Baraff-Witkin).
  /// Otherwise the framework resolves contacts after each step (ColliderSet::resolve_contacts).
  virtual bool handles_contacts() const { return false; }
  /// What step() carries from one step to the next besides positions and velocities (a warm
  /// start, the active contacts), for an exact restart (loom run --resume). Default: nothing.
  virtual std::vector<double> restart_state() const { return {}; }
  /// Restore what restart_state() returned (after prepare()); false when it does not fit.
  virtual bool set_restart_state(const std::vector<double>& s) { return s.empty(); }
  /// For an integrator that keeps its own copy of x and v (the CUDA backend keeps them on the
  /// device): bring scene.state.x and .v up to date with it. The framework calls this before
  /// it reads them (the guards, the stats, the output, a study's measurement). Default: nothing
  /// to do, scene.state is the state.
  virtual void sync_to_host(Scene&) {}
  /// The per-step guard on the integrator's own copy, without bringing it to the host: the
  /// lowest vertex whose squared speed is not <= vmax2 or whose position is not finite (the
  /// test of Simulation::check_state), -1 when there is none. -2 (the default): not checked
  /// here; the framework calls sync_to_host and checks scene.state itself.
  virtual Index first_unguarded_vertex(double /*vmax2*/) { return -2; }
};

/// Shared helper: advance time bookkeeping after a step of size h.
inline void finish_step(State& s, double h) {
  s.time += h;
  s.step += 1;
}

}  // namespace loom

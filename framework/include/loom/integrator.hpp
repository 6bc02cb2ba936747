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
};

/// Shared helper: advance time bookkeeping after a step of size h.
inline void finish_step(State& s, double h) {
  s.time += h;
  s.step += 1;
}

}  // namespace loom

// Stable-step estimate for explicit combos, for `loom validate`.
#pragma once

#include <optional>
#include <string>

namespace loom {

struct Scene;

/// The largest stable step of an explicit integrator on the linearised cloth at its initial
/// state: h* = c / sqrt(lambda_max(M^-1 K)), K = -df/dx, over the free vertices, with c the
/// integrator's stability bound for an undamped oscillator (docs/NUMERICS.md): 2 for
/// symplectic Euler, 2 sqrt(2) for RK4 (its stability region on the imaginary axis), sqrt(2)
/// for the harmonic-oscillation step (the lower end of its bracket [sqrt(2), 1.7207]).
struct StepLimit {
  double lambda_max = 0;   ///< estimate of the largest eigenvalue of M^-1 K (1/s^2)
  double factor = 0;       ///< c
  double h_max = 0;        ///< c / sqrt(lambda_max)
  int iterations = 0;      ///< power iterations used
};

/// c for an integrator (above), 0 for one without a stable-step estimate (implicit ones).
double stable_step_factor(const std::string& integrator);

/// nullopt when the integrator is not one of the explicit ones above or the material has no
/// Jacobian. Builds a temporary Jacobian pattern (the material is re-bound by any later
/// prepare()); cost: one Jacobian and up to 200 sparse products.
std::optional<StepLimit> estimate_step_limit(Scene& scene, const std::string& integrator);

}  // namespace loom

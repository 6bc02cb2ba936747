// Integrators of the CUDA backend (registered as (integrator, name, "cuda")): the state lives
// on the device for the whole run (uploaded in prepare()); x and v are copied back into
// scene.state after every step, or after every n-th with `host_sync_every: n` (the framework's
// divergence guard, output and stats read scene.state: set guard.check_every to the same n and
// substeps to a multiple of it, otherwise they see a stale state). Host edits of scene.state
// between steps are not seen by the device. Double by default; the
// `precision: float` parameter runs the device arrays in float (coefficients are still
// computed in double and rounded once).
//
//   harmonic_oscillation  variants velocity | analytic_position | kang_cho_2011, same per-spring
//                         math as the CPU plugin (loom/kernels/ho.hpp)
//   rk4                   loom/kernels/rk4.hpp stages; forces from the device force model
//   symplectic_euler      forces from the device force model, then the CPU plugin's vertex update
//                         (symplectic_euler/se_update.hpp); sphere, plane and mesh contacts after the step
//   baraff_witkin         device assembly of A and b (NUMERICS 3.1/3.2, Kang-Cho and Rayleigh
//                         damping), pins through the filter S, solved by cusparse_pcg on device
#pragma once

#include <memory>
#include <string>

#include "device_model.hpp"
#include "device_pcg.hpp"
#include "baraff_witkin.hpp"
#include "ho_integrator.hpp"
#include "loom/integrator.hpp"
#include "loom/params.hpp"
#include "rk4_integrator.hpp"
#include "symplectic_euler.hpp"

namespace loom::cuda {

enum class Precision { Double, Float };
/// Reads `precision` (double | float) through loom::device_keys_spec(), which the cpu
/// integrators' specs (baraff_witkin_spec, harmonic_oscillation_spec, rk4_spec) include.
Precision parse_precision(const Params& p);

enum class HoVariantD { Velocity = 0, AnalyticPosition = 1, KangCho2011 = 2 };

std::unique_ptr<Integrator> make_cuda_ho(const Params& p);
std::unique_ptr<Integrator> make_cuda_rk4(const Params& p);
std::unique_ptr<Integrator> make_cuda_baraff_witkin(const Params& p);
std::unique_ptr<Integrator> make_cuda_symplectic_euler(const Params& p);

/// Direct construction (tests, benchmarks).
/// merge: key merge_springs (springs on the same two vertices stepped as one, the CPU plugin's rule).
std::unique_ptr<Integrator> make_cuda_ho(HoVariantD variant, Precision precision, int host_sync_every = 1,
                                         bool merge = true);
/// merge: key merge_springs (springs on the same two vertices stepped as one; forces only).
std::unique_ptr<Integrator> make_cuda_rk4(Precision precision, int host_sync_every = 1, bool merge = true);
/// merge: key merge_springs (springs on the same two vertices stepped as one; forces only).
std::unique_ptr<Integrator> make_cuda_symplectic_euler(Precision precision, int host_sync_every = 1, bool merge = true);
struct BwOptionsD {
  double kang_cho_damping = 0, rayleigh_alpha = 0, rayleigh_beta = 0;
  bool halve_on_failure = false;
  int max_halvings = 3;
  bool warm_start = true;
  /// Coulomb friction of the colliders' contacts as tangential dampers inside the solve (the
  /// cpu plugin's rule and default); false: the velocity correction after the solve.
  bool implicit_friction = true;
  int host_sync_every = 1;
};
std::unique_ptr<Integrator> make_cuda_baraff_witkin(const BwOptionsD& o, Precision precision);

}  // namespace loom::cuda

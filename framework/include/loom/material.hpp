// Material: the force model. Coarse interface: one virtual call computes the forces of
// the whole cloth.
#pragma once

#include <array>
#include <span>
#include <string>
#include <vector>

#include "loom/bsr.hpp"
#include "loom/common.hpp"
#include "loom/springs.hpp"

namespace loom {

struct Mesh;
struct State;
struct DeviceDescription;

class Material {
 public:
  virtual ~Material() = default;

  virtual std::string name() const = 0;

  /// Lumped masses (kg) of every vertex, written into mass (size n). Called once.
  virtual void compute_masses(std::span<double> mass) const = 0;

  /// Internal forces (elastic + material damping, no gravity) at positions x and
  /// velocities v (3n each). Overwrites f (3n).
  virtual void compute_forces(std::span<const double> x, std::span<const double> v,
                              std::span<double> f) const = 0;

  /// Elastic potential energy at positions x.
  virtual double elastic_energy(std::span<const double> x) const = 0;

  /// Largest strain magnitude (relative stretch or compression) at positions x.
  virtual double max_strain(std::span<const double> x) const = 0;

  /// Springs, for per-spring integrators; nullptr for materials that are not spring networks.
  virtual const SpringSet* springs() const { return nullptr; }

  /// Summary for `loom validate`, e.g. {"springs", "161544"}.
  virtual std::vector<std::pair<std::string, std::string>> describe() const { return {}; }

  // ---- Jacobians (implicit integrators). Only called when has_jacobian(). ----
  virtual bool has_jacobian() const { return false; }
  /// Vertex pairs (i != j) coupled by an element; the pattern adds the diagonal.
  virtual void jacobian_pairs(std::vector<std::array<Index, 2>>& pairs) const { (void)pairs; }
  /// Called once with the pattern built from jacobian_pairs: build the scatter map.
  virtual void bind_pattern(const BsrPattern& pattern) { (void)pattern; }
  /// Write df/dx (and df/dv when dfdv is non-null) at (x, v) into matrices over the bound
  /// pattern, overwriting every value. Implementations must not allocate.
  virtual void compute_jacobians(std::span<const double> x, std::span<const double> v,
                                 BsrMatrix& dfdx, BsrMatrix* dfdv) const {
    (void)x; (void)v; (void)dfdx; (void)dfdv;
  }

  // ---- Device backends ----
  /// The material's elements as plain arrays plus the per-element kernel ids
  /// (loom/device_material.hpp), for backends that run the kernels themselves (CUDA). Called
  /// once at set-up. Append blocks to `out` and return true when they reproduce
  /// compute_forces / compute_jacobians exactly; return false (the default) to be evaluated
  /// on the host instead.
  virtual bool describe_device(DeviceDescription& out) const { (void)out; return false; }
};

}  // namespace loom

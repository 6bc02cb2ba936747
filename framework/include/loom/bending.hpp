// Hinge bending on any triangle mesh, composable with any membrane material
// (NUMERICS.md section 5, docs/plugins/bending.md). A scene adds it inside the material
// section:
//   material: {type: gnatv, material_file: ..., bending: {stiffness: 1.0e-5}}
// The framework reads (and marks used) the `bending` key before the material plugin checks
// its keys, builds the material as usual and wraps it in a BentMaterial, which sums the
// membrane's and the hinges' forces, energies and Jacobians. A material stays one folder;
// bending is one framework file (this one) plus the per-hinge kernel in kernels/bending.hpp.
#pragma once

#include <array>
#include <memory>
#include <string>
#include <vector>

#include "loom/kernels/bending.hpp"
#include "loom/material.hpp"
#include "loom/mesh.hpp"
#include "loom/params.hpp"

namespace loom {

struct BendingOptions {
  /// Bending rigidities B (N m) for curvature along the weft, along the warp, and along
  /// the bias (45 degrees). Hinge edges run across the curvature: an edge along the warp
  /// bends with b_weft.
  double b_weft = 0, b_warp = 0, b_bias = 0;
  bool anisotropic = false;      ///< the three differ (needs texture coordinates)
  bool exact_jacobian = false;   ///< exact Hessian instead of the Gauss-Newton (PSD) term
  bool skip_non_manifold = false;  ///< skip edges of 3+ triangles with a warning (else refuse)
  double weft_angle = 0;         ///< rad, weft direction from the texture u axis toward v
};

/// Read a `bending:` block. Errors (negative, NaN, Inf stiffness, unknown keys) name the
/// file and line.
BendingOptions read_bending_options(const Params& p);

/// The hinges of a mesh (one per interior edge), their rest data and a vertex colouring
/// (hinges of one colour share no vertex) for race-free parallel scatter.
class HingeSet {
 public:
  /// Throws InputError for a non-manifold edge unless opt.skip_non_manifold (then the
  /// skipped edges are listed in warnings()), for anisotropic stiffness without texture
  /// coordinates, and for a hinge whose rest angle is undefined.
  HingeSet(const Mesh& mesh, const BendingOptions& opt);

  Index num_hinges() const { return static_cast<Index>(hinge_.size()); }
  int num_colours() const { return static_cast<int>(colour_start_.size()) - 1; }
  /// Hinges in storage (colour) order: vertices (x0, x1 the edge; x2, x3 opposite).
  const std::vector<std::array<Index, 4>>& hinges() const { return hinge_; }
  const std::vector<bending::RestHinge<double>>& rest() const { return rest_; }
  const std::vector<Index>& colour_start() const { return colour_start_; }
  const std::vector<std::string>& warnings() const { return warnings_; }
  const BendingOptions& options() const { return opt_; }
  void set_exact_jacobian(bool on) { opt_.exact_jacobian = on; }

  /// f += bending forces at x.
  void add_forces(std::span<const double> x, std::span<double> f) const;
  double energy(std::span<const double> x) const;
  void jacobian_pairs(std::vector<std::array<Index, 2>>& pairs) const;
  void bind_pattern(const BsrPattern& pattern);
  /// dfdx += bending Jacobian at x (over the bound pattern).
  void add_jacobian(std::span<const double> x, BsrMatrix& dfdx) const;

 private:
  BendingOptions opt_;
  Index n_ = 0;
  std::vector<std::array<Index, 4>> hinge_;
  std::vector<bending::RestHinge<double>> rest_;
  std::vector<Index> colour_start_;
  std::vector<Index> scatter_;  // 16 per hinge: block (x_a, x_b) at 4 a + b
  std::vector<std::string> warnings_;
  const BsrPattern* bound_ = nullptr;
};

/// A membrane material plus hinge bending: forces, energies and Jacobians summed; masses,
/// strains from the membrane.
class BentMaterial final : public Material {
 public:
  BentMaterial(std::unique_ptr<Material> membrane, const Mesh& mesh, const BendingOptions& opt);

  std::string name() const override { return membrane_->name(); }
  void compute_masses(std::span<double> mass) const override { membrane_->compute_masses(mass); }
  void compute_forces(std::span<const double> x, std::span<const double> v, std::span<double> f) const override;
  double elastic_energy(std::span<const double> x) const override;
  double max_strain(std::span<const double> x) const override { return membrane_->max_strain(x); }
  /// No springs: a per-spring integrator would ignore the hinges.
  const SpringSet* springs() const override { return nullptr; }
  std::vector<std::pair<std::string, std::string>> describe() const override;
  /// The membrane's blocks plus one Hinge block; false when the membrane has none.
  bool describe_device(DeviceDescription& out) const override;

  bool has_jacobian() const override { return membrane_->has_jacobian(); }
  void jacobian_pairs(std::vector<std::array<Index, 2>>& pairs) const override;
  void bind_pattern(const BsrPattern& pattern) override;
  void compute_jacobians(std::span<const double> x, std::span<const double> v, BsrMatrix& dfdx,
                         BsrMatrix* dfdv) const override;

  const Material& membrane() const { return *membrane_; }
  const HingeSet& hinges() const { return hinges_; }
  HingeSet& hinges() { return hinges_; }

 private:
  std::unique_ptr<Material> membrane_;
  HingeSet hinges_;
};

/// The scene hook: returns `material` unchanged when `bending` is not a valid node, else
/// reads the block and wraps the material. Refuses backends other than cpu and cuda (the
/// CUDA backend runs the hinges through describe_device()). Prints the non-manifold warnings.
std::unique_ptr<Material> add_bending(std::unique_ptr<Material> material, const Params& bending, const Mesh& mesh,
                                      const std::string& backend);

}  // namespace loom

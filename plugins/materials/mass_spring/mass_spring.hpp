// mass_spring: Hooke springs on a mesh or grid stencil (Kang & Cho 2011), with optional
// axial dampers and force Jacobians for implicit integrators. See docs/plugins/mass_spring.md.
#pragma once

#include <array>
#include <cstdint>
#include <span>
#include <string>
#include <vector>

#include "loom/material.hpp"
#include "loom/mesh.hpp"
#include "loom/param_spec.hpp"
#include "loom/params.hpp"
#include "loom/spring_layout.hpp"
#include "loom/springs.hpp"

namespace loom::mass_spring {

enum class Stencil { MeshEdges, StructuralShearBend, RadiusSqrt5, KangChoTable1 };

const char* to_string(Stencil s);
/// Parses a stencil name; returns false for an unknown one.
bool parse_stencil(const std::string& name, Stencil& out);

/// A value per spring class (indexed by SpringClass).
struct ClassValues {
  std::array<double, 4> v{0, 0, 0, 0};
  static ClassValues all(double x) { return ClassValues{{x, x, x, x}}; }
  double operator[](SpringClass c) const { return v[static_cast<int>(c)]; }
};

/// Build the springs of a stencil over the mesh (rest lengths from mesh.positions), sorted by
/// (lower, upper) endpoint with i < j. Grid stencils need mesh.grid; kang_cho_table1 also uses
/// the mesh's triangles. Throws std::invalid_argument when a grid stencil meets a non-grid mesh.
/// Rest lengths are not validated here (the material does that).
SpringSet build_springs(const Mesh& mesh, Stencil stencil, const ClassValues& stiffness,
                        const ClassValues& damping);

/// The keys of mass_spring: stencil, stiffness, damping, density, vertex_mass, clamp_compressed.
const ParamSpec& mass_spring_spec();

class MassSpringMaterial final : public Material {
 public:
  /// Reads: stencil, stiffness, damping, density | vertex_mass, clamp_compressed.
  MassSpringMaterial(const Params& p, const Mesh& mesh);

  std::string name() const override { return "mass_spring"; }
  void compute_masses(std::span<double> mass) const override;
  void compute_forces(std::span<const double> x, std::span<const double> v,
                      std::span<double> f) const override;
  double elastic_energy(std::span<const double> x) const override;
  double max_strain(std::span<const double> x) const override;
  const SpringSet* springs() const override { return &springs_; }
  std::vector<std::pair<std::string, std::string>> describe() const override;
  /// One Spring block (loom/device_material.hpp).
  bool describe_device(DeviceDescription& out) const override;

  bool has_jacobian() const override { return true; }
  void jacobian_pairs(std::vector<std::array<Index, 2>>& pairs) const override;
  void bind_pattern(const BsrPattern& pattern) override;
  void compute_jacobians(std::span<const double> x, std::span<const double> v, BsrMatrix& dfdx,
                         BsrMatrix* dfdv) const override;

  // Inspection (tests, benchmarks).
  Stencil stencil() const { return stencil_; }
  const SpringLayout& layout() const { return layout_; }
  bool damped() const { return damped_; }
  bool clamp_compressed() const { return clamp_; }
  Index num_vertices() const { return n_; }
  Index count(SpringClass c) const { return counts_[static_cast<int>(c)]; }
  /// Distinct vertex pairs joined by springs (fewer than springs().size() when some pair has several).
  Index vertex_pairs() const { return pairs_; }

 private:
  void check_sizes(std::size_t xs, const char* what) const;

  Index n_ = 0;
  Stencil stencil_ = Stencil::MeshEdges;
  SpringSet springs_;            // stored in layout_ traversal order
  SpringLayout layout_;
  std::vector<double> inv_rest_;  // 1 / l0
  std::vector<double> mass_;
  std::array<Index, 4> counts_{0, 0, 0, 0};
  Index pairs_ = 0;   ///< distinct vertex pairs
  bool damped_ = false;
  bool clamp_ = true;
  // Jacobian scatter map: per spring, positions of blocks (i,i), (j,j), (i,j), (j,i).
  const BsrPattern* pattern_ = nullptr;
  std::vector<Index> scatter_;
  // Per spring: bit 0 / bit 1 set when it is the first (in traversal order) to write block
  // (i,j) / (j,i); the first writer assigns, later ones add. Set when every off-diagonal
  // block of the pattern belongs to some spring, so only diagonal blocks need zeroing.
  std::vector<std::uint8_t> first_write_;
  bool assign_offdiag_ = false;
};

}  // namespace loom::mass_spring

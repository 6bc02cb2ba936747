// The `gnatv` material plugin: Volino et al.'s nonlinear anisotropic triangle material
// driven by measured stress-strain curves (NUMERICS.md section 2; docs/plugins/gnatv.md).
#pragma once

#include <array>
#include <string>
#include <vector>

#include "loom/kernels/gnatv.hpp"
#include "loom/material.hpp"
#include "loom/mesh.hpp"
#include "loom/param_spec.hpp"
#include "loom/params.hpp"
#include "material_file.hpp"

namespace loom::gnatv {

struct GnatvOptions {
  std::string material_file;            ///< resolved path
  CurveInterpolation interpolation = CurveInterpolation::MonotoneCubic;
  enum class Orientation { Auto, UV, XAxis } orientation = Orientation::Auto;
  double weft_angle = 0;                ///< radians, from the reference direction toward the in-plane normal x it
  double density = 0;                   ///< kg/m^2; 0 = from the material file
  double stress_scale = 1;
  bool psd_projection = true;
};

/// The keys of gnatv (material_file, interpolation, orientation, weft_angle, density,
/// stress_scale, psd_projection), read through this spec by the Params constructor.
const ParamSpec& gnatv_spec();

class GnatvMaterial final : public Material {
 public:
  /// From scene parameters (material_file resolved against the scene file's folder).
  GnatvMaterial(const Params& p, const Mesh& mesh);
  /// From options and already-read material data (tests, benchmarks).
  GnatvMaterial(const GnatvOptions& opt, MaterialData data, const Mesh& mesh);

  std::string name() const override { return "gnatv"; }
  void compute_masses(std::span<double> mass) const override;
  void compute_forces(std::span<const double> x, std::span<const double> v, std::span<double> f) const override;
  double elastic_energy(std::span<const double> x) const override;
  double max_strain(std::span<const double> x) const override;
  std::vector<std::pair<std::string, std::string>> describe() const override;
  /// One GnatvTriangle block (loom/device_material.hpp).
  bool describe_device(DeviceDescription& out) const override;

  bool has_jacobian() const override { return true; }
  void jacobian_pairs(std::vector<std::array<Index, 2>>& pairs) const override;
  void bind_pattern(const BsrPattern& pattern) override;
  void compute_jacobians(std::span<const double> x, std::span<const double> v, BsrMatrix& dfdx,
                         BsrMatrix* dfdv) const override;

  // Introspection (tests).
  Index num_triangles() const { return static_cast<Index>(rest_.size()); }
  int num_colours() const { return static_cast<int>(colour_start_.size()) - 1; }
  /// Triangles in storage (colour) order: vertices and rest data.
  const std::vector<std::array<Index, 3>>& triangles() const { return tri_; }
  const std::vector<RestTriangle<double>>& rest() const { return rest_; }
  /// Colour c holds chunks colour_start()[c] .. colour_start()[c+1]-1; chunk q holds the
  /// stored triangles chunk_start()[q] .. chunk_start()[q+1]-1. Chunks of one colour share
  /// no vertex.
  const std::vector<Index>& colour_start() const { return colour_start_; }
  const std::vector<Index>& chunk_start() const { return chunk_start_; }
  const Curves<double>& curves() const { return views_; }
  const MaterialData& data() const { return data_; }
  double density() const { return density_; }
  bool psd_projection() const { return opt_.psd_projection; }
  void set_psd_projection(bool on) { opt_.psd_projection = on; }

 private:
  void setup(const Mesh& mesh);

  GnatvOptions opt_;
  MaterialData data_;
  Curves<double> views_;
  double density_ = 0;
  Index n_ = 0;
  std::vector<std::array<Index, 3>> tri_;         // colour-sorted
  std::vector<RestTriangle<double>> rest_;        // same order
  std::vector<Index> colour_start_;               // colour c: chunks [colour_start_[c], colour_start_[c+1])
  std::vector<Index> chunk_start_;                // chunk q: triangles [chunk_start_[q], chunk_start_[q+1])
  std::vector<Index> original_index_;             // mesh triangle index of each stored triangle
  std::vector<double> mass_;
  std::vector<Index> scatter_;                    // 9 per triangle: block of (v_j, v_i) at 3j+i; ~k = first write
  std::vector<Index> untouched_;                  // pattern blocks no triangle writes
  const BsrPattern* bound_ = nullptr;
};

}  // namespace loom::gnatv

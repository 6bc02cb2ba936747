// Reading a measured-material YAML file (materials/README.md): areal density and the
// weft, warp and shear stress-strain curves.
#pragma once

#include <string>

#include "loom/curves.hpp"

namespace loom::gnatv {

struct MaterialData {
  std::string path;             ///< the file that was read
  std::string name;             ///< optional "name" in the file
  double areal_density = 0;     ///< kg/m^2
  Curve weft, warp, shear;      ///< eps_uu, eps_vv, eps_uv, in the model's measure (green_pk2)
  /// What each curve in the file measures ("nominal" or "green_pk2"); nominal samples are
  /// converted exactly on load (docs/NUMERICS.md, "What a curve measures").
  std::string weft_measure, warp_measure, shear_measure;
};

/// Read and check a material file; stresses are multiplied by stress_scale. Throws
/// InputError naming the file and line for a missing file, missing keys, a curve with
/// fewer than 2 samples, NaN/Inf, a strain grid that does not increase, or a curve whose
/// stress at zero strain is not zero (the rest state must be stress free), a curve without
/// `measure`, strains beyond 1 (percent), or a stress that decreases with strain.
MaterialData read_material_file(const std::string& path, CurveInterpolation kind, double stress_scale = 1.0);

}  // namespace loom::gnatv

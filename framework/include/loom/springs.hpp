// A set of springs, exposed by spring materials (mass_spring) to integrators that
// work per spring (harmonic_oscillation).
#pragma once

#include <cstdint>
#include <vector>

#include "loom/common.hpp"

namespace loom {

enum class SpringClass : std::uint8_t { Structural = 0, Shear = 1, Bend = 2, Edge = 3 };

struct SpringSet {
  std::vector<Index> i, j;              ///< endpoints
  std::vector<double> rest_length;      ///< l0 > 0
  std::vector<double> stiffness;        ///< k (N/m)
  std::vector<double> damping;          ///< axial damper c (N s/m), 0 for none
  std::vector<SpringClass> kind;

  Index size() const { return static_cast<Index>(i.size()); }
  void add(Index a, Index b, double l0, double k, double c, SpringClass cls) {
    i.push_back(a); j.push_back(b); rest_length.push_back(l0);
    stiffness.push_back(k); damping.push_back(c); kind.push_back(cls);
  }
};

}  // namespace loom

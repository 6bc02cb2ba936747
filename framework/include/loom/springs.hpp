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

/// The springs of s with every group of springs on the same two endpoints (either order) merged
/// into one: stiffnesses and dampers added, the rest length the stiffness-weighted mean (kept
/// exactly when the group's rest lengths are equal), endpoints and kind those of the group's
/// first spring, in the order of each group's first spring. For a force-only use (symplectic
/// Euler, RK4) the merged spring's force equals the group's sum in exact arithmetic at every
/// length and velocity: (k1 + k2)(l - l0) = k1 (l - l1) + k2 (l - l2) with l0 = (k1 l1 + k2 l2) /
/// (k1 + k2), and the dampers act along the same axis. Not for harmonic_oscillation, whose
/// per-spring constants are not linear in k: it adds its members' constants instead
/// (build_ho_springs, HoMerge). merged (optional): how many springs were folded away.
SpringSet merge_duplicate_springs(const SpringSet& s, Index* merged = nullptr);

}  // namespace loom

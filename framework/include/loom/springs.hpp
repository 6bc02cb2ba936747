// A set of springs, exposed by spring materials (mass_spring) to integrators that
// work per spring (harmonic_oscillation).
#pragma once

#include <array>
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

/// Key of the vertex pair (a, b), the same for (b, a): the lower index in the high 32 bits.
inline std::uint64_t spring_pair_key(Index a, Index b) {
  const auto lo = static_cast<std::uint32_t>(a < b ? a : b);
  const auto hi = static_cast<std::uint32_t>(a < b ? b : a);
  return (std::uint64_t{lo} << 32) | hi;
}

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

/// The springs of a set grouped by vertex pair, for an integrator whose per-spring constants are
/// not linear in the stiffness (harmonic_oscillation, CPU and CUDA): it merges a group by adding
/// its members' constants, so it keeps the members.
struct SpringPairGroups {
  /// One spring per merged group (its first member's endpoints and kind, stiffnesses and dampers
  /// added, the rest length the first's when the members agree, else the stiffness-weighted mean)
  /// or per spring kept as it is, in the order of each group's first spring.
  SpringSet springs;
  std::vector<Index> group;   ///< per spring of `springs`: its merged group, or -1
  std::vector<Index> first;   ///< members of group g: [first[g], first[g + 1]) (size groups + 1)
  std::vector<double> l0, k, c;   ///< per member: rest length, stiffness, damper
  Index merged = 0;           ///< springs folded away (s.size() - springs.size())
};

/// Groups the springs of s on the same two vertices (either order). equal_rest_length_only: a
/// group whose rest lengths differ is kept as separate springs. Memory beyond the output: about
/// 17 bytes per spring while it runs.
SpringPairGroups group_springs_by_pair(const SpringSet& s, bool equal_rest_length_only);

/// Rest length and the four constants of merged group g of `groups` (first, l0 and member
/// constants from member(m) -> {kx, kv, ex, ev}): the constants added, the rest length the
/// members' when they agree, otherwise the kx-weighted mean (sum kx_m (l - l0_m) = kx (l - l0)
/// at every length). equal: set to whether the members' rest lengths agree.
template <class Member>
std::array<double, 5> pair_group_constants(const std::vector<Index>& first, const std::vector<double>& l0, Index g,
                                           Member member, bool& equal) {
  std::array<double, 5> r{0, 0, 0, 0, 0};
  const Index b = first[g], e = first[g + 1];
  double kxl = 0;
  equal = true;
  for (Index m = b; m < e; ++m) {
    const std::array<double, 4> c = member(m);
    for (int a = 0; a < 4; ++a) r[1 + a] += c[a];
    kxl += c[0] * l0[m];
    equal = equal && l0[m] == l0[b];
  }
  r[0] = equal || r[1] == 0.0 ? l0[b] : kxl / r[1];
  return r;
}

}  // namespace loom

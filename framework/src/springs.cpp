#include "loom/springs.hpp"

#include <algorithm>
#include <cstdint>
#include <unordered_map>

namespace loom {

SpringSet merge_duplicate_springs(const SpringSet& s, Index* merged) {
  const Index S = s.size();
  std::unordered_map<std::uint64_t, Index> slot_of;   // endpoint pair (lower, upper) -> merged spring
  slot_of.reserve(static_cast<std::size_t>(S));
  SpringSet out;
  std::vector<double> kl;            // sum of k * l0 per merged spring
  std::vector<std::uint8_t> same;    // every spring merged into it has its first spring's rest length
  for (Index q = 0; q < S; ++q) {
    const auto lo = static_cast<std::uint32_t>(std::min(s.i[q], s.j[q]));
    const auto hi = static_cast<std::uint32_t>(std::max(s.i[q], s.j[q]));
    const auto [it, first] = slot_of.try_emplace((std::uint64_t{lo} << 32) | hi, out.size());
    if (first) {   // the group's first spring, in the input order
      out.add(s.i[q], s.j[q], s.rest_length[q], s.stiffness[q], s.damping[q], s.kind[q]);
      kl.push_back(s.stiffness[q] * s.rest_length[q]);
      same.push_back(1);
      continue;
    }
    const Index m = it->second;
    out.stiffness[m] += s.stiffness[q];
    out.damping[m] += s.damping[q];
    kl[m] += s.stiffness[q] * s.rest_length[q];
    if (s.rest_length[q] != out.rest_length[m]) same[m] = 0;
  }
  // Equal rest lengths stay exact; otherwise the stiffness-weighted mean, which gives the same
  // force (sum k_a) l - sum k_a l_a at every length l.
  for (Index m = 0; m < out.size(); ++m)
    if (!same[m] && out.stiffness[m] > 0) out.rest_length[m] = kl[m] / out.stiffness[m];
  if (merged) *merged = S - out.size();
  return out;
}

}  // namespace loom

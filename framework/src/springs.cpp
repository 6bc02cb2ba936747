#include "loom/springs.hpp"

#include <algorithm>
#include <cstdint>
#include <unordered_map>
#include <utility>

namespace loom {

SpringSet merge_duplicate_springs(const SpringSet& s, Index* merged) {
  const Index S = s.size();
  std::unordered_map<std::uint64_t, Index> slot_of;   // endpoint pair (lower, upper) -> merged spring
  slot_of.reserve(static_cast<std::size_t>(S));
  SpringSet out;
  std::vector<double> kl;            // sum of k * l0 per merged spring
  std::vector<std::uint8_t> same;    // every spring merged into it has its first spring's rest length
  for (Index q = 0; q < S; ++q) {
    const auto [it, first] = slot_of.try_emplace(spring_pair_key(s.i[q], s.j[q]), out.size());
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

SpringPairGroups group_springs_by_pair(const SpringSet& set, bool equal_rest_length_only) {
  const Index S = set.size();
  std::vector<Index> next(static_cast<std::size_t>(S), -1);   // the next spring on the same pair
  {
    std::vector<std::pair<std::uint64_t, Index>> by_pair(static_cast<std::size_t>(S));
    for (Index q = 0; q < S; ++q) by_pair[q] = {spring_pair_key(set.i[q], set.j[q]), q};
    std::sort(by_pair.begin(), by_pair.end());
    for (Index t = 0; t + 1 < S; ++t)
      if (by_pair[t].first == by_pair[t + 1].first) next[by_pair[t].second] = by_pair[t + 1].second;
  }
  SpringPairGroups out;
  std::vector<std::uint8_t> taken(static_cast<std::size_t>(S), 0);
  out.first.assign(1, 0);
  for (Index q = 0; q < S; ++q) {
    if (taken[q]) continue;
    bool equal = true;
    for (Index m = q; m >= 0; m = next[m]) equal = equal && set.rest_length[m] == set.rest_length[q];
    if (next[q] < 0 || (equal_rest_length_only && !equal)) {   // every member kept as it is
      for (Index m = q; m >= 0; m = next[m]) {
        taken[m] = 1;
        out.springs.add(set.i[m], set.j[m], set.rest_length[m], set.stiffness[m], set.damping[m], set.kind[m]);
        out.group.push_back(-1);
      }
      continue;
    }
    double k = 0, c = 0, kl = 0;
    for (Index m = q; m >= 0; m = next[m]) {
      taken[m] = 1;
      k += set.stiffness[m];
      c += set.damping[m];
      kl += set.stiffness[m] * set.rest_length[m];
      out.l0.push_back(set.rest_length[m]);
      out.k.push_back(set.stiffness[m]);
      out.c.push_back(set.damping[m]);
    }
    out.springs.add(set.i[q], set.j[q], equal || k == 0.0 ? set.rest_length[q] : kl / k, k, c, set.kind[q]);
    out.group.push_back(static_cast<Index>(out.first.size()) - 1);
    out.first.push_back(static_cast<Index>(out.l0.size()));
  }
  out.merged = S - out.springs.size();
  return out;
}

}  // namespace loom

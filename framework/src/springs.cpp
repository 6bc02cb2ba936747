#include "loom/springs.hpp"

#include <algorithm>
#include <numeric>

namespace loom {

SpringSet merge_duplicate_springs(const SpringSet& s, Index* merged) {
  const Index S = s.size();
  std::vector<Index> ord(static_cast<std::size_t>(S));
  std::iota(ord.begin(), ord.end(), Index(0));
  auto lo = [&](Index q) { return std::min(s.i[q], s.j[q]); };
  auto hi = [&](Index q) { return std::max(s.i[q], s.j[q]); };
  // Stable: the first spring of each endpoint pair keeps its place, so a set without
  // duplicates comes back in its own order.
  std::stable_sort(ord.begin(), ord.end(), [&](Index a, Index b) {
    return lo(a) != lo(b) ? lo(a) < lo(b) : hi(a) < hi(b);
  });
  // leader[q]: the spring q is merged into (the first of its pair in the input order).
  std::vector<Index> leader(static_cast<std::size_t>(S));
  for (Index r = 0; r < S;) {
    Index e = r + 1;
    while (e < S && lo(ord[e]) == lo(ord[r]) && hi(ord[e]) == hi(ord[r])) ++e;
    for (Index t = r; t < e; ++t) leader[ord[t]] = ord[r];   // stable: ord[r] is the group's first
    r = e;
  }
  SpringSet out;
  std::vector<Index> slot(static_cast<std::size_t>(S), Index(-1));
  std::vector<double> kl;            // sum of k * l0 per merged spring
  std::vector<std::uint8_t> same;    // every spring merged so far has the first one's rest length
  for (Index q = 0; q < S; ++q) {
    const Index L = leader[q];
    if (L == q) {
      slot[q] = out.size();
      out.add(s.i[q], s.j[q], s.rest_length[q], s.stiffness[q], s.damping[q], s.kind[q]);
      kl.push_back(s.stiffness[q] * s.rest_length[q]);
      same.push_back(1);
      continue;
    }
    const Index m = slot[L];
    out.stiffness[m] += s.stiffness[q];
    out.damping[m] += s.damping[q];
    kl[m] += s.stiffness[q] * s.rest_length[q];
    if (s.rest_length[q] != s.rest_length[L]) same[m] = 0;
  }
  // Equal rest lengths stay exact; otherwise the stiffness-weighted mean, which gives the same
  // force (sum k_a) l - sum k_a l_a at every length l.
  for (Index m = 0; m < out.size(); ++m)
    if (!same[m] && out.stiffness[m] > 0) out.rest_length[m] = kl[m] / out.stiffness[m];
  if (merged) *merged = S - out.size();
  return out;
}

}  // namespace loom

// The one vertex -> spring incidence (CSR) of a spring list, built once at set-up: used by
// the spring layouts' gather loops, the reverse Cuthill-McKee order (vertex_order.hpp) and the
// CUDA backend's per-vertex gathers. Host code only; no OpenMP.
#pragma once

#include <cstdint>
#include <span>
#include <stdexcept>
#include <string>
#include <vector>

#include "loom/common.hpp"
#include "loom/springs.hpp"

namespace loom {

/// Per-vertex CSR incidence: the springs at vertex v are entries offsets[v] .. offsets[v+1]-1
/// of spring[] with sign[] = +1 if v is the spring's i endpoint, -1 if it is j. Within a
/// vertex, springs are in increasing index order. Build once; a `#pragma omp parallel for`
/// over vertices then gathers race free (f_v = sum sign * F_s, with F_s the force on i).
struct VertexIncidence {
  std::vector<Index> offsets;       ///< n + 1
  std::vector<Index> spring;        ///< 2 S
  std::vector<std::int8_t> sign;    ///< 2 S

  VertexIncidence() = default;
  VertexIncidence(Index n, std::span<const Index> si, std::span<const Index> sj) { build(n, si, sj); }
  VertexIncidence(Index n, const SpringSet& s) { build(n, s.i, s.j); }

  Index num_vertices() const { return static_cast<Index>(offsets.size()) - 1; }

  void build(Index n, std::span<const Index> si, std::span<const Index> sj) {
    const Index S = static_cast<Index>(si.size());
    offsets.assign(static_cast<std::size_t>(n) + 1, 0);
    for (Index s = 0; s < S; ++s) { ++offsets[si[s] + 1]; ++offsets[sj[s] + 1]; }
    for (Index v = 0; v < n; ++v) offsets[v + 1] += offsets[v];
    spring.resize(2 * static_cast<std::size_t>(S));
    sign.resize(2 * static_cast<std::size_t>(S));
    std::vector<Index> pos(offsets.begin(), offsets.end() - 1);
    for (Index s = 0; s < S; ++s) {
      spring[pos[si[s]]] = s; sign[pos[si[s]]++] = 1;
      spring[pos[sj[s]]] = s; sign[pos[sj[s]]++] = -1;
    }
  }

  /// The other endpoint of entry e (at vertex v): the neighbour across spring[e].
  Index other(std::size_t e, std::span<const Index> si, std::span<const Index> sj) const {
    const auto q = static_cast<std::size_t>(spring[e]);
    return sign[e] > 0 ? sj[q] : si[q];
  }
};

}  // namespace loom

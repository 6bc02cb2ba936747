// SpringLayout: a race-free parallel traversal of a set of springs (header-only).
//
// Problem: a per-spring update that adds to both endpoints (f_i += F, f_j -= F; an HO
// impulse on v_i and v_j; the four Jacobian blocks of a spring) races when two threads
// handle springs that share a vertex.
//
// Layout (built once, O(S + n)):
//   * the vertices 0..n-1 are cut into `parts()` contiguous ranges holding about the same
//     number of springs (a spring is counted at its lower endpoint);
//   * a spring with both endpoints in part p is "interior" to p. Interior springs of
//     different parts share no vertex, so part p's springs run on one thread with plain
//     scatters, no atomics. For meshes numbered row by row (grids, most OBJ files) almost
//     all springs are interior: only springs that cross a cut are left over;
//   * the left-over ("cross") springs are greedily edge-coloured: springs of one colour share
//     no vertex. Few of them (<= kSerialCross) run on one thread; more run colour by colour
//     in parallel.
//   * order() lists the springs in traversal order: part 0's interior springs, part 1's, ...,
//     then the cross springs colour by colour; each range is sorted by lower endpoint, so
//     the gathers of x stream through memory.
//
// Usage:
//   SpringLayout layout(num_vertices, springs.i, springs.j);   // or (n, SpringSet)
//   layout.reorder(springs);   // optional: store the springs in traversal order, then
//                              // order()[k] == k, identity() is true and loops read the
//                              // spring arrays sequentially (what mass_spring does)
//   layout.for_each([&](Index s) { ... });   // s: index into the spring arrays
//   layout.for_each([&](Index v0, Index v1) { /* vertex init of range [v0, v1) */ },
//                   [&](Index s) { ... });
//   layout.for_each_range(init, [&](Index k0, Index k1) { /* springs order()[k], k0 <= k < k1 */ });
//
// for_each contract:
//   * body(s) is called exactly once for every spring s. It may read anything and may write
//     only data that belongs to the endpoints i[s], j[s] (e.g. f[3i..3i+2], f[3j..3j+2],
//     matrix blocks in block rows i and j). Writes to per-spring data of s are fine too.
//   * the two-argument form first calls init(v0, v1) for each part's vertex range (on the
//     thread that then runs that part's interior springs), and every init completes before
//     any cross spring runs: use it to zero an accumulator (f = 0) in the same pass.
//     The ranges cover 0..n-1 exactly once.
//   * the parallel skeleton is traverse_parts (loom/traversal.hpp), shared by every plugin.
//   * call it from outside an OpenMP parallel region: it opens one (the team is
//     omp_get_max_threads(), or whatever the caller set), unless the layout has fewer than
//     kParallelMin springs: small ones run on the calling thread. Nested inside a parallel
//     region it runs on that one thread, still correctly. Any thread count is fine: parts
//     are handed out with schedule(static). No allocation, no virtual call; body is inlined.
//   * results that are summed per vertex are deterministic for a fixed layout (the order of
//     additions into each vertex does not depend on the thread count).
//
// VertexIncidence (below) is the alternative "gather" layout: a CSR list vertex -> (spring,
// sign), sign = +1 when the vertex is the spring's i, -1 when it is j. A per-vertex loop over
// it writes only its own vertex (each spring is then evaluated twice, once per endpoint).
#pragma once

#include <algorithm>
#include <bit>
#include <cstdint>
#include <numeric>
#include <span>
#include <stdexcept>
#include <string>
#include <vector>

#ifdef _OPENMP
#include <omp.h>
#endif

#include "loom/common.hpp"
#include "loom/incidence.hpp"
#include "loom/springs.hpp"
#include "loom/traversal.hpp"

namespace loom {

class SpringLayout {
 public:
  /// Cross springs up to this count run on one thread (cheaper than a barrier per colour).
  static constexpr Index kSerialCross = 16384;
  /// Layouts with fewer springs run on the calling thread (a parallel region costs more).
  static constexpr Index kParallelMin = kParallelMinSprings;  // the rule in common.hpp

  SpringLayout() = default;

  /// Build for springs (i[s], j[s]) over num_vertices vertices. parts <= 0 chooses
  /// max(omp_get_max_threads(), omp_get_num_procs()). Throws std::invalid_argument for
  /// endpoints out of range or i[s] == j[s].
  SpringLayout(Index num_vertices, std::span<const Index> i, std::span<const Index> j, int parts = 0) {
    build(num_vertices, i, j, parts);
  }
  SpringLayout(Index num_vertices, const SpringSet& s, int parts = 0) {
    build(num_vertices, s.i, s.j, parts);
  }

  Index num_vertices() const { return n_; }
  Index num_springs() const { return static_cast<Index>(order_.size()); }
  int parts() const { return static_cast<int>(vertex_begin_.size()) - 1; }
  /// Springs in traversal order (a permutation of 0..S-1).
  std::span<const Index> order() const { return order_; }
  bool identity() const { return identity_; }
  /// Vertex range [begin, end) of part p.
  Index part_vertex_begin(int p) const { return vertex_begin_[p]; }
  Index part_vertex_end(int p) const { return vertex_begin_[p + 1]; }
  /// Range [begin, end) of positions in order() holding part p's interior springs.
  Index part_spring_begin(int p) const { return spring_begin_[p]; }
  Index part_spring_end(int p) const { return spring_begin_[p + 1]; }
  /// Springs that cross a part boundary, and the colours they were split into.
  Index num_cross() const { return num_springs() - spring_begin_.back(); }
  int num_colours() const { return static_cast<int>(colour_begin_.size()) - 1; }
  /// Range of positions in order() holding cross colour c.
  Index colour_begin(int c) const { return colour_begin_[c]; }
  Index colour_end(int c) const { return colour_begin_[c + 1]; }
  bool cross_serial() const { return num_cross() <= kSerialCross; }

  /// a_new[k] = a_old[order()[k]] (a has one entry per spring).
  template <class T>
  void permute(std::vector<T>& a) const {
    if (identity_) return;
    std::vector<T> out(a.size());
    for (std::size_t k = 0; k < order_.size(); ++k) out[k] = a[static_cast<std::size_t>(order_[k])];
    a.swap(out);
  }

  /// Store the springs of s (the set this layout was built from) in traversal order. After
  /// this, order()[k] == k and identity() is true; the partition and colours are unchanged.
  void reorder(SpringSet& s) {
    if (s.size() != num_springs()) throw std::invalid_argument("SpringLayout::reorder: wrong spring set");
    permute(s.i); permute(s.j); permute(s.rest_length); permute(s.stiffness); permute(s.damping);
    permute(s.kind);
    std::iota(order_.begin(), order_.end(), Index(0));
    identity_ = true;
  }

  /// Run body(s) for every spring, race free (see the contract at the top of this file).
  template <class Body>
  void for_each(Body&& body) const {
    for_each([](Index, Index) {}, body);
  }

  /// Range form, for bodies that keep state along a run of springs (e.g. accumulate the
  /// force of a shared endpoint in registers): range(k0, k1) must handle the springs
  /// order()[k], k0 <= k < k1, under the same rules as body(s). Ranges run at the same time
  /// share no vertex. Each part's interior springs come as one range, the serial cross
  /// springs as one range, a parallel colour as chunks of kChunk; the ranges do not depend
  /// on the thread count.
  static constexpr Index kChunk = kTraversalChunk;
  template <class Init, class Range>
  void for_each_range(Init&& init, Range&& range) const {
    if (parts() <= 0) return;
    traverse_parts(
        *this, num_springs() >= kParallelMin,
        [&](int p) {
          init(vertex_begin_[p], vertex_begin_[p + 1]);
          range(spring_begin_[p], spring_begin_[p + 1]);
        },
        range);
  }

  template <class Init, class Body>
  void for_each(Init&& init, Body&& body) const {
    if (parts() <= 0) return;
    traverse_parts(
        *this, num_springs() >= kParallelMin,
        [&](int p) {
          init(vertex_begin_[p], vertex_begin_[p + 1]);
          run(spring_begin_[p], spring_begin_[p + 1], body);
        },
        [&](Index k0, Index k1) { run(k0, k1, body); });
  }

 private:
  template <class Body>
  void run(Index b, Index e, Body& body) const {
    if (identity_) {
      for (Index k = b; k < e; ++k) body(k);
    } else {
      for (Index k = b; k < e; ++k) body(order_[k]);
    }
  }

  void build(Index n, std::span<const Index> si, std::span<const Index> sj, int parts) {
    if (si.size() != sj.size()) throw std::invalid_argument("SpringLayout: i and j differ in size");
    if (n < 0) throw std::invalid_argument("SpringLayout: negative vertex count");
    const Index S = static_cast<Index>(si.size());
    n_ = n;
    if (parts <= 0) {
#ifdef _OPENMP
      parts = std::max(omp_get_max_threads(), omp_get_num_procs());
#else
      parts = 1;
#endif
    }
    parts = std::max(1, std::min<int>(parts, std::max<Index>(n, 1)));
    std::vector<Index> lo(static_cast<std::size_t>(S)), hi(static_cast<std::size_t>(S));
    std::vector<Index> count(static_cast<std::size_t>(n) + 1, 0);
    for (Index s = 0; s < S; ++s) {
      const Index a = si[s], b = sj[s];
      if (a < 0 || b < 0 || a >= n || b >= n)
        throw std::invalid_argument("SpringLayout: spring " + std::to_string(s) + " has an endpoint out of range");
      if (a == b) throw std::invalid_argument("SpringLayout: spring " + std::to_string(s) + " joins a vertex to itself");
      lo[s] = std::min(a, b);
      hi[s] = std::max(a, b);
      ++count[static_cast<std::size_t>(lo[s]) + 1];
    }
    // Springs by lower endpoint (counting sort; stable, so the original order breaks ties).
    for (Index v = 0; v < n; ++v) count[v + 1] += count[v];
    std::vector<Index> by_lo(static_cast<std::size_t>(S));
    {
      std::vector<Index> pos(count.begin(), count.end() - 1);
      for (Index s = 0; s < S; ++s) by_lo[pos[lo[s]]++] = s;
    }
    // Vertex cuts: equal numbers of springs (by lower endpoint) per part.
    vertex_begin_.assign(static_cast<std::size_t>(parts) + 1, 0);
    vertex_begin_[parts] = n;
    for (int p = 1; p < parts; ++p) {
      const Index target = static_cast<Index>((static_cast<std::int64_t>(S) * p) / parts);
      Index v = static_cast<Index>(std::lower_bound(count.begin(), count.end(), target) - count.begin());
      if (S == 0) v = static_cast<Index>((static_cast<std::int64_t>(n) * p) / parts);
      vertex_begin_[p] = std::clamp(v, vertex_begin_[p - 1], n);
    }
    std::vector<int> part_of(static_cast<std::size_t>(n));
    for (int p = 0; p < parts; ++p)
      for (Index v = vertex_begin_[p]; v < vertex_begin_[p + 1]; ++v) part_of[v] = p;

    order_.clear();
    order_.reserve(static_cast<std::size_t>(S));
    spring_begin_.assign(static_cast<std::size_t>(parts) + 1, 0);
    std::vector<Index> cross;
    // by_lo is sorted by lower endpoint, and parts are contiguous vertex ranges, so walking
    // it once emits part 0's interior springs, then part 1's, ...
    for (Index s : by_lo) {
      if (part_of[lo[s]] == part_of[hi[s]]) order_.push_back(s);
      else cross.push_back(s);
    }
    {
      Index k = 0;
      for (int p = 0; p < parts; ++p) {
        spring_begin_[p] = k;
        while (k < static_cast<Index>(order_.size()) && part_of[lo[order_[k]]] == p) ++k;
      }
      spring_begin_[parts] = k;
    }
    // Greedy edge colouring of the cross springs (in lower-endpoint order).
    colour_begin_.assign(1, static_cast<Index>(order_.size()));
    if (!cross.empty()) {
      std::vector<Index> deg(static_cast<std::size_t>(n), 0);
      for (Index s : cross) { ++deg[lo[s]]; ++deg[hi[s]]; }
      const Index maxdeg = *std::max_element(deg.begin(), deg.end());
      const std::size_t words = static_cast<std::size_t>(2 * maxdeg) / 64 + 1;
      std::vector<std::uint64_t> used(static_cast<std::size_t>(n) * words, 0);
      std::vector<int> colour(cross.size());
      int ncol = 0;
      for (std::size_t q = 0; q < cross.size(); ++q) {
        const std::uint64_t* ua = &used[static_cast<std::size_t>(lo[cross[q]]) * words];
        const std::uint64_t* ub = &used[static_cast<std::size_t>(hi[cross[q]]) * words];
        int c = 0;
        for (std::size_t w = 0; w < words; ++w) {
          const std::uint64_t free_bits = ~(ua[w] | ub[w]);
          if (free_bits) { c = static_cast<int>(64 * w) + std::countr_zero(free_bits); break; }
        }
        colour[q] = c;
        ncol = std::max(ncol, c + 1);
        used[static_cast<std::size_t>(lo[cross[q]]) * words + c / 64] |= std::uint64_t(1) << (c % 64);
        used[static_cast<std::size_t>(hi[cross[q]]) * words + c / 64] |= std::uint64_t(1) << (c % 64);
      }
      for (int c = 0; c < ncol; ++c) {
        for (std::size_t q = 0; q < cross.size(); ++q)
          if (colour[q] == c) order_.push_back(cross[q]);
        colour_begin_.push_back(static_cast<Index>(order_.size()));
      }
    }
    identity_ = true;
    for (Index k = 0; k < S; ++k)
      if (order_[k] != k) { identity_ = false; break; }
  }

  Index n_ = 0;
  std::vector<Index> order_;
  std::vector<Index> vertex_begin_{0};
  std::vector<Index> spring_begin_{0};
  std::vector<Index> colour_begin_{0};
  bool identity_ = true;
};


}  // namespace loom

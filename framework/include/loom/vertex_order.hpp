// Vertex orders that give spring loops locality (header-only).
//
// A spring loop gathers the positions and velocities of both endpoints. When the mesh numbers
// its vertices so that a spring's endpoints are far apart (an OBJ file written in an arbitrary
// order, a mesh from a generator that shuffles), most gathers miss the caches. A reverse
// Cuthill-McKee order (RCM) numbers the vertices breadth first from a peripheral vertex, so the
// endpoints of every spring get nearby numbers (small bandwidth), computed once in O(S log d).
//
// A plugin that uses an order keeps its own copies of the vertex data in the internal order
// (gather before its loops, scatter after): everything the user sees (scene state, output,
// pins, statistics) stays in the user's numbering. See docs/ARCHITECTURE.md "Threads".
//
//   VertexOrder o = rcm_order(n, i, j);       // o.perm[k]: user vertex of internal vertex k
//   gather_vertices<3>(o, x_user, x_int);     // x_int[3k + e] = x_user[3 perm[k] + e]
//   scatter_vertices<3>(o, x_int, x_user);    // the inverse
//   gather_state(o, x, v, xi, vi); scatter_state(o, xi, vi, x, v);   // both arrays, one pass
//   mean_spring_span(i, j, &o)                // mean |i' - j'| under the order (locality)
#pragma once

#include <algorithm>
#include <array>
#include <cstdint>
#include <cstdlib>
#include <span>
#include <stdexcept>
#include <string>
#include <vector>

#include "loom/common.hpp"
#include "loom/incidence.hpp"
#include "loom/traversal.hpp"

namespace loom {

/// A vertex permutation: perm[k] is the user vertex stored at internal position k, inv its
/// inverse (inv[perm[k]] == k). Empty: the identity.
struct VertexOrder {
  std::vector<Index> perm;
  std::vector<Index> inv;
  bool identity() const { return perm.empty(); }
  Index to_internal(Index user) const { return identity() ? user : inv[static_cast<std::size_t>(user)]; }
};

/// Vertex adjacency of a spring list in CSR form (duplicates kept; self-loops refused): the
/// neighbours across the springs of the one incidence list (incidence.hpp), in spring order.
struct VertexAdjacency {
  std::vector<Index> offsets, nbr;
  VertexAdjacency(Index n, std::span<const Index> si, std::span<const Index> sj) {
    if (si.size() != sj.size()) throw std::invalid_argument("vertex order: i and j differ in size");
    for (std::size_t s = 0; s < si.size(); ++s)
      if (si[s] < 0 || sj[s] < 0 || si[s] >= n || sj[s] >= n)
        throw std::invalid_argument("vertex order: spring " + std::to_string(s) + " has an endpoint out of range");
    VertexIncidence inc(n, si, sj);
    nbr.resize(inc.spring.size());
    for (std::size_t e = 0; e < nbr.size(); ++e) nbr[e] = inc.other(e, si, sj);
    offsets = std::move(inc.offsets);
  }
  Index degree(Index v) const { return offsets[v + 1] - offsets[v]; }
};

/// Reverse Cuthill-McKee order of the graph of springs (i[s], j[s]) over n vertices. Each
/// connected component starts from a pseudo-peripheral vertex (George & Liu: repeated
/// breadth-first searches from the last level's vertex of least degree); neighbours are visited
/// in order of increasing degree, ties by user index, so the order is deterministic. Components
/// come in order of their lowest user vertex; isolated vertices keep their relative order.
inline VertexOrder rcm_order(Index n, std::span<const Index> si, std::span<const Index> sj) {
  VertexOrder o;
  if (n <= 0) return o;
  const VertexAdjacency A(n, si, sj);
  std::vector<Index> order;
  order.reserve(static_cast<std::size_t>(n));
  std::vector<Index> level(static_cast<std::size_t>(n), -1);   // BFS scratch (component search)
  std::vector<char> placed(static_cast<std::size_t>(n), 0);
  std::vector<Index> queue;
  queue.reserve(static_cast<std::size_t>(n));
  std::vector<Index> nb;
  // BFS from r over unplaced vertices; fills queue with the component, returns its depth.
  auto bfs_levels = [&](Index r) {
    queue.clear();
    queue.push_back(r);
    level[r] = 0;
    Index depth = 0;
    for (std::size_t h = 0; h < queue.size(); ++h) {
      const Index u = queue[h];
      for (Index e = A.offsets[u]; e < A.offsets[u + 1]; ++e) {
        const Index w = A.nbr[static_cast<std::size_t>(e)];
        if (placed[w] || level[w] >= 0) continue;
        level[w] = level[u] + 1;
        depth = std::max(depth, level[w]);
        queue.push_back(w);
      }
    }
    return depth;
  };
  auto reset_levels = [&] {
    for (Index u : queue) level[u] = -1;
  };
  for (Index seed = 0; seed < n; ++seed) {
    if (placed[seed]) continue;
    // pseudo-peripheral start: at most a few sweeps
    Index root = seed;
    Index depth = bfs_levels(root);
    for (int it = 0; it < 8; ++it) {
      Index best = -1;
      for (Index u : queue)
        if (level[u] == depth && (best < 0 || A.degree(u) < A.degree(best) || (A.degree(u) == A.degree(best) && u < best)))
          best = u;
      reset_levels();
      const Index d2 = bfs_levels(best);
      if (d2 <= depth) {
        reset_levels();
        if (d2 == depth) root = best;
        break;
      }
      root = best;
      depth = d2;
      if (it == 7) reset_levels();
    }
    // Cuthill-McKee from root
    const std::size_t start = order.size();
    order.push_back(root);
    placed[root] = 1;
    for (std::size_t h = start; h < order.size(); ++h) {
      const Index u = order[h];
      nb.clear();
      for (Index e = A.offsets[u]; e < A.offsets[u + 1]; ++e) {
        const Index w = A.nbr[static_cast<std::size_t>(e)];
        if (!placed[w]) {
          placed[w] = 1;
          nb.push_back(w);
        }
      }
      std::sort(nb.begin(), nb.end(), [&](Index a, Index b) {
        return A.degree(a) != A.degree(b) ? A.degree(a) < A.degree(b) : a < b;
      });
      order.insert(order.end(), nb.begin(), nb.end());
    }
  }
  std::reverse(order.begin(), order.end());
  o.perm = std::move(order);
  o.inv.assign(static_cast<std::size_t>(n), 0);
  for (Index k = 0; k < n; ++k) o.inv[o.perm[k]] = k;
  return o;
}

/// The `reorder` key of the plugins that use an order (harmonic_oscillation, symplectic_euler):
/// auto applies the RCM order when reorder_pays, none keeps the user's numbering, rcm always
/// reorders.
enum class ReorderMode { Auto, None, Rcm };
/// auto reorders only meshes of at least this many vertices (below it the positions and
/// velocities, 48 bytes a vertex, stay in a core's L2 cache whatever the order) ...
constexpr Index kReorderMinVertices = 16384;
/// ... and only when the RCM order shrinks the mean spring span |i - j| by this factor or more.
constexpr double kReorderMinGain = 4.0;
inline bool reorder_pays(Index n, double span_user, double span_rcm) {
  return n >= kReorderMinVertices && span_user >= kReorderMinGain * span_rcm;
}
/// "auto" | "none" | "rcm" (validated by the plugin's ParamSpec); anything else is auto.
inline ReorderMode parse_reorder_mode(const std::string& s) {
  return s == "none" ? ReorderMode::None : s == "rcm" ? ReorderMode::Rcm : ReorderMode::Auto;
}

inline double mean_spring_span(std::span<const Index> si, std::span<const Index> sj, const VertexOrder* o = nullptr);

/// The order mode gives for springs (i, j) over n vertices: identity, or the RCM order.
inline VertexOrder choose_vertex_order(ReorderMode mode, Index n, std::span<const Index> si,
                                       std::span<const Index> sj) {
  if (mode == ReorderMode::None || n <= 0) return {};
  VertexOrder rcm = rcm_order(n, si, sj);
  if (mode == ReorderMode::Rcm || reorder_pays(n, mean_spring_span(si, sj, nullptr), mean_spring_span(si, sj, &rcm)))
    return rcm;
  return {};
}

/// Mean |i - j| over the springs under order o (nullptr or identity: the user numbering).
inline double mean_spring_span(std::span<const Index> si, std::span<const Index> sj, const VertexOrder* o) {
  if (si.empty()) return 0.0;
  double sum = 0;
  const bool id = !o || o->identity();
  for (std::size_t s = 0; s < si.size(); ++s) {
    const Index a = id ? si[s] : o->inv[si[s]], b = id ? sj[s] : o->inv[sj[s]];
    sum += std::abs(static_cast<double>(a) - static_cast<double>(b));
  }
  return sum / static_cast<double>(si.size());
}

namespace detail {

// The one permuting copy: for each of the `Arrays` (in, out) pairs, in one pass (one parallel
// region), D values per vertex between the user's numbering and the internal one; ToUser false
// gathers (out[D k + e] = in[D perm[k] + e]), true scatters (out[D perm[k] + e] = in[D k + e]).
template <int D, bool ToUser, std::size_t Arrays, class T, class U>
void permute_vertices(const VertexOrder& o, const std::array<const U*, Arrays>& in, const std::array<T*, Arrays>& out) {
  const Index n = static_cast<Index>(o.perm.size());
  const Index* P = o.perm.data();
  for_vertex_ranges(n, [=](Index v0, Index v1) {
    for (Index k = v0; k < v1; ++k) {
      const std::size_t user = static_cast<std::size_t>(D) * static_cast<std::size_t>(P[k]);
      const std::size_t internal = static_cast<std::size_t>(D) * static_cast<std::size_t>(k);
      const std::size_t from = ToUser ? internal : user, to = ToUser ? user : internal;
      for (std::size_t j = 0; j < Arrays; ++j)
        for (int e = 0; e < D; ++e) out[j][to + e] = static_cast<T>(in[j][from + e]);
    }
  });
}

}  // namespace detail

/// out[D k + e] = in[D perm[k] + e] (user -> internal), converting the scalar if U != T.
template <int D, class T, class U>
void gather_vertices(const VertexOrder& o, const U* in, T* out) {
  detail::permute_vertices<D, false, 1, T, U>(o, {in}, {out});
}

/// out[D perm[k] + e] = in[D k + e] (internal -> user).
template <int D, class T, class U>
void scatter_vertices(const VertexOrder& o, const U* in, T* out) {
  detail::permute_vertices<D, true, 1, T, U>(o, {in}, {out});
}

/// Positions and velocities (3 per vertex) user -> internal, in one pass (one parallel region).
template <class T, class U>
void gather_state(const VertexOrder& o, const U* x, const U* v, T* xo, T* vo) {
  detail::permute_vertices<3, false, 2, T, U>(o, {x, v}, {xo, vo});
}

/// Positions and velocities internal -> user, in one pass.
template <class T, class U>
void scatter_state(const VertexOrder& o, const U* x, const U* v, T* xo, T* vo) {
  detail::permute_vertices<3, true, 2, T, U>(o, {x, v}, {xo, vo});
}

}  // namespace loom

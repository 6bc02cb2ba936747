// SpringSweep: the force pass of a spring network fused with the per-vertex update of an
// explicit step (header-only). Used by symplectic_euler and rk4 when the material is a spring
// network (Material::springs() is not null: the material's forces are exactly its springs').
//
// Layout (built once): the springs in SpringLayout traversal order (loom/spring_layout.hpp),
// lower endpoint first, as structure of arrays: 32-bit endpoints i, j and the per-spring
// constants k, l0 (and c when some spring is damped), in the scalar T (double, or float for
// the benchmarks' float rows).
//
// forces(x, v, f, fin): ONE parallel region (traverse_parts, loom/traversal.hpp). Each part
// sweeps its interior springs in order of lower endpoint; a vertex q is complete as soon as
// the sweep has passed every spring with lower endpoint q (its other springs have a smaller
// lower endpoint), unless a cross spring touches it. So the sweep calls fin(q, f + 3q) right
// away, while q's data is in cache, and clears f[q]; the vertices touched by cross springs get
// fin after the cross springs. fin may write x[q] and v[q] (the sweep never reads them again in
// this pass). f must be zero on entry and is zero again on return. Per-vertex sums are
// deterministic for a fixed layout (any thread count gives the same bits).
//
// Grouped, windowed sweep (the default when it applies; loom/spring_groups.hpp, the same grouping
// and window as harmonic_oscillation's): each part's interior springs are stored as segments of
// springs (i0 + step r, i0 + step r + off) per block of kSpringGroupBlock (64) vertices; the
// part's live vertices are copied once into a structure-of-arrays window (x, y, z, the force
// sums, and v when some spring is damped), a segment's forces are computed by one vectorised
// loop with unit-stride (or stride-2) loads and no gathers, then added to the window's sums, and
// a vertex is handed to fin from the window as soon as its block is done. Per-spring arithmetic is block_forces' (one sqrt
// and one division per spring); only the order of the additions into a vertex differs from the
// one-spring-at-a-time sweep, so the two agree to rounding (tests/symplectic_euler,
// SymplecticEulerFused.WindowedSweepMatchesPlainSweep). A unit-stride segment whose lower and
// upper ranges are disjoint computes and scatters its forces in one loop
// (sweep_segment_forces_scatter), one whose ranges overlap is scattered in one pass
// (window_segment_scatter_overlap); both give the two passes' bits (fuse, issue 16). Used when grouping pays (segments average
// at least 4 springs) and the window fits (live span <= kSpringWinMaxSpan); build(..., false)
// keeps the plain sweep.
#pragma once

#include <algorithm>
#include <cmath>
#include <cstdint>
#include <limits>
#include <type_traits>
#include <vector>

#include "loom/common.hpp"
#include "loom/kernels/spring.hpp"
#include "loom/spring_groups.hpp"
#include "loom/spring_layout.hpp"
#include "loom/springs.hpp"
#include "loom/traversal.hpp"

namespace loom {

/// The shared part of a spring's force (the arithmetic of SpringSweep::block_forces): d = x_q - x_p,
/// the inverse length il (no compare: l2 + the smallest normal, the same value for l2 > 0) and,
/// damped, du = d . (v_q - v_p). One function for the one-segment and the twin loops, so their
/// bits agree; the twin loops compute it once per endpoint pair.
template <class T, bool Damped>
[[gnu::always_inline]] inline void sweep_spring_geometry(Index p, Index q, const T* __restrict X,
                                                        const T* __restrict Y, const T* __restrict Z,
                                                        const T* __restrict VX, const T* __restrict VY,
                                                        const T* __restrict VZ, T& d0, T& d1, T& d2, T& il, T& du) {
  const T tiny = std::numeric_limits<T>::min();
  d0 = X[q] - X[p];
  d1 = Y[q] - Y[p];
  d2 = Z[q] - Z[p];
  const T l2 = d0 * d0 + d1 * d1 + d2 * d2;
  using std::sqrt;
  il = T(1) / sqrt(l2 + tiny);
  if constexpr (Damped) du = d0 * (VX[q] - VX[p]) + d1 * (VY[q] - VY[p]) + d2 * (VZ[q] - VZ[p]);
}

/// A spring's force scale from the shared part.
template <class T, bool Damped>
[[gnu::always_inline]] inline T sweep_spring_scale(T k, T l0, T c, T il, T du) {
  T sc = k * (T(1) - l0 * il);
  if constexpr (Damped) sc += c * du * il * il;
  return sc;
}

/// Forces of a segment's springs (a + Step r, a + Step r + off), r < len, in window coordinates,
/// into F (3 x Bk, structure of arrays): the arithmetic of SpringSweep::block_forces.
template <class T, bool Damped, int Step, Index Bk>
inline void sweep_segment_forces(Index len, Index a, Index off, const T* __restrict K, const T* __restrict L0,
                                 const T* __restrict C, const T* __restrict X, const T* __restrict Y,
                                 const T* __restrict Z, const T* __restrict VX, const T* __restrict VY,
                                 const T* __restrict VZ, T* __restrict F) {
#pragma omp simd
  for (Index r = 0; r < len; ++r) {
    const Index p = a + Step * r, q = p + off;
    T d0, d1, d2, il, du = T(0);
    sweep_spring_geometry<T, Damped>(p, q, X, Y, Z, VX, VY, VZ, d0, d1, d2, il, du);
    const T sc = sweep_spring_scale<T, Damped>(K[r], L0[r], Damped ? C[r] : T(0), il, du);
    F[r] = sc * d0;
    F[Bk + r] = sc * d1;
    F[2 * Bk + r] = sc * d2;
  }
}

/// sweep_segment_forces and the unit-stride window_segment_scatter in one pass (issue 16), for a
/// segment whose lower and upper slot ranges [a, a + len) and [a + off, a + off + len) are
/// disjoint (off >= len): each slot of FX, FY, FZ gets exactly one addition from the segment, so
/// the sums are the two passes' bit for bit. F still receives the forces: a product that is also
/// stored is never contracted into the scatter's addition (see ho_window_impulses_scatter).
template <class T, bool Damped, Index Bk>
inline void sweep_segment_forces_scatter(Index len, Index a, Index off, const T* __restrict K,
                                         const T* __restrict L0, const T* __restrict C, const T* __restrict X,
                                         const T* __restrict Y, const T* __restrict Z, const T* __restrict VX,
                                         const T* __restrict VY, const T* __restrict VZ, T* __restrict F,
                                         T* __restrict FX, T* __restrict FY, T* __restrict FZ) {
#pragma omp simd
  for (Index r = 0; r < len; ++r) {
    const Index p = a + r, q = p + off;
    T d0, d1, d2, il, du = T(0);
    sweep_spring_geometry<T, Damped>(p, q, X, Y, Z, VX, VY, VZ, d0, d1, d2, il, du);
    const T sc = sweep_spring_scale<T, Damped>(K[r], L0[r], Damped ? C[r] : T(0), il, du);
    const T f0 = sc * d0, f1 = sc * d1, f2 = sc * d2;
    F[r] = f0;
    F[Bk + r] = f1;
    F[2 * Bk + r] = f2;
    FX[p] += f0;
    FY[p] += f1;
    FZ[p] += f2;
    FX[q] -= f0;
    FY[q] -= f1;
    FZ[q] -= f2;
  }
}

/// sweep_segment_forces for a twin pair of segments (SpringSegment::twin: the same endpoints;
/// constants KA, L0A, CA and KB, L0B, CB): d, il (and du) once per endpoint pair, the forces of
/// both springs into FA and FB, each with sweep_segment_forces' operations (the same bits).
template <class T, bool Damped, int Step, Index Bk>
inline void sweep_segment_forces_twin(Index len, Index a, Index off, const T* __restrict KA, const T* __restrict L0A,
                                      const T* __restrict CA, const T* __restrict KB, const T* __restrict L0B,
                                      const T* __restrict CB, const T* __restrict X, const T* __restrict Y,
                                      const T* __restrict Z, const T* __restrict VX, const T* __restrict VY,
                                      const T* __restrict VZ, T* __restrict FA, T* __restrict FB) {
#pragma omp simd
  for (Index r = 0; r < len; ++r) {
    const Index p = a + Step * r, q = p + off;
    T d0, d1, d2, il, du = T(0);
    sweep_spring_geometry<T, Damped>(p, q, X, Y, Z, VX, VY, VZ, d0, d1, d2, il, du);
    const T sa = sweep_spring_scale<T, Damped>(KA[r], L0A[r], Damped ? CA[r] : T(0), il, du);
    const T sb = sweep_spring_scale<T, Damped>(KB[r], L0B[r], Damped ? CB[r] : T(0), il, du);
    FA[r] = sa * d0;
    FA[Bk + r] = sa * d1;
    FA[2 * Bk + r] = sa * d2;
    FB[r] = sb * d0;
    FB[Bk + r] = sb * d1;
    FB[2 * Bk + r] = sb * d2;
  }
}

/// sweep_segment_forces_scatter for a twin pair of unit-stride segments with disjoint lower and
/// upper ranges (off >= len): slot a + r gets + fA, then + fB, slot a + r + off gets - fA, then
/// - fB: the two segments' additions in the order of the two loops run one after the other.
template <class T, bool Damped, Index Bk>
inline void sweep_segment_forces_scatter_twin(Index len, Index a, Index off, const T* __restrict KA,
                                              const T* __restrict L0A, const T* __restrict CA,
                                              const T* __restrict KB, const T* __restrict L0B,
                                              const T* __restrict CB, const T* __restrict X, const T* __restrict Y,
                                              const T* __restrict Z, const T* __restrict VX, const T* __restrict VY,
                                              const T* __restrict VZ, T* __restrict FA, T* __restrict FB,
                                              T* __restrict FX, T* __restrict FY, T* __restrict FZ) {
#pragma omp simd
  for (Index r = 0; r < len; ++r) {
    const Index p = a + r, q = p + off;
    T d0, d1, d2, il, du = T(0);
    sweep_spring_geometry<T, Damped>(p, q, X, Y, Z, VX, VY, VZ, d0, d1, d2, il, du);
    const T sa = sweep_spring_scale<T, Damped>(KA[r], L0A[r], Damped ? CA[r] : T(0), il, du);
    const T sb = sweep_spring_scale<T, Damped>(KB[r], L0B[r], Damped ? CB[r] : T(0), il, du);
    const T a0 = sa * d0, a1 = sa * d1, a2 = sa * d2;
    const T b0 = sb * d0, b1 = sb * d1, b2 = sb * d2;
    FA[r] = a0;
    FA[Bk + r] = a1;
    FA[2 * Bk + r] = a2;
    FB[r] = b0;
    FB[Bk + r] = b1;
    FB[2 * Bk + r] = b2;
    FX[p] = (FX[p] + a0) + b0;
    FY[p] = (FY[p] + a1) + b1;
    FZ[p] = (FZ[p] + a2) + b2;
    FX[q] = (FX[q] - a0) - b0;
    FY[q] = (FY[q] - a1) - b1;
    FZ[q] = (FZ[q] - a2) - b2;
  }
}

/// Help of the key `merge_springs` (SpringSweep::merge_duplicates), declared by symplectic_euler and rk4.
inline constexpr const char* kMergeSpringsHelp =
    "merge springs on the same two vertices into one before stepping (stiffnesses and dampers added, rest "
    "length the stiffness-weighted mean): the same force in exact arithmetic, fewer springs per step (the "
    "kang_cho_table1 stencil doubles almost every spring: about 1.4x faster). false: every spring on its own "
    "(the results before 2026-12-01, bit for bit)";

template <class T>
struct SpringSweep {
  SpringLayout layout;
  std::vector<Index> i, j;       ///< traversal order, i < j
  std::vector<T> k, l0, c;       ///< c empty when no spring is damped
  std::vector<std::uint8_t> is_deferred;   ///< per vertex: touched by a cross spring
  std::vector<Index> deferred;
  Index n = 0;
  /// Blocked sweep: the forces of kSweepBlock springs computed by one vectorised loop (`omp
  /// simd`: gathers of x, v; one sqrt and one division per lane) into a buffer, then scattered.
  /// false (default): one spring at a time, which measured faster on the earlier benchmark
  /// machine (docs/plugins/mass_spring.md); bench table1 times both (SeStep_*_blocked).
  /// (Only for the plain sweep: a grouped sweep ignores it.)
  bool blocked = false;
  static constexpr Index kSweepBlock = 128;
  // Grouped, windowed sweep (loom/spring_groups.hpp): on when grouped (then win_cap > 0).
  bool grouped = false;
  std::vector<SpringSegment> segs;
  std::vector<SpringBlock> blocks;
  std::vector<Index> part_block;
  std::vector<Index> block_need;
  Index win_span = 0, win_cap = 0;
  /// Per part: x, y, z, the three force sums, and vx, vy, vz (damped only), win_cap each.
  static constexpr int kWinArrays = 9;
  mutable std::vector<T> win;
  /// Grouped sweep: forces and scatter in one pass for unit-stride segments whose lower and
  /// upper ranges are disjoint (sweep_segment_forces_scatter), and one scatter pass for those
  /// whose ranges overlap (window_segment_scatter_overlap); the same bits. false: forces, then
  /// two scatter passes for every segment (table1's SeStep_double_unfused row).
  bool fuse = true;
  /// Grouped sweep: a twin pair of segments (SpringSegment::twin: duplicate springs on the same
  /// endpoints) computes d, the inverse length (and du) once per pair (sweep_segment_forces_twin);
  /// the same bits. false: each segment on its own (table1's SeStep_double_notwin row).
  bool twins = true;
  /// Grouped sweep: when fin offers `finalise4` (se_step_springs' SeFinish), the vertices of a
  /// block are handed to it four at a time from the window (vectorised, the same bits as fin);
  /// false: fin one vertex at a time (table1's SeStep_double_scalarfin row, the tests' reference).
  bool block_finalise = true;
  /// build(): springs on the same two endpoints are merged into one first (merge_duplicate_springs,
  /// loom/springs.hpp: exact in real arithmetic for forces, so the results change at rounding only);
  /// false keeps every spring (the twin segments then pair them, with the unmerged bits; the twin
  /// tests and table1's SeStep_double_nomerge row). Set before build().
  static constexpr bool kMergeDuplicatesDefault = true;
  bool merge_duplicates = kMergeDuplicatesDefault;
  Index merged = 0;        ///< springs folded away by the last build()
  Index source_size = 0;   ///< springs in the set given to the last build()

  Index size() const { return static_cast<Index>(i.size()); }
  bool damped() const { return !c.empty(); }
  /// Whether forces() opens a parallel region (the rule of common.hpp, in springs).
  bool parallel() const { return size() >= kParallelMinSprings && traversal_threads() > 1; }

  /// Build from a spring set over nv vertices (any order, either endpoint first).
  /// allow_grouping = false keeps the plain sweep (tests and benchmarks compare the two);
  /// group_block: vertices per block of the grouped sweep (group_springs).
  void build(Index nv, const SpringSet& set, bool allow_grouping = true, Index group_block = kSpringGroupBlock) {
    n = nv;
    source_size = set.size();
    merged = 0;
    SpringSet s = merge_duplicates ? merge_duplicate_springs(set, &merged) : set;
    layout = SpringLayout(nv, s);
    layout.reorder(s);
    const Index S = s.size();
    i.resize(S);
    j.resize(S);
    k.resize(S);
    l0.resize(S);
    bool any_damped = false;
    for (Index q = 0; q < S; ++q) any_damped = any_damped || s.damping[q] != 0.0;
    c.assign(any_damped ? S : 0, T(0));
    for (Index q = 0; q < S; ++q) {
      i[q] = std::min(s.i[q], s.j[q]);   // a spring is symmetric in its endpoints
      j[q] = std::max(s.i[q], s.j[q]);
      k[q] = static_cast<T>(s.stiffness[q]);
      l0[q] = static_cast<T>(s.rest_length[q]);
      if (any_damped) c[q] = static_cast<T>(s.damping[q]);
    }
    group(allow_grouping, group_block);
    is_deferred.assign(static_cast<std::size_t>(nv), 0);
    for (Index q = layout.colour_begin(0); q < S; ++q) is_deferred[i[q]] = is_deferred[j[q]] = 1;
    deferred.clear();
    for (Index v = 0; v < nv; ++v)
      if (is_deferred[v]) deferred.push_back(v);
  }

  /// The same springs in another scalar.
  template <class U>
  void convert_from(const SpringSweep<U>& o) {
    layout = o.layout;
    i = o.i;
    j = o.j;
    k.assign(o.k.begin(), o.k.end());
    l0.assign(o.l0.begin(), o.l0.end());
    c.assign(o.c.begin(), o.c.end());
    is_deferred = o.is_deferred;
    deferred = o.deferred;
    n = o.n;
    blocked = o.blocked;
    grouped = o.grouped;
    segs = o.segs;
    blocks = o.blocks;
    part_block = o.part_block;
    block_need = o.block_need;
    win_span = o.win_span;
    win_cap = o.win_cap;
    win.assign(o.win.size(), T(0));
    fuse = o.fuse;
    twins = o.twins;
    block_finalise = o.block_finalise;
    merge_duplicates = o.merge_duplicates;
    merged = o.merged;
    source_size = o.source_size;
  }

  /// Spring forces at (x, v) accumulated into f, with fin(q, f + 3q) per completed vertex
  /// (see the top of this file). v is read only when some spring is damped.
  template <class Fin>
  void forces(const T* x, const T* v, T* f, Fin&& fin) const {
    if (grouped) {
      damped() ? run_window<true>(x, v, f, fin) : run_window<false>(x, v, f, fin);
      return;
    }
    if (damped())
      blocked ? run<true, true>(x, v, f, fin) : run<true, false>(x, v, f, fin);
    else
      blocked ? run<false, true>(x, v, f, fin) : run<false, false>(x, v, f, fin);
  }

 private:
  /// Store the interior springs grouped (when it pays and the window fits) and plan the window.
  void group(bool allow, Index block) {
    grouped = false;
    segs.clear();
    blocks.clear();
    part_block.clear();
    block_need.clear();
    win_span = win_cap = 0;
    win.clear();
    if (!allow) return;
    SpringGroups g;
    const std::vector<Index> perm = group_springs(layout, i, j, g, block);
    if (!g.grouped) return;
    grouped = true;
    segs = std::move(g.segs);
    blocks = std::move(g.blocks);
    part_block = std::move(g.part_block);
    plan_spring_window(layout, *this);
    if (win_cap == 0) {   // live span too large: keep the plain sweep (springs unpermuted)
      grouped = false;
      segs.clear();
      blocks.clear();
      part_block.clear();
      return;
    }
    apply_spring_perm(perm, i);
    apply_spring_perm(perm, j);
    apply_spring_perm(perm, k);
    apply_spring_perm(perm, l0);
    if (!c.empty()) apply_spring_perm(perm, c);
    win.assign(static_cast<std::size_t>(layout.parts()) * kWinArrays * static_cast<std::size_t>(win_cap), T(0));
  }

  /// The grouped, windowed sweep (see the top of this file).
  template <bool Damped, class Fin>
  void run_window(const T* x, const T* v, T* f, Fin& fin) const {
    constexpr Index Bk = kSpringGroupBlockMax;   // buffer capacity: segments hold at most this many springs
    const Index* I = i.data();
    const Index* J = j.data();
    const T* K = k.data();
    const T* L0 = l0.data();
    const T* C = c.data();
    const std::uint8_t* def = is_deferred.data();
    auto sweep = [&](int p) {
      const Index cap = win_cap;
      T* A[kWinArrays];
      window_arrays(win.data(), p, cap, A);
      T* const X = A[0];
      T* const Y = A[1];
      T* const Z = A[2];
      T* const FX = A[3];
      T* const FY = A[4];
      T* const FZ = A[5];
      T* const VX = A[6];
      T* const VY = A[7];
      T* const VZ = A[8];
      const int narr = Damped ? 9 : 6;
      Index ws = layout.part_vertex_begin(p), fill = ws, qfin = ws;
      alignas(64) T F[3 * Bk];
      alignas(64) T F2[3 * Bk];   // the second segment of a twin pair
      for (Index bk = part_block[p]; bk < part_block[p + 1]; ++bk) {
        const SpringBlock& B = blocks[bk];
        const Index need = block_need[bk];
        window_make_room(A, narr, cap, need, qfin, fill, ws);
        window_fill<T, Damped, false>(x, v, fill, need, ws, X, Y, Z, VX, VY, VZ, FX, FY, FZ, nullptr, nullptr,
                                      nullptr);
        fill = std::max(fill, need);
        for (Index sg = B.seg_begin; sg < B.seg_end; ++sg) {
          const SpringSegment& G = segs[sg];
          const Index a = G.i0 - ws;
          const T* Cg = Damped ? C + G.begin : nullptr;
          if (twins && G.twin) {
            // a twin pair (the next segment has the same endpoints): the shared part once, then
            // each segment's additions in the order of the two segments run one after the other
            const SpringSegment& G2 = segs[++sg];
            const T* Cg2 = Damped ? C + G2.begin : nullptr;
            if (G.step == 1 && fuse && G.off >= G.len) {
              sweep_segment_forces_scatter_twin<T, Damped, Bk>(G.len, a, G.off, K + G.begin, L0 + G.begin, Cg,
                                                               K + G2.begin, L0 + G2.begin, Cg2, X, Y, Z, VX, VY, VZ,
                                                               F, F2, FX, FY, FZ);
            } else if (G.step == 1) {
              sweep_segment_forces_twin<T, Damped, 1, Bk>(G.len, a, G.off, K + G.begin, L0 + G.begin, Cg,
                                                          K + G2.begin, L0 + G2.begin, Cg2, X, Y, Z, VX, VY, VZ, F,
                                                          F2);
              if (fuse && G.off > 0) {   // overlapping ranges: both scatters in one pass
                window_segment_scatter_twin<T, 1, Bk>(G.len, a, G.off, FX, FY, FZ, F, F2);
              } else {
                window_segment_scatter<T, 1, Bk>(G.len, a, G.off, FX, FY, FZ, F);
                window_segment_scatter<T, 1, Bk>(G.len, a, G.off, FX, FY, FZ, F2);
              }
            } else {
              sweep_segment_forces_twin<T, Damped, 2, Bk>(G.len, a, G.off, K + G.begin, L0 + G.begin, Cg,
                                                          K + G2.begin, L0 + G2.begin, Cg2, X, Y, Z, VX, VY, VZ, F,
                                                          F2);
              if (fuse) {   // both scatters in one pass
                window_segment_scatter_twin<T, 2, Bk>(G.len, a, G.off, FX, FY, FZ, F, F2);
              } else {
                window_segment_scatter<T, 2, Bk>(G.len, a, G.off, FX, FY, FZ, F);
                window_segment_scatter<T, 2, Bk>(G.len, a, G.off, FX, FY, FZ, F2);
              }
            }
            continue;
          }
          if (G.step == 1 && fuse && G.off >= G.len) {   // disjoint ranges: one pass
            sweep_segment_forces_scatter<T, Damped, Bk>(G.len, a, G.off, K + G.begin, L0 + G.begin, Cg, X, Y, Z, VX,
                                                        VY, VZ, F, FX, FY, FZ);
          } else if (G.step == 1) {
            sweep_segment_forces<T, Damped, 1, Bk>(G.len, a, G.off, K + G.begin, L0 + G.begin, Cg, X, Y, Z, VX, VY,
                                                   VZ, F);
            if (fuse && G.off > 0)   // overlapping ranges: one scatter pass
              window_segment_scatter_overlap<T, Bk>(G.len, a, G.off, FX, FY, FZ, F);
            else
              window_segment_scatter<T, 1, Bk>(G.len, a, G.off, FX, FY, FZ, F);
          } else {
            sweep_segment_forces<T, Damped, 2, Bk>(G.len, a, G.off, K + G.begin, L0 + G.begin, Cg, X, Y, Z, VX, VY,
                                                   VZ, F);
            window_segment_scatter<T, 2, Bk>(G.len, a, G.off, FX, FY, FZ, F);
          }
        }
        const auto hand_off = [&](Index q) {   // cross springs add to q later: its sums to f
          const Index l = q - ws;
          T* fq = f + 3 * static_cast<std::size_t>(q);
          fq[0] += FX[l];
          fq[1] += FY[l];
          fq[2] += FZ[l];
        };
        if constexpr (requires { fin.finalise4(qfin, qfin, ws, X, Y, Z, VX, VY, VZ, FX, FY, FZ, def); }) {
          // four vertices at a time (deferred ones written back unchanged), then their hand-offs
          if (block_finalise) {
            const Index vend = fin.finalise4(qfin, B.vertex_end, ws, X, Y, Z, Damped ? VX : nullptr,
                                             Damped ? VY : nullptr, Damped ? VZ : nullptr, FX, FY, FZ, def);
            for (; qfin < vend; ++qfin)
              if (def[qfin]) hand_off(qfin);
          }
        }
        for (; qfin < B.vertex_end; ++qfin) {
          const Index l = qfin - ws;
          if (def[qfin]) {
            hand_off(qfin);
          } else {
            const T fq[3] = {FX[l], FY[l], FZ[l]};
            fin(qfin, fq);
          }
        }
      }
    };
    auto cross = [&](Index k0, Index k1) {
      for (Index q = k0; q < k1; ++q) {
        T fi[3];
        one_spring<Damped>(q, I, J, K, L0, C, x, v, fi);
        T* fa = f + 3 * static_cast<std::size_t>(I[q]);
        T* fb = f + 3 * static_cast<std::size_t>(J[q]);
        for (int e = 0; e < 3; ++e) {
          fa[e] += fi[e];
          fb[e] -= fi[e];
        }
      }
    };
    traverse_parts(layout, parallel(), sweep, cross, static_cast<Index>(deferred.size()), [&](Index r) {
      T* fq = f + 3 * static_cast<std::size_t>(deferred[r]);
      fin(deferred[r], static_cast<const T*>(fq));
      fq[0] = fq[1] = fq[2] = T(0);
    });
  }

  template <bool Damped>
  static void one_spring(Index q, const Index* I, const Index* J, const T* K, const T* L0, const T* C, const T* x,
                         const T* v, T fi[3]) {
    const std::size_t a = 3 * static_cast<std::size_t>(I[q]), b = 3 * static_cast<std::size_t>(J[q]);
    if constexpr (Damped)
      kernels::spring_force_damped(x + a, x + b, v + a, v + b, K[q], L0[q], C[q], fi);
    else
      kernels::spring_force(x + a, x + b, K[q], L0[q], fi);
  }

  /// Forces on the lower endpoints of springs [s, s + m) into F (3 per spring), vectorised.
  template <bool Damped>
  static void block_forces(Index m, const Index* __restrict I, const Index* __restrict J, const T* __restrict K,
                           const T* __restrict L0, const T* __restrict C, const T* __restrict x,
                           const T* __restrict v, T* __restrict F) {
#pragma omp simd
    for (Index r = 0; r < m; ++r) {
      const std::size_t a = 3 * static_cast<std::size_t>(I[r]), b = 3 * static_cast<std::size_t>(J[r]);
      const T d0 = x[b] - x[a], d1 = x[b + 1] - x[a + 1], d2 = x[b + 2] - x[a + 2];
      const T l2 = d0 * d0 + d1 * d1 + d2 * d2;
      // kernels::spring_inv_length without a comparison (under the default -ftrapping-math a
      // compare blocks the vectoriser): adding the smallest normal number changes l2 only below
      // 2^52 (double) / 2^23 (float) times it, and a zero-length spring still gets zero force
      // (d = 0 times a finite scale)
      using std::sqrt;
      const T il = T(1) / sqrt(l2 + std::numeric_limits<T>::min());
      T sc = K[r] * (T(1) - L0[r] * il);
      if constexpr (Damped) {
        const T du = d0 * (v[b] - v[a]) + d1 * (v[b + 1] - v[a + 1]) + d2 * (v[b + 2] - v[a + 2]);
        sc += C[r] * du * il * il;
      }
      F[3 * r] = sc * d0;
      F[3 * r + 1] = sc * d1;
      F[3 * r + 2] = sc * d2;
    }
  }

  template <bool Damped, bool Blocked, class Fin>
  void run(const T* x, const T* v, T* f, Fin& fin) const {
    const Index* I = i.data();
    const Index* J = j.data();
    const T* K = k.data();
    const T* L0 = l0.data();
    const T* C = c.data();
    const std::uint8_t* def = is_deferred.data();
    auto finish = [&](Index q) {
      T* fq = f + 3 * static_cast<std::size_t>(q);
      fin(q, fq);
      fq[0] = fq[1] = fq[2] = T(0);
    };
    auto spring = [&](Index q, T fi[3]) { one_spring<Damped>(q, I, J, K, L0, C, x, v, fi); };
    auto sweep_blocked = [&](int p) {
      const Index ve = layout.part_vertex_end(p);
      const Index se = layout.part_spring_end(p);
      Index q = layout.part_vertex_begin(p);
      Index s = layout.part_spring_begin(p);
      alignas(64) T F[3 * kSweepBlock];
      while (s < se) {
        const Index m = std::min<Index>(kSweepBlock, se - s);
        block_forces<Damped>(m, I + s, J + s, K + s, L0 + s, Damped ? C + s : nullptr, x, v, F);
        for (Index r = 0; r < m;) {
          const Index a = I[s + r];
          for (; q < a; ++q)
            if (!def[q]) finish(q);
          T fa[3] = {T(0), T(0), T(0)};
          do {
            T* fb = f + 3 * static_cast<std::size_t>(J[s + r]);
            for (int e = 0; e < 3; ++e) {
              fa[e] += F[3 * r + e];
              fb[e] -= F[3 * r + e];
            }
            ++r;
          } while (r < m && I[s + r] == a);
          T* fp = f + 3 * static_cast<std::size_t>(a);
          for (int e = 0; e < 3; ++e) fp[e] += fa[e];
        }
        s += m;
      }
      for (; q < ve; ++q)
        if (!def[q]) finish(q);
    };
    auto sweep = [&](int p) {
      if constexpr (Blocked) {
        sweep_blocked(p);
        return;
      }
      const Index ve = layout.part_vertex_end(p);
      const Index se = layout.part_spring_end(p);
      Index q = layout.part_vertex_begin(p);
      Index s = layout.part_spring_begin(p);
      while (s < se) {
        const Index a = I[s];
        for (; q < a; ++q)   // every spring of a vertex below a is applied
          if (!def[q]) finish(q);
        // the run of springs with lower endpoint a: its force on a summed in registers
        T fa[3] = {T(0), T(0), T(0)};
        do {
          T fi[3];
          spring(s, fi);
          T* fb = f + 3 * static_cast<std::size_t>(J[s]);
          for (int e = 0; e < 3; ++e) {
            fa[e] += fi[e];
            fb[e] -= fi[e];
          }
          ++s;
        } while (s < se && I[s] == a);
        T* fp = f + 3 * static_cast<std::size_t>(a);
        for (int e = 0; e < 3; ++e) fp[e] += fa[e];
      }
      for (; q < ve; ++q)
        if (!def[q]) finish(q);
    };
    auto cross = [&](Index k0, Index k1) {
      for (Index q = k0; q < k1; ++q) {
        T fi[3];
        spring(q, fi);
        T* fa = f + 3 * static_cast<std::size_t>(I[q]);
        T* fb = f + 3 * static_cast<std::size_t>(J[q]);
        for (int e = 0; e < 3; ++e) {
          fa[e] += fi[e];
          fb[e] -= fi[e];
        }
      }
    };
    traverse_parts(layout, parallel(), sweep, cross, static_cast<Index>(deferred.size()),
                   [&](Index r) { finish(deferred[r]); });
  }
};

/// The per-vertex update of se_step_springs: v += h (w f + g), x += h v for a free vertex (w != 0,
/// as fma(h, fma(w, f, g), v) and fma(h, v, x)); a pinned one (w = 0) moves with its velocity
/// (x += h v where that component of v is not zero: a fixed pin is not touched at all).
/// finalise4 does the same for four vertices at a time from the windowed sweep's copies
/// (SpringSweep::block_finalise), operation for operation (double with AVX2 and FMA), so the
/// same bits; it returns the first vertex it left to operator() (none without AVX2, or in float).
template <class T>
struct SeFinish {
  T* x;
  T* v;
  const T* w;
  T h, g0, g1, g2;

  void operator()(Index q, const T* fq) const {
    const T wi = w[q];
    T* xi = x + 3 * static_cast<std::size_t>(q);
    T* vi = v + 3 * static_cast<std::size_t>(q);
    const T g[3] = {g0, g1, g2};
    if (wi != T(0)) {
      for (int e = 0; e < 3; ++e) {
        vi[e] = fma_(h, fma_(wi, fq[e], g[e]), vi[e]);
        xi[e] = fma_(h, vi[e], xi[e]);
      }
    } else {
      for (int e = 0; e < 3; ++e)
        if (vi[e] != T(0)) xi[e] = fma_(h, vi[e], xi[e]);
    }
  }

  /// Vertices [from, from + 4 m) (m = (to - from) / 4) from the window: positions X, Y, Z (the
  /// user's x until the vertex is finalised), velocities VX, VY, VZ when the sweep copied them
  /// (damped springs; else read from v), force sums FX, FY, FZ; a deferred vertex (cross springs
  /// add to it later) is written back unchanged, its hand-off is the caller's.
  Index finalise4(Index from, Index to, Index ws, const T* X, const T* Y, const T* Z, const T* VX, const T* VY,
                  const T* VZ, const T* FX, const T* FY, const T* FZ, const std::uint8_t* deferred) const {
#if defined(__AVX2__) && defined(__FMA__)
    if constexpr (std::is_same_v<T, double>) {
      const __m256d zero = _mm256_setzero_pd(), hv = _mm256_set1_pd(h);
      const __m256d gv0 = _mm256_set1_pd(g0), gv1 = _mm256_set1_pd(g1), gv2 = _mm256_set1_pd(g2);
      const Index end = from + ((to - from) / 4) * 4;
      for (Index q = from; q < end; q += 4) {
        const Index l = q - ws;
        const std::size_t o = 3 * static_cast<std::size_t>(q);
        const __m256d wq = _mm256_loadu_pd(w + q);
        const __m256d free = _mm256_cmp_pd(wq, zero, _CMP_NEQ_UQ);   // w != 0
        const __m256d keep = lanes_where_zero4(deferred + q);       // not deferred
        const __m256d x0 = _mm256_loadu_pd(X + l), x1 = _mm256_loadu_pd(Y + l), x2 = _mm256_loadu_pd(Z + l);
        __m256d v0, v1, v2;
        if (VX) {
          v0 = _mm256_loadu_pd(VX + l), v1 = _mm256_loadu_pd(VY + l), v2 = _mm256_loadu_pd(VZ + l);
        } else {
          aos3_load4(v + o, v0, v1, v2);
        }
        // free: n = fma(h, fma(w, f, g), v), y = fma(h, n, x); pinned: n = v, y = fma(h, v, x)
        // where v != 0, else x
        const __m256d n0 = _mm256_blendv_pd(
            v0, _mm256_fmadd_pd(hv, _mm256_fmadd_pd(wq, _mm256_loadu_pd(FX + l), gv0), v0), free);
        const __m256d n1 = _mm256_blendv_pd(
            v1, _mm256_fmadd_pd(hv, _mm256_fmadd_pd(wq, _mm256_loadu_pd(FY + l), gv1), v1), free);
        const __m256d n2 = _mm256_blendv_pd(
            v2, _mm256_fmadd_pd(hv, _mm256_fmadd_pd(wq, _mm256_loadu_pd(FZ + l), gv2), v2), free);
        const __m256d y0 = _mm256_blendv_pd(x0, _mm256_fmadd_pd(hv, n0, x0),
                                            _mm256_or_pd(free, _mm256_cmp_pd(n0, zero, _CMP_NEQ_UQ)));
        const __m256d y1 = _mm256_blendv_pd(x1, _mm256_fmadd_pd(hv, n1, x1),
                                            _mm256_or_pd(free, _mm256_cmp_pd(n1, zero, _CMP_NEQ_UQ)));
        const __m256d y2 = _mm256_blendv_pd(x2, _mm256_fmadd_pd(hv, n2, x2),
                                            _mm256_or_pd(free, _mm256_cmp_pd(n2, zero, _CMP_NEQ_UQ)));
        aos3_store4(v + o, _mm256_blendv_pd(v0, n0, keep), _mm256_blendv_pd(v1, n1, keep),
                    _mm256_blendv_pd(v2, n2, keep));
        aos3_store4(x + o, _mm256_blendv_pd(x0, y0, keep), _mm256_blendv_pd(x1, y1, keep),
                    _mm256_blendv_pd(x2, y2, keep));
      }
      return end;
    }
#endif
    (void)to, (void)ws, (void)X, (void)Y, (void)Z, (void)VX, (void)VY, (void)VZ, (void)FX, (void)FY, (void)FZ;
    (void)deferred;
    return from;
  }

 private:
  // fma where the machine has it (the compiler contracts the plain expression to the same with
  // -march=native); the plain expression elsewhere, where no vector path exists either.
  static T fma_(T a, T b, T c) {
#if defined(__FMA__)
    return std::fma(a, b, c);
#else
    return a * b + c;
#endif
  }
};

/// One symplectic Euler step of a spring network on raw arrays (3n x, v, f; n inverse masses
/// w): v += h (w f + g), x += h v for free vertices; pinned ones (w = 0) move with their
/// velocity, and a fixed pin (v = 0) is not touched at all. f: zero on entry and on return.
template <class T>
void se_step_springs(const SpringSweep<T>& sw, T* x, T* v, const T* w, T* f, T h, const T g[3]) {
  sw.forces(x, v, f, SeFinish<T>{x, v, w, h, g[0], g[1], g[2]});
}

}  // namespace loom

// Grouped, windowed spring sweeps (issue 16), shared by harmonic_oscillation (HoSprings,
// plugins/integrators/harmonic_oscillation/ho_window.hpp) and the fused symplectic Euler / RK4
// sweep (SpringSweep, loom/explicit_springs.hpp). Header-only.
//
// Grouping (group_springs): each part of a SpringLayout has its vertex range cut into blocks of
// kSpringGroupBlock vertices; the interior springs whose lower endpoint lies in a block are
// ordered by (offset j - i, duplicate rank, i) and cut into segments of springs
// (i0 + step r, i0 + step r + off), r < len, step 1 or 2, stored consecutively. A segment then
// reads its endpoints' data with unit (or 2) stride and its per-spring constants contiguously:
// no gathers. Grouping pays when segments average at least 4 springs (grids, most meshes numbered
// row by row or by RCM); SpringGroups::grouped says whether it does.
//
// Window (plan_spring_window, window_make_room): a sweep copies each vertex of a part, once, into
// a per-part structure-of-arrays window just before the first block that reads it, runs the
// segments there with unit stride, and finalises a vertex from the window as soon as the sweep has
// passed it. When the next block needs a vertex beyond the window, the live vertices move to its
// start. The capacity is 4x the largest live span of any block (at least 1024 vertices), so a move
// copies at most a quarter of the window; spans above kSpringWinMaxSpan turn the window off.
#pragma once

#include <algorithm>
#include <cstddef>
#include <cstdint>
#include <cstring>
#include <numeric>
#include <type_traits>
#include <vector>

#include "loom/common.hpp"
#include "loom/spring_layout.hpp"

#if defined(__AVX2__)
#include <immintrin.h>
#endif

namespace loom {

/// A run of springs (i0 + step r, i0 + step r + off), r < len, stored at [begin, begin + len).
/// twin = 1: the next segment of the block has the same i0, len, off and step (duplicate pairs,
/// the next rank: it reads the same vertices), so a sweep may compute the two segments' shared
/// geometry once (issue 16; group_springs sets it on the first of the two, 0 on the second, and
/// makes such segments neighbours where that keeps every slot's order of additions:
/// pair_twin_segments).
struct SpringSegment {
  Index begin, len, i0, off, step;   ///< step 1 or 2
  Index twin = 0;
};
/// A block of the grouped sweep: its segments, and the vertex bound below which vertices are final
/// once the block is done.
struct SpringBlock {
  Index vertex_end, seg_begin, seg_end;
};

/// The most vertices per block of the grouped traversal, so the most springs per segment: the
/// sweeps' per-segment buffers hold this many springs.
constexpr Index kSpringGroupBlockMax = 256;
/// Vertices per block of the grouped traversal, the default of group_springs' block (the fused
/// symplectic Euler / RK4 sweep's; harmonic_oscillation's is kHoGroupBlock). Larger blocks give
/// fewer, longer segments (on the 112,896-vertex Table 1 grid 23,983 segments with 64, 8,505 with
/// 256: a segment then runs to the end of its grid row or block) and a larger window (live span =
/// block + the largest offset j - i: 2,944 and 3,712 vertices). table1's *_block64/128/256 rows
/// compare the sizes; under the load of the measurements so far (docs/benchmarks/ho.md, issue 16)
/// the differences were within the noise, so the default stays 64.
constexpr Index kSpringGroupBlock = 64;
/// Largest live span (vertices) for which a window is used.
constexpr Index kSpringWinMaxSpan = 1 << 16;

/// The grouped traversal of a layout's interior springs.
struct SpringGroups {
  bool grouped = false;               ///< segments average at least 4 springs
  std::vector<SpringSegment> segs;
  std::vector<SpringBlock> blocks;
  std::vector<Index> part_block;      ///< blocks of part p: [part_block[p], part_block[p + 1])
};

/// Whether two segments add to no common slot (conservatively: their lower and upper slot
/// intervals [i0, i0 + step (len - 1)] and [i0 + off, ...] do not meet).
inline bool spring_segments_disjoint(const SpringSegment& a, const SpringSegment& b) {
  const Index ea = a.step * (a.len - 1), eb = b.step * (b.len - 1);
  const Index sa[2] = {a.i0, a.i0 + a.off}, sb[2] = {b.i0, b.i0 + b.off};
  for (Index x : sa)
    for (Index y : sb)
      if (x <= y + eb && y <= x + ea) return false;
  return true;
}

/// Twin pairs among the segments [from, end) of one block (issue 16): a segment and a later one
/// with the same i0, len, off and step (duplicate springs on the same pairs: they read the same
/// vertices) are made neighbours, the first marked twin = 1. The later segment moves up only past
/// segments that add to none of its slots (spring_segments_disjoint), so every slot receives its
/// additions in the same order as before: the sums are unchanged, bit for bit. Segments refer to
/// their springs by begin, so the springs stay where they are.
inline void pair_twin_segments(std::vector<SpringSegment>& segs, std::size_t from) {
  const std::size_t end = segs.size();
  for (std::size_t t = from; t + 1 < end; ++t) {
    const SpringSegment s0 = segs[t];
    for (std::size_t u = t + 1; u < end; ++u) {
      const SpringSegment s1 = segs[u];
      if (s1.i0 != s0.i0 || s1.len != s0.len || s1.off != s0.off || s1.step != s0.step) continue;
      bool free = true;
      for (std::size_t m = t + 1; m < u && free; ++m) free = spring_segments_disjoint(segs[m], s1);
      if (!free) continue;   // a later match may still move up
      for (std::size_t m = u; m > t + 1; --m) segs[m] = segs[m - 1];
      segs[t + 1] = s1;
      segs[t].twin = 1;
      ++t;
      break;
    }
  }
}

/// Group the springs (i[q] < j[q], in the layout's traversal order: each part's interior
/// springs sorted by lower endpoint). Returns perm: the grouped order is q' -> perm[q'] (apply it
/// to every per-spring array: a_new[q'] = a_old[perm[q']]); cross springs keep their places.
/// The segments in g refer to positions in the grouped order.
/// block: vertices per block, clamped to [1, kSpringGroupBlockMax] (benchmarks and tests compare
/// block sizes; only the order of the additions into a vertex depends on it).
inline std::vector<Index> group_springs(const SpringLayout& layout, const std::vector<Index>& i,
                                        const std::vector<Index>& j, SpringGroups& g,
                                        Index block = kSpringGroupBlock) {
  block = std::clamp<Index>(block, 1, kSpringGroupBlockMax);
  const Index S = static_cast<Index>(i.size());
  std::vector<Index> perm(static_cast<std::size_t>(S));
  std::iota(perm.begin(), perm.end(), Index(0));
  g.segs.clear();
  g.blocks.clear();
  g.part_block.assign(static_cast<std::size_t>(layout.parts()) + 1, 0);
  std::vector<Index> rank;
  for (int p = 0; p < layout.parts(); ++p) {
    const Index sb = layout.part_spring_begin(p), se = layout.part_spring_end(p);
    const Index vb = layout.part_vertex_begin(p), ve = layout.part_vertex_end(p);
    Index* P = perm.data() + sb;
    const std::size_t m = static_cast<std::size_t>(se - sb);
    auto blk = [&](Index q) { return (i[q] - vb) / block; };
    // duplicate pairs (i, j) (some stencils carry two springs on a pair) get ranks 0, 1, ... so
    // that each copy joins its own run of consecutive i
    rank.assign(m, 0);
    std::stable_sort(P, P + m, [&](Index a, Index b) { return i[a] != i[b] ? i[a] < i[b] : j[a] < j[b]; });
    for (std::size_t r = 1; r < m; ++r)
      if (i[P[r]] == i[P[r - 1]] && j[P[r]] == j[P[r - 1]]) rank[P[r] - sb] = rank[P[r - 1] - sb] + 1;
    std::stable_sort(P, P + m, [&](Index a, Index b) {
      const Index ba = blk(a), bb = blk(b);
      if (ba != bb) return ba < bb;
      const Index oa = j[a] - i[a], ob = j[b] - i[b];
      if (oa != ob) return oa < ob;
      if (rank[a - sb] != rank[b - sb]) return rank[a - sb] < rank[b - sb];
      return i[a] < i[b];
    });
    g.part_block[p] = static_cast<Index>(g.blocks.size());
    auto I = [&](Index q) { return i[perm[q]]; };
    auto O = [&](Index q) { return j[perm[q]] - i[perm[q]]; };
    Index q = sb;
    for (Index v0 = vb; v0 < ve; v0 += block) {
      const Index v1 = std::min<Index>(v0 + block, ve);
      const Index seg_begin = static_cast<Index>(g.segs.size());
      while (q < se && I(q) < v1) {
        SpringSegment s{q, 1, I(q), O(q), 1};
        ++q;
        // the step (1 or 2) is fixed by the second spring
        if (q < se && I(q) < v1 && O(q) == s.off && I(q) - s.i0 == 2) s.step = 2;
        while (q < se && I(q) < v1 && O(q) == s.off && I(q) == s.i0 + s.step * s.len && s.len < block) {
          ++s.len;
          ++q;
        }
        g.segs.push_back(s);
      }
      pair_twin_segments(g.segs, static_cast<std::size_t>(seg_begin));
      g.blocks.push_back({v1, seg_begin, static_cast<Index>(g.segs.size())});
    }
  }
  g.part_block[layout.parts()] = static_cast<Index>(g.blocks.size());
  const Index interior = layout.colour_begin(0);
  g.grouped = !g.segs.empty() && interior >= 4 * static_cast<Index>(g.segs.size());
  return perm;
}

/// a_new[q] = a_old[perm[q]].
template <class A>
void apply_spring_perm(const std::vector<Index>& perm, A& a) {
  A tmp(a.size());
  for (std::size_t q = 0; q < perm.size(); ++q) tmp[q] = a[static_cast<std::size_t>(perm[q])];
  a.swap(tmp);
}

/// Window plan for grouped springs (any struct with grouped, segs, blocks, part_block and the
/// outputs block_need, win_span, win_cap): need[bk] = 1 + the largest vertex that block bk reads
/// (at least the block's vertex_end); win_span, the largest number of vertices live at once
/// (from the first unfinished vertex to the farthest one read); the capacity win_cap (0 when that
/// span is too large: window off). Any capacity >= win_span is correct.
template <class Springs>
void plan_spring_window(const SpringLayout& layout, Springs& s) {
  s.block_need.assign(s.blocks.size(), 0);
  s.win_cap = 0;
  s.win_span = 0;
  if (!s.grouped) return;
  Index span = 0;
  for (int p = 0; p < layout.parts(); ++p) {
    Index qfin = layout.part_vertex_begin(p);
    for (Index bk = s.part_block[p]; bk < s.part_block[p + 1]; ++bk) {
      const auto& B = s.blocks[bk];
      Index need = B.vertex_end;
      for (Index sg = B.seg_begin; sg < B.seg_end; ++sg) {
        const auto& G = s.segs[sg];
        need = std::max(need, G.i0 + G.off + G.step * (G.len - 1) + 1);
      }
      s.block_need[bk] = need;
      span = std::max(span, need - qfin);
      qfin = B.vertex_end;
    }
  }
  s.win_span = span;
  if (span > kSpringWinMaxSpan) return;
  s.win_cap = std::max<Index>(1024, 4 * span);
}

/// The narr arrays of part p's window in the scratch win (parts x narr x cap, part after part):
/// A[e] = win + (p narr + e) cap.
template <class T, int N>
inline void window_arrays(T* win, int p, Index cap, T* (&A)[N]) {
  T* base = win + static_cast<std::size_t>(p) * N * static_cast<std::size_t>(cap);
  for (int e = 0; e < N; ++e) A[e] = base + static_cast<std::size_t>(e) * static_cast<std::size_t>(cap);
}

/// Fill the window slots of the vertices [from, to) in one pass: x (interleaved 3n array, x0 y0
/// z0 x1 ...) into X, Y, Z; with WithV also v into VX, VY, VZ; the accumulators A0, A1, A2 (and,
/// with SixAcc, A3, A4, A5) zeroed. Window slot = vertex - ws.
template <class T, bool WithV, bool SixAcc>
inline void window_fill(const T* __restrict x, const T* __restrict v, Index from, Index to, Index ws,
                        T* __restrict X, T* __restrict Y, T* __restrict Z, T* __restrict VX, T* __restrict VY,
                        T* __restrict VZ, T* __restrict A0, T* __restrict A1, T* __restrict A2, T* __restrict A3,
                        T* __restrict A4, T* __restrict A5) {
  for (Index q = from; q < to; ++q) {
    const std::size_t o = 3 * static_cast<std::size_t>(q);
    const Index l = q - ws;
    X[l] = x[o];
    Y[l] = x[o + 1];
    Z[l] = x[o + 2];
    A0[l] = A1[l] = A2[l] = T(0);
    if constexpr (WithV) {
      VX[l] = v[o];
      VY[l] = v[o + 1];
      VZ[l] = v[o + 2];
    }
    if constexpr (SixAcc) A3[l] = A4[l] = A5[l] = T(0);
  }
}

/// A segment's per-spring vectors F (3 x Bk, structure of arrays) added at window vertices
/// a + Step r and subtracted at a + off + Step r, r < len (two passes: the ranges may overlap).
///
/// Step 2 in double with AVX2 (window_scatter_step2_avx2): four springs' values go to slots
/// s, s + 2, s + 4, s + 6 as one load-add-store of the eight slots s..s+7 with +0 added to the odd
/// ones. That is the scalar loop's result bit for bit: x - (+0) = x for every x, x + (+0) = x for
/// every x but -0, and a window sum is never -0 (it starts at +0, and under round-to-nearest
/// x + y or x - y is -0 only when x already is). The vector loop stops while slot s + 7 still lies inside the
/// segment's own range, so it touches only slots of this window (no other thread's data).
template <class T, int Step, Index Bk>
inline void window_segment_scatter(Index len, Index a, Index off, T* __restrict FX, T* __restrict FY,
                                   T* __restrict FZ, const T* __restrict F);

/// The portable loop of window_segment_scatter for r in [r0, len).
template <class T, int Step, Index Bk>
inline void window_segment_scatter_from(Index r0, Index len, Index a, Index off, T* __restrict FX,
                                        T* __restrict FY, T* __restrict FZ, const T* __restrict F) {
  for (Index r = r0; r < len; ++r) {
    FX[a + Step * r] += F[r];
    FY[a + Step * r] += F[Bk + r];
    FZ[a + Step * r] += F[2 * Bk + r];
  }
  for (Index r = r0; r < len; ++r) {
    FX[a + off + Step * r] -= F[r];
    FY[a + off + Step * r] -= F[Bk + r];
    FZ[a + off + Step * r] -= F[2 * Bk + r];
  }
}

#if defined(__AVX2__)
/// Stride-2 scatter of one component, all len springs: sign +1 adds G[r] at A[2 r], -1
/// subtracts. Vector part r < r1 (r1 a multiple of 4 with r1 + 1 <= len, so that the highest slot
/// a vector touches, 2 r1 - 1, is at most 2 (len - 1), a slot of the segment), then the tail.
template <int Sign>
inline void window_scatter_step2_avx2(Index len, double* __restrict A, const double* __restrict G) {
  const Index r1 = len >= 1 ? ((len - 1) / 4) * 4 : 0;
  const __m256d zero = _mm256_setzero_pd();
  for (Index r = 0; r < r1; r += 4) {
    const __m256d g = _mm256_permute4x64_pd(_mm256_loadu_pd(G + r), 0xD8);   // g0 g2 g1 g3
    const __m256d lo = _mm256_unpacklo_pd(g, zero);                            // g0 0 g1 0
    const __m256d hi = _mm256_unpackhi_pd(g, zero);                            // g2 0 g3 0
    double* s = A + 2 * r;
    const __m256d s0 = _mm256_loadu_pd(s), s1 = _mm256_loadu_pd(s + 4);
    if constexpr (Sign > 0) {
      _mm256_storeu_pd(s, _mm256_add_pd(s0, lo));
      _mm256_storeu_pd(s + 4, _mm256_add_pd(s1, hi));
    } else {
      _mm256_storeu_pd(s, _mm256_sub_pd(s0, lo));
      _mm256_storeu_pd(s + 4, _mm256_sub_pd(s1, hi));
    }
  }
  for (Index r = r1; r < len; ++r) {
    if constexpr (Sign > 0)
      A[2 * r] += G[r];
    else
      A[2 * r] -= G[r];
  }
}
#endif

#if defined(__AVX2__)
/// Four vertices' components a, b, c (a0..a3, b0..b3, c0..c3) stored interleaved, as the user
/// arrays hold them: a0 b0 c0 a1 | b1 c1 a2 b2 | c2 a3 b3 c3 (12 doubles from out). Used by the
/// windowed sweeps' vectorised finalisations (harmonic_oscillation, symplectic_euler).
inline void aos3_store4(double* out, __m256d a, __m256d b, __m256d c) {
  const __m256d t0 = _mm256_unpacklo_pd(a, b);       // a0 b0 a2 b2
  const __m256d t2 = _mm256_shuffle_pd(c, a, 0xA);   // c0 a1 c2 a3
  const __m256d t3 = _mm256_shuffle_pd(b, c, 0xF);   // b1 c1 b3 c3
  _mm256_storeu_pd(out, _mm256_permute2f128_pd(t0, t2, 0x20));
  _mm256_storeu_pd(out + 4, _mm256_permute2f128_pd(t3, t0, 0x30));
  _mm256_storeu_pd(out + 8, _mm256_permute2f128_pd(t2, t3, 0x31));
}

/// The inverse of aos3_store4: 12 interleaved doubles from in to four vertices' a, b, c.
inline void aos3_load4(const double* in, __m256d& a, __m256d& b, __m256d& c) {
  const __m256d m0 = _mm256_loadu_pd(in), m1 = _mm256_loadu_pd(in + 4), m2 = _mm256_loadu_pd(in + 8);
  const __m256d t0 = _mm256_permute2f128_pd(m0, m1, 0x30);   // a0 b0 a2 b2
  const __m256d t1 = _mm256_permute2f128_pd(m0, m2, 0x21);   // c0 a1 c2 a3
  const __m256d t2 = _mm256_permute2f128_pd(m1, m2, 0x30);   // b1 c1 b3 c3
  a = _mm256_shuffle_pd(t0, t1, 0xA);
  b = _mm256_shuffle_pd(t0, t2, 0x5);
  c = _mm256_shuffle_pd(t1, t2, 0xA);
}

/// Four bytes of a 0/1 flag array as a lane mask: all ones where the flag is 0.
inline __m256d lanes_where_zero4(const std::uint8_t* flags) {
  std::uint32_t d4;
  std::memcpy(&d4, flags, 4);
  return _mm256_castsi256_pd(
      _mm256_cmpeq_epi64(_mm256_cvtepu8_epi64(_mm_cvtsi32_si128(static_cast<int>(d4))), _mm256_setzero_si256()));
}
#endif

template <class T, int Step, Index Bk>
inline void window_segment_scatter(Index len, Index a, Index off, T* __restrict FX, T* __restrict FY,
                                   T* __restrict FZ, const T* __restrict F) {
#if defined(__AVX2__)
  if constexpr (Step == 2 && std::is_same_v<T, double>) {
    // the lower pass whole, then the upper one (the two ranges may share slots: same order of
    // additions into a slot as the portable loop)
    window_scatter_step2_avx2<+1>(len, FX + a, F);
    window_scatter_step2_avx2<+1>(len, FY + a, F + Bk);
    window_scatter_step2_avx2<+1>(len, FZ + a, F + 2 * Bk);
    window_scatter_step2_avx2<-1>(len, FX + a + off, F);
    window_scatter_step2_avx2<-1>(len, FY + a + off, F + Bk);
    window_scatter_step2_avx2<-1>(len, FZ + a + off, F + 2 * Bk);
    return;
  }
#endif
  window_segment_scatter_from<T, Step, Bk>(0, len, a, off, FX, FY, FZ, F);
}

/// The unit-stride scatter of a segment whose lower and upper ranges overlap (0 < off < len) in
/// one pass over the slots [a, a + off + len) instead of two (issue 16): a slot in both ranges
/// gets (S + F[r]) - F[r - off], the two passes' additions in their order, so the same bits;
/// the slots in one range get their one addition. Saves a load and a store per shared slot and
/// the second pass's reloads of slots the first just stored.
template <class T, Index Bk>
inline void window_segment_scatter_overlap(Index len, Index a, Index off, T* __restrict FX, T* __restrict FY,
                                           T* __restrict FZ, const T* __restrict F) {
  T* const S[3] = {FX + a, FY + a, FZ + a};
  for (int e = 0; e < 3; ++e) {
    T* __restrict D = S[e];
    const T* __restrict G = F + e * Bk;
    for (Index r = 0; r < off; ++r) D[r] += G[r];
    for (Index r = off; r < len; ++r) D[r] = (D[r] + G[r]) - G[r - off];
    for (Index r = len; r < len + off; ++r) D[r] -= G[r - off];
  }
}

/// The scatters of a twin pair of segments (SpringSegment::twin: the same slots) in one pass:
/// what window_segment_scatter<T, Step, Bk>(..., F) followed by the same with F2 gives, bit for
/// bit (issue 16). When off is a multiple of Step (k = off / Step), slot a + Step t gets, in this
/// order, + F[t] (t < len), - F[t - k] (k <= t < len + k), + F2[t], - F2[t - k]: the two
/// two-pass scatters' additions into that slot in their order, since each of those passes adds to
/// a slot at most once. Otherwise (stride 2, odd off) the lower and upper slots are disjoint and
/// each gets its two additions, F's then F2's. One load and store per slot instead of four. In
/// double with AVX2 the stride-2 loops add +0 to the odd slots between, as
/// window_scatter_step2_avx2 does (a window sum is never -0), and stop while the highest slot a
/// vector touches is still a slot of the pair's range.
template <class T, int Step, Index Bk>
inline void window_segment_scatter_twin(Index len, Index a, Index off, T* __restrict FX, T* __restrict FY,
                                        T* __restrict FZ, const T* __restrict F, const T* __restrict F2) {
  T* const S[3] = {FX + a, FY + a, FZ + a};
  if (off % Step != 0) {   // stride 2, odd offset: the lower and upper slots are disjoint
    for (int e = 0; e < 3; ++e) {
      T* __restrict D = S[e];
      const T* __restrict G = F + e * Bk;
      const T* __restrict H = F2 + e * Bk;
      for (Index t = 0; t < len; ++t) D[Step * t] = (D[Step * t] + G[t]) + H[t];
      for (Index t = 0; t < len; ++t) D[off + Step * t] = (D[off + Step * t] - G[t]) - H[t];
    }
    return;
  }
  const Index k = off / Step, n = len + k;   // slots a + Step t, t < n
  const Index lo_end = std::min(len, k);      // [0, lo_end): lower only
  const Index both_end = len;                 // [k, len): both (when k < len)
  const Index up_begin = std::max(len, k);    // [up_begin, n): upper only
  for (int e = 0; e < 3; ++e) {
    T* __restrict D = S[e];
    const T* __restrict G = F + e * Bk;
    const T* __restrict H = F2 + e * Bk;
    Index t = 0;
#if defined(__AVX2__)
    if constexpr (Step == 2 && std::is_same_v<T, double>) {
      // four slots (eight with the odd ones between) at a time while slot 2 t + 7 <= 2 (n - 1)
      const __m256d zero = _mm256_setzero_pd();
      const auto spread = [&](const double* g, __m256d& lo, __m256d& hi) {   // g0 0 g1 0 | g2 0 g3 0
        const __m256d v = _mm256_permute4x64_pd(_mm256_loadu_pd(g), 0xD8);
        lo = _mm256_unpacklo_pd(v, zero);
        hi = _mm256_unpackhi_pd(v, zero);
      };
      const auto fits = [&](Index t0, Index end) { return t0 + 4 <= end && 2 * t0 + 7 <= 2 * (n - 1); };
      __m256d gl, gh, hl, hh, ul, uh, vl, vh;
      for (; fits(t, lo_end); t += 4) {
        double* d = D + 2 * t;
        spread(G + t, gl, gh);
        spread(H + t, hl, hh);
        _mm256_storeu_pd(d, _mm256_add_pd(_mm256_add_pd(_mm256_loadu_pd(d), gl), hl));
        _mm256_storeu_pd(d + 4, _mm256_add_pd(_mm256_add_pd(_mm256_loadu_pd(d + 4), gh), hh));
      }
      for (; t < lo_end; ++t) D[2 * t] = (D[2 * t] + G[t]) + H[t];
      t = std::max(t, k);
      for (; fits(t, both_end); t += 4) {
        double* d = D + 2 * t;
        spread(G + t, gl, gh);
        spread(G + t - k, ul, uh);
        spread(H + t, hl, hh);
        spread(H + t - k, vl, vh);
        _mm256_storeu_pd(d, _mm256_sub_pd(_mm256_add_pd(_mm256_sub_pd(_mm256_add_pd(_mm256_loadu_pd(d), gl), ul), hl), vl));
        _mm256_storeu_pd(d + 4,
                         _mm256_sub_pd(_mm256_add_pd(_mm256_sub_pd(_mm256_add_pd(_mm256_loadu_pd(d + 4), gh), uh), hh), vh));
      }
      for (; t < both_end; ++t) D[2 * t] = (((D[2 * t] + G[t]) - G[t - k]) + H[t]) - H[t - k];
      t = std::max(t, up_begin);
      for (; fits(t, n); t += 4) {
        double* d = D + 2 * t;
        spread(G + t - k, ul, uh);
        spread(H + t - k, vl, vh);
        _mm256_storeu_pd(d, _mm256_sub_pd(_mm256_sub_pd(_mm256_loadu_pd(d), ul), vl));
        _mm256_storeu_pd(d + 4, _mm256_sub_pd(_mm256_sub_pd(_mm256_loadu_pd(d + 4), uh), vh));
      }
      for (; t < n; ++t) D[2 * t] = (D[2 * t] - G[t - k]) - H[t - k];
      continue;
    }
#endif
    for (t = 0; t < lo_end; ++t) D[Step * t] = (D[Step * t] + G[t]) + H[t];
    for (t = k; t < both_end; ++t) D[Step * t] = (((D[Step * t] + G[t]) - G[t - k]) + H[t]) - H[t - k];
    for (t = up_begin; t < n; ++t) D[Step * t] = (D[Step * t] - G[t - k]) - H[t - k];
  }
}

/// Before a block that reads vertices up to need - 1: when need lies beyond the window
/// [ws, ws + cap), move the live vertices [qfin, fill) of the narr arrays A to the start (ws = qfin).
template <class T>
inline void window_make_room(T* const* A, int narr, Index cap, Index need, Index qfin, Index fill, Index& ws) {
  if (need <= ws + cap) return;
  const std::size_t sh = static_cast<std::size_t>(qfin - ws), cnt = static_cast<std::size_t>(fill - qfin);
  for (int e = 0; e < narr; ++e) std::memmove(A[e], A[e] + sh, cnt * sizeof(T));
  ws = qfin;
}

}  // namespace loom

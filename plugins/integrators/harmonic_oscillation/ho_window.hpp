// The windowed grouped sweep of the HO step (issue 16): the grouped sweep (HoSprings::grouped,
// segments of springs (i0 + step r, i0 + step r + off)) run on a per-part window that holds x, v
// and the accumulators of the live vertices in structure of arrays.
//
// Why: the plain grouped sweep reads x[3 i + e] and v[3 i + e] (three doubles per vertex) in its
// vectorised impulse loop, so every lane needs shuffles to go from the interleaved layout to one
// register per component, and every segment shuffles again (a vertex is read by about 10
// segments, once per spring it is an endpoint of). Here each vertex is copied once into the
// window (X, Y, Z, VX, VY, VZ, contiguous per component) just before the first block that reads
// it, the segments read and accumulate there with unit stride (stride 2 for step-2 segments), and
// the vertex is finalised from the window (user arrays written once) as soon as the sweep has
// passed it. The accumulators live in the window too (cache resident), so the 3n accumulator
// array is touched only for the vertices that cross springs reach.
//
// The window of part p covers vertices [ws, ws + cap); when the next block needs a vertex beyond
// it, the live vertices [qfin, fill) move to the start (ws = qfin). cap is chosen in
// plan_ho_window from the largest live span of any block (4x it, at least 1024), so a move
// copies at most a quarter of the window. The arithmetic and the order of every addition are
// those of the plain grouped sweep: results are bit-identical (tests/harmonic_oscillation,
// HoStorage.WindowedSweepIsBitIdentical). Unit-stride segments whose lower and upper ranges are
// disjoint compute and scatter their impulses in one loop (ho_window_impulses_scatter), those
// whose ranges overlap scatter in one pass (window_segment_scatter_overlap); the same bits
// (HoSprings::fuse, issue 16; HoStorage.FusedImpulseScatterIsBitIdentical).
#pragma once

#include <algorithm>
#include <cstddef>
#include <cstdint>
#include <cstring>
#include <limits>
#include <vector>

#include "loom/common.hpp"
#include "loom/kernels/ho.hpp"
#include "loom/spring_groups.hpp"

#if defined(__AVX2__) && defined(__FMA__)
#include <immintrin.h>
#define LOOM_HO_FINALISE_AVX2 1
#endif

namespace loom {

/// Arrays per part in the window: x, v (3 each), the velocity and position accumulators (3 each).
constexpr int kHoWinArrays = 12;
/// Largest live span (vertices) for which the window is used; beyond it the plain grouped sweep runs.
constexpr Index kHoWinMaxSpan = kSpringWinMaxSpan;

/// Window plan for grouped springs (loom/spring_groups.hpp, shared with the fused SE/RK4 sweep).
template <class Springs, class Layout>
void plan_ho_window(const Layout& layout, Springs& s) {
  plan_spring_window(layout, s);
}

/// Allocate the window scratch (parts x kHoWinArrays x cap), zeroed.
template <class Springs>
void allocate_ho_window(Springs& s, int parts) {
  s.win.assign(s.win_cap > 0 ? static_cast<std::size_t>(parts) * kHoWinArrays * static_cast<std::size_t>(s.win_cap) : 0,
               0);
}

/// The geometry of a window spring (p, q): unit vector n, length l and velocity along n ddot.
/// The arithmetic of kernels::ho_spring_velocity (ho_spring_axis) operation for operation; shared
/// by the one-spring and the twin loops (ho_window_spring, ho_window_twin_*), so their bits agree.
template <class T>
[[gnu::always_inline]] inline void ho_window_geometry(Index p, Index q, const T* __restrict X, const T* __restrict Y,
                                                     const T* __restrict Z, const T* __restrict VX,
                                                     const T* __restrict VY, const T* __restrict VZ, T& n0, T& n1,
                                                     T& n2, T& l, T& ddot) {
  using std::sqrt;
  const T tiny = std::numeric_limits<T>::min();
  const T d0 = X[q] - X[p], d1 = Y[q] - Y[p], d2 = Z[q] - Z[p];
  const T l2 = d0 * d0 + d1 * d1 + d2 * d2;
  l = sqrt(l2);
  const T inv = T(1) / (l + tiny);
  n0 = d0 * inv;
  n1 = d1 * inv;
  n2 = d2 * inv;
  ddot = n0 * (VX[q] - VX[p]) + n1 * (VY[q] - VY[p]) + n2 * (VZ[q] - VZ[p]);
}

/// The impulse per unit inverse mass along n of a spring with constants at c, from its geometry
/// (HO velocity, or kang_cho_2011 with |ddot|); also its stretch delta.
template <class T, bool kKc>
[[gnu::always_inline]] inline T ho_window_sv(std::size_t c, const T* __restrict L0, const T* __restrict KX,
                                            const T* __restrict KV, T l, T ddot, T& delta) {
  using std::abs;
  delta = l - L0[c];
  if constexpr (kKc)
    return KX[c] * delta + KV[c] * abs(ddot);
  else
    return KX[c] * delta + KV[c] * ddot;
}

/// One spring (p, q) of a window segment, constants at c: its unit vector n, stretch delta,
/// velocity along n ddot and the impulse per unit inverse mass along n (the return value; HO
/// velocity, or kang_cho_2011 with |ddot|). The arithmetic of kernels::ho_spring_velocity
/// (ho_spring_axis) operation for operation; shared by the two-pass and the one-pass loops, so
/// their bits agree.
template <class T, bool kKc>
[[gnu::always_inline]] inline T ho_window_spring(Index p, Index q, std::size_t c, const T* __restrict L0,
                                                const T* __restrict KX, const T* __restrict KV, const T* __restrict X,
                                                const T* __restrict Y, const T* __restrict Z, const T* __restrict VX,
                                                const T* __restrict VY, const T* __restrict VZ, T& n0, T& n1, T& n2,
                                                T& delta, T& ddot) {
  T l;
  ho_window_geometry<T>(p, q, X, Y, Z, VX, VY, VZ, n0, n1, n2, l, ddot);
  return ho_window_sv<T, kKc>(c, L0, KX, KV, l, ddot, delta);
}

/// Per-segment impulse loop on the window: springs (a + Step r, a + Step r + off) in window
/// coordinates; constants per spring, read contiguously (Table: gathered from the tables by id). Writes each spring's impulse per unit inverse mass g = s n into
/// G (3 x Bk, SoA) and, for analytic_position, its displacement per unit inverse mass into Q: the
/// endpoints' inverse masses are applied once per vertex when it is finalised, not per spring.
/// The arithmetic is kernels::ho_spring_velocity's (ho_spring_axis) operation for operation.
template <class T, int V, bool Table, int Step, Index Bk>
inline void ho_window_impulses(Index len, Index a, Index off, const std::uint16_t* __restrict ID,
                               const T* __restrict L0, const T* __restrict KX, const T* __restrict KV,
                               const T* __restrict EX, const T* __restrict EV, const T* __restrict X,
                               const T* __restrict Y, const T* __restrict Z, const T* __restrict VX,
                               const T* __restrict VY, const T* __restrict VZ, T* __restrict G, T* __restrict Q) {
  constexpr bool kPos = V == 1;   // HoVariant::AnalyticPosition
  constexpr bool kKc = V == 2;    // HoVariant::KangCho2011
  for (Index r = 0; r < len; ++r) {
    const Index p = a + Step * r, q = p + off;
    const std::size_t c = Table ? static_cast<std::size_t>(ID[r]) : static_cast<std::size_t>(r);
    T n0, n1, n2, delta, ddot;
    const T sv = ho_window_spring<T, kKc>(p, q, c, L0, KX, KV, X, Y, Z, VX, VY, VZ, n0, n1, n2, delta, ddot);
    G[r] = sv * n0;
    G[Bk + r] = sv * n1;
    G[2 * Bk + r] = sv * n2;
    if constexpr (kPos) {
      const T e = EX[c] * delta + EV[c] * ddot;
      Q[r] = e * n0;
      Q[Bk + r] = e * n1;
      Q[2 * Bk + r] = e * n2;
    }
  }
}

/// ho_window_impulses and the unit-stride window_segment_scatter in one pass (issue 16), for a
/// segment whose lower and upper slot ranges [a, a + len) and [a + off, a + off + len) are
/// disjoint (off >= len). Each slot of DX, DY, DZ then gets exactly one addition from the
/// segment, so the sums are the two passes' bit for bit (the same additions, per slot in the
/// same order); the loop has no dependence between iterations, hence `omp simd`. G still
/// receives the impulses: a product that is also stored is never contracted into the scatter's
/// addition (GCC's -ffp-contract=fast fuses a product whose only uses are additions, and an FMA
/// would round differently from the two passes). Velocity and kang_cho_2011 variants.
template <class T, int V, bool Table, Index Bk>
inline void ho_window_impulses_scatter(Index len, Index a, Index off, const std::uint16_t* __restrict ID,
                                       const T* __restrict L0, const T* __restrict KX, const T* __restrict KV,
                                       const T* __restrict X, const T* __restrict Y, const T* __restrict Z,
                                       const T* __restrict VX, const T* __restrict VY, const T* __restrict VZ,
                                       T* __restrict G, T* __restrict DX, T* __restrict DY, T* __restrict DZ) {
  static_assert(V != 1, "analytic_position keeps the two passes");
  constexpr bool kKc = V == 2;   // HoVariant::KangCho2011
#pragma omp simd
  for (Index r = 0; r < len; ++r) {
    const Index p = a + r, q = p + off;
    const std::size_t c = Table ? static_cast<std::size_t>(ID[r]) : static_cast<std::size_t>(r);
    T n0, n1, n2, delta, ddot;
    const T sv = ho_window_spring<T, kKc>(p, q, c, L0, KX, KV, X, Y, Z, VX, VY, VZ, n0, n1, n2, delta, ddot);
    const T g0 = sv * n0, g1 = sv * n1, g2 = sv * n2;
    G[r] = g0;
    G[Bk + r] = g1;
    G[2 * Bk + r] = g2;
    DX[p] += g0;
    DY[p] += g1;
    DZ[p] += g2;
    DX[q] -= g0;
    DY[q] -= g1;
    DZ[q] -= g2;
  }
}

/// Per-spring constants of one segment of a twin pair (ho_window_impulses_twin): the table ids
/// (Table) or the streams l0, kx, kv (and ex, ev for analytic_position), from the segment's start.
template <class T>
struct HoSegConsts {
  const std::uint16_t* id;
  const T *l0, *kx, *kv, *ex, *ev;
};

/// ho_window_impulses for a twin pair of segments (SpringSegment::twin: the same endpoints, the
/// springs' own constants A and B): the geometry of each endpoint pair (n, l, ddot) once, the
/// impulses of both springs into GA and GB (and QA, QB for analytic_position). Each spring's
/// operations are those of ho_window_impulses, so GA and GB hold the bits the two segments'
/// loops would write.
template <class T, int V, bool Table, int Step, Index Bk>
inline void ho_window_impulses_twin(Index len, Index a, Index off, HoSegConsts<T> A, HoSegConsts<T> B,
                                    const T* __restrict X, const T* __restrict Y, const T* __restrict Z,
                                    const T* __restrict VX, const T* __restrict VY, const T* __restrict VZ,
                                    T* __restrict GA, T* __restrict GB, T* __restrict QA, T* __restrict QB) {
  constexpr bool kPos = V == 1;   // HoVariant::AnalyticPosition
  constexpr bool kKc = V == 2;    // HoVariant::KangCho2011
  const std::uint16_t* __restrict IA = A.id;
  const std::uint16_t* __restrict IB = B.id;
  const T* __restrict L0a = A.l0;
  const T* __restrict KXa = A.kx;
  const T* __restrict KVa = A.kv;
  const T* __restrict L0b = B.l0;
  const T* __restrict KXb = B.kx;
  const T* __restrict KVb = B.kv;
  for (Index r = 0; r < len; ++r) {
    const Index p = a + Step * r, q = p + off;
    const std::size_t ca = Table ? static_cast<std::size_t>(IA[r]) : static_cast<std::size_t>(r);
    const std::size_t cb = Table ? static_cast<std::size_t>(IB[r]) : static_cast<std::size_t>(r);
    T n0, n1, n2, l, ddot, da, db;
    ho_window_geometry<T>(p, q, X, Y, Z, VX, VY, VZ, n0, n1, n2, l, ddot);
    const T sa = ho_window_sv<T, kKc>(ca, L0a, KXa, KVa, l, ddot, da);
    const T sb = ho_window_sv<T, kKc>(cb, L0b, KXb, KVb, l, ddot, db);
    GA[r] = sa * n0;
    GA[Bk + r] = sa * n1;
    GA[2 * Bk + r] = sa * n2;
    GB[r] = sb * n0;
    GB[Bk + r] = sb * n1;
    GB[2 * Bk + r] = sb * n2;
    if constexpr (kPos) {
      const T ea = A.ex[ca] * da + A.ev[ca] * ddot;
      const T eb = B.ex[cb] * db + B.ev[cb] * ddot;
      QA[r] = ea * n0;
      QA[Bk + r] = ea * n1;
      QA[2 * Bk + r] = ea * n2;
      QB[r] = eb * n0;
      QB[Bk + r] = eb * n1;
      QB[2 * Bk + r] = eb * n2;
    }
  }
}

/// ho_window_impulses_scatter for a twin pair of unit-stride segments with disjoint lower and
/// upper ranges (off >= len): per spring position r the geometry once, then slot a + r gets
/// + gA, then + gB, and slot a + r + off gets - gA, then - gB: each slot the additions of the
/// first segment's loop, then the second's, as when the two run one after the other (no slot
/// gets two additions from one segment). GA and GB still receive the impulses (no contraction
/// into the additions). Velocity and kang_cho_2011 variants.
template <class T, int V, bool Table, Index Bk>
inline void ho_window_impulses_scatter_twin(Index len, Index a, Index off, HoSegConsts<T> A, HoSegConsts<T> B,
                                            const T* __restrict X, const T* __restrict Y, const T* __restrict Z,
                                            const T* __restrict VX, const T* __restrict VY, const T* __restrict VZ,
                                            T* __restrict GA, T* __restrict GB, T* __restrict DX, T* __restrict DY,
                                            T* __restrict DZ) {
  static_assert(V != 1, "analytic_position keeps the two passes");
  constexpr bool kKc = V == 2;   // HoVariant::KangCho2011
  const std::uint16_t* __restrict IA = A.id;
  const std::uint16_t* __restrict IB = B.id;
  const T* __restrict L0a = A.l0;
  const T* __restrict KXa = A.kx;
  const T* __restrict KVa = A.kv;
  const T* __restrict L0b = B.l0;
  const T* __restrict KXb = B.kx;
  const T* __restrict KVb = B.kv;
#pragma omp simd
  for (Index r = 0; r < len; ++r) {
    const Index p = a + r, q = p + off;
    const std::size_t ca = Table ? static_cast<std::size_t>(IA[r]) : static_cast<std::size_t>(r);
    const std::size_t cb = Table ? static_cast<std::size_t>(IB[r]) : static_cast<std::size_t>(r);
    T n0, n1, n2, l, ddot, da, db;
    ho_window_geometry<T>(p, q, X, Y, Z, VX, VY, VZ, n0, n1, n2, l, ddot);
    const T sa = ho_window_sv<T, kKc>(ca, L0a, KXa, KVa, l, ddot, da);
    const T sb = ho_window_sv<T, kKc>(cb, L0b, KXb, KVb, l, ddot, db);
    const T a0 = sa * n0, a1 = sa * n1, a2 = sa * n2;
    const T b0 = sb * n0, b1 = sb * n1, b2 = sb * n2;
    GA[r] = a0;
    GA[Bk + r] = a1;
    GA[2 * Bk + r] = a2;
    GB[r] = b0;
    GB[Bk + r] = b1;
    GB[2 * Bk + r] = b2;
    DX[p] = (DX[p] + a0) + b0;
    DY[p] = (DY[p] + a1) + b1;
    DZ[p] = (DZ[p] + a2) + b2;
    DX[q] = (DX[q] - a0) - b0;
    DY[q] = (DY[q] - a1) - b1;
    DZ[q] = (DZ[q] - a2) - b2;
  }
}

#if defined(LOOM_HO_FINALISE_AVX2)
/// Vertices [from, from + 4 m) of a block finalised 4 at a time (velocity and kang_cho_2011
/// variants, double): kernels::ho_finalise_vertex on w_q (DX, DY, DZ)[l], operation for
/// operation (its fma calls are these _mm256_fmadd_pd), so the same bits as the scalar
/// finalisation; x and v are read from the window's copies (X..VZ, equal to the user arrays'
/// values until the vertex is finalised) and written to the user arrays (interleaved) once.
/// Deferred vertices (cross springs add to them later) are written back unchanged (a blend
/// instead of a branch); their hand-off to the 3n accumulators is the caller's. Returns
/// from + 4 m, the first vertex left to the caller (m = (to - from) / 4).
inline Index ho_finalise_block_avx2(Index from, Index to, Index ws, const double* __restrict X,
                                    const double* __restrict Y, const double* __restrict Z,
                                    const double* __restrict VX, const double* __restrict VY,
                                    const double* __restrict VZ, const double* __restrict DX,
                                    const double* __restrict DY, const double* __restrict DZ,
                                    const double* __restrict w, const std::uint8_t* __restrict deferred,
                                    double* __restrict x, double* __restrict v, double h, const double hg[3]) {
  const __m256d zero = _mm256_setzero_pd(), one = _mm256_set1_pd(1.0), hv = _mm256_set1_pd(h);
  const __m256d hg0 = _mm256_set1_pd(hg[0]), hg1 = _mm256_set1_pd(hg[1]), hg2 = _mm256_set1_pd(hg[2]);
  const Index end = from + ((to - from) / 4) * 4;
  for (Index q = from; q < end; q += 4) {
    const Index l = q - ws;
    const __m256d wq = _mm256_loadu_pd(w + q);
    const __m256d f = _mm256_and_pd(_mm256_cmp_pd(wq, zero, _CMP_GT_OQ), one);   // w > 0 ? 1 : 0
    const __m256d keep = lanes_where_zero4(deferred + q);   // not deferred
    const __m256d x0 = _mm256_loadu_pd(X + l), x1 = _mm256_loadu_pd(Y + l), x2 = _mm256_loadu_pd(Z + l);
    const __m256d v0 = _mm256_loadu_pd(VX + l), v1 = _mm256_loadu_pd(VY + l), v2 = _mm256_loadu_pd(VZ + l);
    // v = v + fma(f, hg, w s); x = fma(h, v, x)
    const __m256d n0 = _mm256_add_pd(v0, _mm256_fmadd_pd(f, hg0, _mm256_mul_pd(wq, _mm256_loadu_pd(DX + l))));
    const __m256d n1 = _mm256_add_pd(v1, _mm256_fmadd_pd(f, hg1, _mm256_mul_pd(wq, _mm256_loadu_pd(DY + l))));
    const __m256d n2 = _mm256_add_pd(v2, _mm256_fmadd_pd(f, hg2, _mm256_mul_pd(wq, _mm256_loadu_pd(DZ + l))));
    const __m256d y0 = _mm256_fmadd_pd(hv, n0, x0), y1 = _mm256_fmadd_pd(hv, n1, x1), y2 = _mm256_fmadd_pd(hv, n2, x2);
    const std::size_t o = 3 * static_cast<std::size_t>(q);
    aos3_store4(v + o, _mm256_blendv_pd(v0, n0, keep), _mm256_blendv_pd(v1, n1, keep), _mm256_blendv_pd(v2, n2, keep));
    aos3_store4(x + o, _mm256_blendv_pd(x0, y0, keep), _mm256_blendv_pd(x1, y1, keep), _mm256_blendv_pd(x2, y2, keep));
  }
  return end;
}
#endif

}  // namespace loom

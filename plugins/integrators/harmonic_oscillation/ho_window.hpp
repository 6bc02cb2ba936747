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
// HoStorage.WindowedSweepIsBitIdentical).
#pragma once

#include <algorithm>
#include <cstddef>
#include <cstring>
#include <limits>
#include <vector>

#include "loom/common.hpp"
#include "loom/kernels/ho.hpp"
#include "loom/spring_groups.hpp"

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
  const T tiny = std::numeric_limits<T>::min();
  for (Index r = 0; r < len; ++r) {
    const Index p = a + Step * r, q = p + off;
    const std::size_t c = Table ? static_cast<std::size_t>(ID[r]) : static_cast<std::size_t>(r);
    using std::sqrt;
    using std::abs;
    const T d0 = X[q] - X[p], d1 = Y[q] - Y[p], d2 = Z[q] - Z[p];
    const T l2 = d0 * d0 + d1 * d1 + d2 * d2;
    const T l = sqrt(l2);
    const T inv = T(1) / (l + tiny);
    const T n0 = d0 * inv, n1 = d1 * inv, n2 = d2 * inv;
    const T delta = l - L0[c];
    const T ddot = n0 * (VX[q] - VX[p]) + n1 * (VY[q] - VY[p]) + n2 * (VZ[q] - VZ[p]);
    T sv;
    if constexpr (kKc)
      sv = KX[c] * delta + KV[c] * abs(ddot);
    else
      sv = KX[c] * delta + KV[c] * ddot;
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

}  // namespace loom

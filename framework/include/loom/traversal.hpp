// The one parallel traversal of Loom's element loops (header-only; issue 19).
//
// Every plugin loop that scatters into vertices (spring forces, spring Jacobian blocks, the HO
// impulses) and every loop over vertices goes through the two skeletons below, so the parallel
// regions, barriers and the serial/parallel rule (common.hpp, docs/ARCHITECTURE.md "Threads")
// live in one place:
//
//   for_vertex_ranges(n, body)   body(v0, v1) on contiguous vertex ranges covering 0..n-1;
//                                one parallel region with one implicit barrier, or one call on
//                                the calling thread when n < kParallelMinVertices.
//
//   traverse_parts(layout, parallel, part, cross, after_count, after)
//                                ONE parallel region per call:
//                                  1. part(p) for every part p of the layout (omp for, static);
//                                  2. barrier, then the cross items: cross(k0, k1) on ranges of
//                                     the layout's order(); all of them on one thread when the
//                                     layout says cross_serial(), else colour by colour in chunks
//                                     of kTraversalChunk (ranges run at the same time share no
//                                     vertex), one barrier per colour;
//                                  3. barrier, then after(r) for r < after_count (omp for, static):
//                                     per-vertex work that needs every item applied (HO finalises
//                                     the vertices that cross springs touch here).
//                                The ranges do not depend on the thread count, so per-vertex sums
//                                are deterministic for a fixed layout. Nested inside a parallel
//                                region it runs on that one thread, still correctly.
//
// The layout (SpringLayout in loom/spring_layout.hpp) provides parts(), colour_begin(c),
// colour_end(c), num_colours() and cross_serial(). No allocation, no virtual call; the bodies
// are inlined.
#pragma once

#include <algorithm>
#include <cstdint>

#ifdef _OPENMP
#include <omp.h>
#endif

#include "loom/common.hpp"

namespace loom {

/// Cross items per chunk when a colour runs in parallel.
constexpr Index kTraversalChunk = 1024;

/// Number of threads a parallel region opened now would get (1 without OpenMP).
inline int traversal_threads() {
#ifdef _OPENMP
  return omp_get_max_threads();
#else
  return 1;
#endif
}

/// body(v0, v1) on contiguous ranges covering [0, n) exactly once: one range per thread
/// (static split), or the single range [0, n) on the calling thread when n is below the rule
/// of common.hpp (min_parallel, default kParallelMinVertices) or one thread is available.
template <class Body>
void for_vertex_ranges(Index n, Body&& body, Index min_parallel = kParallelMinVertices) {
  if (n <= 0) return;
  if (n < min_parallel || traversal_threads() == 1) {
    body(Index(0), n);
    return;
  }
#pragma omp parallel
  {
#ifdef _OPENMP
    const Index T = static_cast<Index>(omp_get_num_threads()), t = static_cast<Index>(omp_get_thread_num());
#else
    const Index T = 1, t = 0;
#endif
    const Index v0 = static_cast<Index>((static_cast<std::int64_t>(n) * t) / T);
    const Index v1 = static_cast<Index>((static_cast<std::int64_t>(n) * (t + 1)) / T);
    if (v1 > v0) body(v0, v1);
  }
}

/// The part / cross / after skeleton (see the top of this file).
template <class Layout, class Part, class Cross, class After>
void traverse_parts(const Layout& L, bool parallel, Part&& part, Cross&& cross, Index after_count, After&& after) {
  const int P = L.parts();
  const int C = L.num_colours();
  const bool serial_cross = L.cross_serial();
  if (!parallel || traversal_threads() == 1) {
    // The same calls in the same order as a team of one thread, without opening a region: in a
    // region of one thread libgomp still ends every barrier with a futex wake (a system call),
    // three to five per step, as much as a small cloth's whole step.
    for (int p = 0; p < P; ++p) part(p);
    if (C > 0) {
      if (serial_cross) {
        cross(L.colour_begin(0), L.colour_end(C - 1));
      } else {
        for (int c = 0; c < C; ++c) {
          const Index b = L.colour_begin(c), e = L.colour_end(c);
          const Index chunks = (e - b + kTraversalChunk - 1) / kTraversalChunk;
          for (Index q = 0; q < chunks; ++q) cross(b + q * kTraversalChunk, std::min(e, b + (q + 1) * kTraversalChunk));
        }
      }
    }
    for (Index r = 0; r < after_count; ++r) after(r);
    return;
  }
#pragma omp parallel
  {
#pragma omp for schedule(static)
    for (int p = 0; p < P; ++p) part(p);
    // implicit barrier: every part is done
    if (C > 0) {
      if (serial_cross) {
#pragma omp single
        cross(L.colour_begin(0), L.colour_end(C - 1));
      } else {
        for (int c = 0; c < C; ++c) {
          const Index b = L.colour_begin(c), e = L.colour_end(c);
          const Index chunks = (e - b + kTraversalChunk - 1) / kTraversalChunk;
#pragma omp for schedule(static)
          for (Index q = 0; q < chunks; ++q) cross(b + q * kTraversalChunk, std::min(e, b + (q + 1) * kTraversalChunk));
        }
      }
    }
    if (after_count > 0) {
#pragma omp for schedule(static)
      for (Index r = 0; r < after_count; ++r) after(r);
    }
  }
}

/// traverse_parts without the after phase.
template <class Layout, class Part, class Cross>
void traverse_parts(const Layout& L, bool parallel, Part&& part, Cross&& cross) {
  traverse_parts(L, parallel, part, cross, Index(0), [](Index) {});
}

}  // namespace loom

// The fused spring path of symplectic_euler (loom/explicit_springs.hpp: one pass over the
// springs that updates each vertex as soon as its force is complete) against the generic path
// (material forces, then the vertex loop).
#include <gtest/gtest.h>

#include <omp.h>

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <numeric>
#include <random>
#include <set>
#include <string>
#include <utility>
#include <vector>

#include "loom/explicit_springs.hpp"
#include "loom/kernels/spring.hpp"
#include "loom/params.hpp"
#include "symplectic_euler.hpp"
#include "test_spring_material.hpp"

using namespace loom;
using loom::testing::make_scene;
using loom::testing::TestSpringMaterial;

namespace {
// Two runs' results (x then v, in the user's numbering) equal to rounding: positions to xtol and
// velocities to vtol of their scale (by default 1e-13 and 1e-11); and the springs did move the
// cloth by more than min_moved.
void expect_runs_agree(const std::vector<double> res[2], const std::vector<double>& x0, const std::string& what,
                       double xtol = 1e-13, double vtol = 1e-11, double min_moved = 1e-6) {
  const std::size_t m3 = x0.size();
  double sx = 0, sv = 0, moved = 0;
  for (std::size_t q = 0; q < m3; ++q) {
    sx = std::max(sx, std::abs(res[0][q]));
    sv = std::max(sv, std::abs(res[0][m3 + q]));
    moved = std::max(moved, std::abs(res[0][q] - x0[q]));
  }
  EXPECT_GT(moved, min_moved) << what;
  for (std::size_t q = 0; q < m3; ++q) {
    ASSERT_NEAR(res[1][q], res[0][q], xtol * sx) << what << " x " << q;
    ASSERT_NEAR(res[1][m3 + q], res[0][m3 + q], vtol * sv) << what << " v " << q;
  }
}
}  // namespace

// Equal to rounding, with dampers, fixed and moving pins; the same bits on 1 and 2 threads.
TEST(SymplecticEulerFused, MatchesGenericPathAndThreadCounts) {
  const int nx = 52;   // 52 x 52 vertices, ~10k springs: above kParallelMinSprings
  const loom::testing::TestCloth cloth = loom::testing::make_test_cloth(nx, true);
  const std::vector<double>&x = cloth.x, &v = cloth.v, &m = cloth.m;
  const SpringSet& s = cloth.springs;
  ASSERT_GE(s.size(), kParallelMinSprings);
  const Index fixed = nx * (nx - 1), moving = nx * nx - 1;
  std::vector<double> res[3];
  for (int run = 0; run < 3; ++run) {   // 0: generic, 1: fused 1 thread, 2: fused 2 threads
    omp_set_num_threads(run == 2 ? 2 : 1);
    auto scene = make_scene(x, v, m, {fixed, moving}, {0, -9.81, 0}, std::make_unique<TestSpringMaterial>(s, m, run > 0));
    for (int e = 0; e < 3; ++e) scene->state.v[3 * moving + e] = 0.1 * (e + 1);
    symplectic_euler::SymplecticEuler se{Params()};
    se.prepare(*scene, 1e-4);
    EXPECT_EQ(se.fused(), run > 0);
    for (int st = 0; st < 40; ++st) se.step(*scene, 1e-4);
    for (int e = 0; e < 3; ++e) {
      EXPECT_EQ(scene->state.x[3 * fixed + e], x[3 * fixed + e]);   // bit for bit
      EXPECT_EQ(scene->state.v[3 * moving + e], 0.1 * (e + 1));
    }
    res[run] = scene->state.x;
    res[run].insert(res[run].end(), scene->state.v.begin(), scene->state.v.end());
  }
  omp_set_num_threads(2);
  // The test material's force k (l - l0) d / l and the kernel's k (1 - l0/l) d round differently
  // near the rest length (the cancellation in 1 - l0/l costs about 1/strain ulps, strain ~ 1e-4
  // here), so the velocities agree to 1e-9 of their scale, the positions to 1e-12 of theirs.
  expect_runs_agree(res, x, "fused against generic", 1e-12, 1e-9, 1e-5);
  for (std::size_t q = 0; q < res[1].size(); ++q) ASSERT_EQ(res[2][q], res[1][q]) << q;
}

// The blocked sweep (forces of 128 springs by one vectorised loop, then scattered) and the
// grouped, windowed sweep (loom/spring_groups.hpp) against the one-spring-at-a-time sweep: the
// same step up to rounding, damped and undamped, in double and float; the same bits on 1 and 2
// threads. The grid carries duplicate springs on some pairs (as the kang_cho_table1 stencil
// does), stride-2 bending springs and two pinned corners.
struct SweepCloth {
  Index n = 0;
  SpringSet s;
  std::vector<double> x0, v0, w;
};
SweepCloth sweep_cloth(int nx, bool damped) {
  SweepCloth c;
  c.n = nx * nx;
  for (int r = 0; r < nx; ++r)
    for (int col = 0; col < nx; ++col) {
      c.x0.insert(c.x0.end(), {0.02 * col, 0.001 * std::sin(0.7 * col + r), 0.02 * r});
      c.v0.insert(c.v0.end(), {0.01 * std::sin(r + 2.0 * col), 0.02 * std::cos(3.0 * r - col), 0.0});
      c.w.push_back(r == nx - 1 && (col == 0 || col == nx - 1) ? 0.0 : 1000.0 / (1 + 0.5 * ((r * 7 + col * 3) % 5)));
    }
  for (int r = 0; r < nx; ++r)
    for (int col = 0; col < nx; ++col) {
      const int a = r * nx + col;
      const double cd = damped ? 0.02 : 0.0;
      if (col + 1 < nx) c.s.add(a, a + 1, 0.02, 2000, cd, SpringClass::Structural);
      if (r + 1 < nx) c.s.add(a + nx, a, 0.02, 2000, cd, SpringClass::Structural);
      if (col + 1 < nx && r + 1 < nx) c.s.add(a, a + nx + 1, 0.02 * std::sqrt(2.0), 500, 0.0, SpringClass::Shear);
      if (col + 1 < nx && r + 1 < nx && (r + col) % 3 == 0)   // a second spring on some pairs
        c.s.add(a + nx + 1, a, 0.02 * std::sqrt(2.0), 300, 0.0, SpringClass::Shear);
      if (col + 2 < nx) c.s.add(a, a + 2, 0.04, 50, 0.0, SpringClass::Bend);
    }
  return c;
}

// mode 0: plain, 1: blocked, 2: grouped and windowed (with blocks of `block` vertices).
template <class T>
void sweep_matches_plain(int mode, bool damped, double tol, Index block = kSpringGroupBlock) {
  const SweepCloth cl = sweep_cloth(60, damped);
  ASSERT_GE(cl.s.size(), kParallelMinSprings);
  SpringSweep<double> plain, grouped;
  plain.build(cl.n, cl.s, false);
  grouped.build(cl.n, cl.s, true, block);
  EXPECT_FALSE(plain.grouped);
  ASSERT_TRUE(grouped.grouped);
  ASSERT_GT(grouped.win_cap, 0);
  // every segment lies in one block of its part: its lower endpoints within [v0, v0 + block)
  for (int p = 0; p < grouped.layout.parts(); ++p) {
    const Index vb = grouped.layout.part_vertex_begin(p);
    for (Index bk = grouped.part_block[p]; bk < grouped.part_block[p + 1]; ++bk)
      for (Index sg = grouped.blocks[bk].seg_begin; sg < grouped.blocks[bk].seg_end; ++sg) {
        const SpringSegment& G = grouped.segs[sg];
        ASSERT_LE(G.len, block);
        const Index last = G.i0 + G.step * (G.len - 1);
        ASSERT_EQ((G.i0 - vb) / block, (last - vb) / block);
        ASSERT_LT(last, grouped.blocks[bk].vertex_end);
        for (Index r = 0; r < G.len; ++r) {   // the segment's springs are what it says
          ASSERT_EQ(grouped.i[G.begin + r], G.i0 + G.step * r);
          ASSERT_EQ(grouped.j[G.begin + r], G.i0 + G.step * r + G.off);
        }
      }
  }
  std::vector<T> res[3];
  for (int run = 0; run < 3; ++run) {   // plain 1 thread, mode 1 thread, mode 2 threads
    omp_set_num_threads(run == 2 ? 2 : 1);
    SpringSweep<T> sw;
    sw.convert_from(run > 0 && mode == 2 ? grouped : plain);
    sw.blocked = run > 0 && mode == 1;
    std::vector<T> x(cl.x0.begin(), cl.x0.end()), v(cl.v0.begin(), cl.v0.end()), f(x.size(), T(0));
    const std::vector<T> w(cl.w.begin(), cl.w.end());
    const T g[3] = {T(0), T(-9.81), T(0)};
    for (int st = 0; st < 30; ++st) se_step_springs<T>(sw, x.data(), v.data(), w.data(), f.data(), T(1e-4), g);
    for (T e : f) ASSERT_EQ(e, T(0));   // f is zero again on return
    res[run] = x;
    res[run].insert(res[run].end(), v.begin(), v.end());
  }
  omp_set_num_threads(2);
  const std::size_t m3 = cl.x0.size();
  double sx = 0, sv = 0, moved = 0;
  for (std::size_t q = 0; q < m3; ++q) {
    sx = std::max(sx, std::abs(double(res[0][q])));
    sv = std::max(sv, std::abs(double(res[0][m3 + q])));
    moved = std::max(moved, std::abs(double(res[0][q]) - cl.x0[q]));
  }
  EXPECT_GT(moved, 1e-6);
  for (std::size_t q = 0; q < res[0].size(); ++q) {
    ASSERT_NEAR(res[1][q], res[0][q], tol * (q < m3 ? sx : sv)) << q;
    ASSERT_EQ(res[2][q], res[1][q]) << q;
  }
}

TEST(SymplecticEulerFused, BlockedSweepMatchesPlainSweep) {
  for (bool damped : {false, true}) {
    sweep_matches_plain<double>(1, damped, 1e-9);
    sweep_matches_plain<float>(1, damped, 1e-3);
  }
}

TEST(SymplecticEulerFused, WindowedSweepMatchesPlainSweep) {
  for (bool damped : {false, true}) {
    sweep_matches_plain<double>(2, damped, 1e-9);
    sweep_matches_plain<float>(2, damped, 1e-3);
  }
}

// The block size of the grouping (group_springs' block, default kSpringGroupBlock) changes only the
// order of the additions into a vertex: blocks of 16, 64, 128 and 256 vertices
// all match the plain sweep to rounding, and 2 threads give 1 thread's bits.
TEST(SymplecticEulerFused, WindowedSweepAnyBlockSize) {
  for (Index block : {16, 64, 128, 256})
    for (bool damped : {false, true}) sweep_matches_plain<double>(2, damped, 1e-9, block);
}

// Issue 16: a unit-stride segment whose lower and upper ranges are disjoint (off >= len)
// computes its forces and scatters them in one pass (sweep_segment_forces_scatter); every slot
// then gets the same additions in the same order as with the two passes, so 30 steps with
// SpringSweep::fuse on (the default) and off give the same bits, damped and undamped, on 1 and 2
// threads. Rows of 80 vertices: the vertical and diagonal springs' segments are disjoint, the
// horizontal ones overlap, and both kinds must be present.
TEST(SymplecticEulerFused, FusedForceScatterIsBitIdentical) {
  for (bool damped : {false, true}) {
    const SweepCloth cl = sweep_cloth(80, damped);
    SpringSweep<double> sw;
    sw.build(cl.n, cl.s);
    ASSERT_TRUE(sw.grouped);
    EXPECT_TRUE(sw.fuse);
    int disjoint = 0, overlapping = 0;
    for (const SpringSegment& G : sw.segs)
      if (G.step == 1) (G.off >= G.len ? disjoint : overlapping) += 1;
    ASSERT_GT(disjoint, 100);
    ASSERT_GT(overlapping, 100);
    const double g[3] = {0.0, -9.81, 0.0};
    auto run = [&](bool fuse, int threads) {
      omp_set_num_threads(threads);
      sw.fuse = fuse;
      std::vector<double> x = cl.x0, v = cl.v0, f(x.size(), 0.0);
      for (int st = 0; st < 30; ++st) se_step_springs<double>(sw, x.data(), v.data(), cl.w.data(), f.data(), 1e-4, g);
      for (double e : f) EXPECT_EQ(e, 0.0);
      x.insert(x.end(), v.begin(), v.end());
      return x;
    };
    const std::vector<double> two_pass = run(false, 1);
    double change = 0;
    for (int threads : {1, 2}) {
      const std::vector<double> fused = run(true, threads);
      ASSERT_EQ(two_pass.size(), fused.size());
      for (std::size_t q = 0; q < fused.size(); ++q) {
        ASSERT_EQ(two_pass[q], fused[q]) << "damped " << damped << " threads " << threads << " entry " << q;
        const double start = q < cl.x0.size() ? cl.x0[q] : cl.v0[q - cl.x0.size()];
        change = std::max(change, std::abs(fused[q] - start));
      }
    }
    EXPECT_GT(change, 1e-6);   // the springs did act
  }
  omp_set_num_threads(2);
}

// Issue 16: duplicate springs on the same pair (as in the kang_cho_table1 stencil) give twin
// segments (SpringSegment::twin), whose d, inverse length and du the windowed sweep computes once
// (sweep_segment_forces_twin, sweep_segment_forces_scatter_twin). Each slot gets the two
// segments' additions in the order of the two segments run one after the other, so 30 steps with
// SpringSweep::twins on (the default) give the bits of twins off, damped and undamped, fused and
// two-pass, on 1 and 2 threads; and the one-spring-at-a-time sweep's result to rounding. The
// duplicates have their own constants, and there are twin pairs of every kind (unit stride with
// disjoint and with overlapping ranges, stride 2). (With merge_duplicates off: by default the
// sweep merges duplicates into one spring, next test.)
TEST(SymplecticEulerFused, TwinSegmentsAreBitIdentical) {
  const int nx = 130;   // rows longer than a block: most blocks hold one row's segments
  for (bool damped : {false, true}) {
    SweepCloth cl = sweep_cloth(nx, damped);
    const double cd = damped ? 0.03 : 0.0;
    for (int r = 0; r < nx; ++r)
      for (int col = 0; col < nx; ++col) {
        const int a = r * nx + col;
        if (col + 1 < nx) cl.s.add(a + 1, a, 0.0201, 1500, cd, SpringClass::Structural);   // overlapping twins
        if (r + 1 < nx) cl.s.add(a, a + nx, 0.0199, 2500, 0.5 * cd, SpringClass::Structural);   // disjoint twins
        if (col + 2 < nx && (r + col) % 2 == 0)   // stride-2 twins
          for (int t = 0; t < 2; ++t) cl.s.add(a, a + 2, 0.04 + 0.001 * t, 60 + 20 * t, cd, SpringClass::Bend);
      }
    SpringSweep<double> sw, plain;
    sw.merge_duplicates = plain.merge_duplicates = false;   // keep the duplicates: twin segments
    sw.build(cl.n, cl.s);
    plain.build(cl.n, cl.s, false);
    ASSERT_TRUE(sw.grouped);
    EXPECT_TRUE(sw.twins);
    EXPECT_EQ(sw.size(), cl.s.size());
    int disjoint = 0, overlapping = 0, stride2 = 0;
    for (std::size_t sg = 0; sg < sw.segs.size(); ++sg) {
      const SpringSegment& G = sw.segs[sg];
      if (!G.twin) continue;
      ASSERT_LT(sg + 1, sw.segs.size());
      const SpringSegment& H = sw.segs[sg + 1];
      for (Index r = 0; r < G.len; ++r) {   // the same endpoints, spring by spring
        ASSERT_EQ(sw.i[G.begin + r], sw.i[H.begin + r]);
        ASSERT_EQ(sw.j[G.begin + r], sw.j[H.begin + r]);
      }
      if (G.step == 2) ++stride2;
      else (G.off >= G.len ? disjoint : overlapping) += 1;
    }
    EXPECT_GT(disjoint, 100);
    EXPECT_GT(overlapping, 100);
    EXPECT_GT(stride2, 100);
    const double g[3] = {0.0, -9.81, 0.0};
    auto run = [&](SpringSweep<double>& s, bool twins, bool fuse, int threads) {
      omp_set_num_threads(threads);
      s.twins = twins;
      s.fuse = fuse;
      std::vector<double> x = cl.x0, v = cl.v0, f(x.size(), 0.0);
      for (int st = 0; st < 30; ++st) se_step_springs<double>(s, x.data(), v.data(), cl.w.data(), f.data(), 1e-4, g);
      for (double e : f) EXPECT_EQ(e, 0.0);
      x.insert(x.end(), v.begin(), v.end());
      return x;
    };
    const std::vector<double> ref = run(plain, true, true, 1);
    const std::size_t m3 = cl.x0.size();
    double sx = 0, sv = 0;
    for (std::size_t q = 0; q < m3; ++q) {
      sx = std::max(sx, std::abs(ref[q]));
      sv = std::max(sv, std::abs(ref[m3 + q]));
    }
    double change = 0;
    for (bool fuse : {true, false}) {
      const std::vector<double> single = run(sw, false, fuse, 1);
      for (int threads : {1, 2}) {
        const std::vector<double> twin = run(sw, true, fuse, threads);
        ASSERT_EQ(single.size(), twin.size());
        for (std::size_t q = 0; q < twin.size(); ++q) {
          ASSERT_EQ(single[q], twin[q]) << "damped " << damped << " fuse " << fuse << " threads " << threads
                                        << " entry " << q;
          ASSERT_NEAR(twin[q], ref[q], q < m3 ? 1e-12 * sx : 1e-9 * sv) << q;
          const double start = q < m3 ? cl.x0[q] : cl.v0[q - m3];
          change = std::max(change, std::abs(twin[q] - start));
        }
      }
    }
    EXPECT_GT(change, 1e-6);   // the springs did act
    sw.twins = true;
    sw.fuse = true;
  }
  omp_set_num_threads(2);
}

// The windowed sweep's vectorised finalisation (SeFinish::finalise4, four vertices at a time from
// the window) gives the per-vertex update's bits: damped and undamped (velocities from the window
// or from v), free vertices, moving pins (w = 0, v != 0), fixed pins whose coordinates include
// -0 (left untouched: a pass of x + h 0 would make them +0), and the vertices cross springs
// touch (deferred, two parts), on 1 and 2 threads; a grid of odd width leaves scalar remainders.
TEST(SymplecticEulerFused, BlockFinaliseIsBitIdentical) {
  const int nx = 67;
  for (bool damped : {false, true}) {
    SweepCloth cl = sweep_cloth(nx, damped);
    int fixed = 0;
    for (Index q = 5; q < cl.n; q += 97) {   // fixed pins, some at -0
      cl.w[q] = 0.0;
      for (int e = 0; e < 3; ++e) cl.v0[3 * q + e] = 0.0;
      cl.x0[3 * q + 1] = -0.0;
      ++fixed;
    }
    int moving = 0;
    for (Index q = 11; q < cl.n; q += 89)   // moving pins
      if (cl.w[q] != 0.0) {
        cl.w[q] = 0.0;
        cl.v0[3 * q] = 0.05, cl.v0[3 * q + 1] = 0.0, cl.v0[3 * q + 2] = -0.03;
        ++moving;
      }
    ASSERT_GT(fixed, 20);
    ASSERT_GT(moving, 20);
    SpringSweep<double> sw;
    sw.build(cl.n, cl.s);
    ASSERT_TRUE(sw.grouped);
    ASSERT_GE(sw.layout.parts(), 2);   // cross springs, deferred vertices
    ASSERT_FALSE(sw.deferred.empty());
    const double g[3] = {0.0, -9.81, 0.0};
    auto run = [&](bool block, int threads) {
      omp_set_num_threads(threads);
      sw.block_finalise = block;
      std::vector<double> x = cl.x0, v = cl.v0, f(x.size(), 0.0);
      for (int st = 0; st < 25; ++st) se_step_springs<double>(sw, x.data(), v.data(), cl.w.data(), f.data(), 1e-4, g);
      for (double e : f) EXPECT_EQ(e, 0.0);
      x.insert(x.end(), v.begin(), v.end());
      return x;
    };
    const std::vector<double> ref = run(false, 1);
    for (Index q = 5; q < cl.n; q += 97) {   // the fixed pins did not move, -0 kept
      EXPECT_TRUE(std::signbit(ref[3 * q + 1])) << q;
      EXPECT_EQ(ref[3 * q], cl.x0[3 * q]) << q;
    }
    double change = 0;
    for (std::size_t e = 0; e < cl.x0.size(); ++e) change = std::max(change, std::abs(ref[e] - cl.x0[e]));
    EXPECT_GT(change, 1e-5);   // the cloth moved
    for (int threads : {1, 2}) {
      const std::vector<double> got = run(true, threads);
      ASSERT_EQ(got.size(), ref.size());
      for (std::size_t e = 0; e < got.size(); ++e)
        ASSERT_EQ(std::memcmp(&got[e], &ref[e], sizeof(double)), 0)
            << "damped " << damped << " threads " << threads << " entry " << e << ": " << got[e] << " vs " << ref[e];
    }
    sw.block_finalise = true;
  }
  omp_set_num_threads(2);
}

// One force pass of the windowed sweep: fin is called exactly once per vertex, with the force of
// an independent per-spring sum over the original spring set (kernels::spring_force, the set's
// order) to rounding; f is zero again on return.
TEST(SymplecticEulerFused, WindowedForcesPerVertex) {
  for (bool damped : {false, true}) {
    const SweepCloth cl = sweep_cloth(70, damped);
    std::vector<double> ref(cl.x0.size(), 0.0);
    for (Index q = 0; q < cl.s.size(); ++q) {
      const Index a = cl.s.i[q], b = cl.s.j[q];
      double fi[3];
      if (damped)
        kernels::spring_force_damped(&cl.x0[3 * a], &cl.x0[3 * b], &cl.v0[3 * a], &cl.v0[3 * b], cl.s.stiffness[q],
                                     cl.s.rest_length[q], cl.s.damping[q], fi);
      else
        kernels::spring_force(&cl.x0[3 * a], &cl.x0[3 * b], cl.s.stiffness[q], cl.s.rest_length[q], fi);
      for (int e = 0; e < 3; ++e) {
        ref[3 * a + e] += fi[e];
        ref[3 * b + e] -= fi[e];
      }
    }
    double scale = 0;
    for (double e : ref) scale = std::max(scale, std::abs(e));
    ASSERT_GT(scale, 0.0);
    for (int threads : {1, 2}) {
      omp_set_num_threads(threads);
      SpringSweep<double> sw;
      sw.build(cl.n, cl.s);
      ASSERT_TRUE(sw.grouped);
      std::vector<double> f(cl.x0.size(), 0.0), got(cl.x0.size(), 0.0);
      std::vector<int> calls(static_cast<std::size_t>(cl.n), 0);
      sw.forces(cl.x0.data(), cl.v0.data(), f.data(), [&](Index q, const double* fq) {
        ++calls[q];
        for (int e = 0; e < 3; ++e) got[3 * q + e] = fq[e];
      });
      for (Index q = 0; q < cl.n; ++q) ASSERT_EQ(calls[q], 1) << q;
      for (double e : f) ASSERT_EQ(e, 0.0);
      for (std::size_t q = 0; q < ref.size(); ++q) ASSERT_NEAR(got[q], ref[q], 1e-12 * scale) << q;
    }
  }
  omp_set_num_threads(2);
}

// reorder: the fused step in the RCM order equals the step in the mesh's order to rounding,
// reported in the mesh's numbering (positions, velocities; the fixed pin bit for bit); auto
// reorders a large mesh numbered at random and leaves a row-by-row grid alone.
namespace {
struct Shuffled {
  std::vector<double> x, v, m;
  SpringSet s;
  std::vector<Index> pins;
  Shuffled(int nx, bool shuffle) {
    const int n = nx * nx;
    std::vector<Index> pi(n);
    std::iota(pi.begin(), pi.end(), 0);
    if (shuffle) std::shuffle(pi.begin(), pi.end(), std::mt19937(17));
    x.resize(3 * n);
    v.resize(3 * n);
    m.resize(n);
    for (int r = 0; r < nx; ++r)
      for (int c = 0; c < nx; ++c) {
        const Index u = pi[r * nx + c];
        x[3 * u] = 0.02 * c;
        x[3 * u + 1] = 0.001 * std::sin(0.7 * c + r);
        x[3 * u + 2] = 0.02 * r;
        v[3 * u] = 0.01 * std::sin(r + 2.0 * c);
        v[3 * u + 1] = 0.02 * std::cos(3.0 * r - c);
        m[u] = 1e-3 * (1 + 0.5 * ((r * 7 + c * 3) % 5));
      }
    for (int r = 0; r < nx; ++r)
      for (int c = 0; c < nx; ++c) {
        const int a = r * nx + c;
        if (c + 1 < nx) s.add(pi[a], pi[a + 1], 0.02, 2000, 0.02, SpringClass::Structural);
        if (r + 1 < nx) s.add(pi[a + nx], pi[a], 0.02, 2000, 0.0, SpringClass::Structural);
        if (c + 1 < nx && r + 1 < nx) s.add(pi[a], pi[a + nx + 1], 0.02 * std::sqrt(2.0), 500, 0.0, SpringClass::Shear);
        if (c + 2 < nx) s.add(pi[a], pi[a + 2], 0.04, 50, 0.0, SpringClass::Bend);
      }
    pins = {pi[nx * (nx - 1)], pi[nx * nx - 1]};
  }
};

}  // namespace

// Numbered at random: both runs take the plain sweep (grouping does not pay in either order).
// Numbered row by row: the mesh's order runs the grouped, windowed sweep, the RCM order the plain
// sweep (its numbering runs along anti-diagonals, so segments would be short): the windowed path
// against another path in another order.
TEST(SymplecticEulerReorder, ReorderedRunEqualsUserOrderRun) {
  for (bool shuffle : {true, false}) {
    const Shuffled g(40, shuffle);
    std::vector<double> res[2];
    for (int ro : {0, 1}) {
      auto scene = make_scene(g.x, g.v, g.m, g.pins, {0, -9.81, 0}, std::make_unique<TestSpringMaterial>(g.s, g.m));
      symplectic_euler::SymplecticEuler se{Params::from_string(ro ? "reorder: rcm\n" : "reorder: none\n")};
      se.prepare(*scene, 1e-4);
      EXPECT_TRUE(se.fused());
      EXPECT_EQ(se.reordered(), ro == 1);
      EXPECT_EQ(se.windowed(), !shuffle && ro == 0);
      for (int st = 0; st < 60; ++st) se.step(*scene, 1e-4);
      for (int e = 0; e < 3; ++e) EXPECT_EQ(scene->state.x[3 * g.pins[0] + e], g.x[3 * g.pins[0] + e]);
      res[ro] = scene->state.x;
      res[ro].insert(res[ro].end(), scene->state.v.begin(), scene->state.v.end());
    }
    expect_runs_agree(res, g.x, shuffle ? "shuffled" : "row by row");
  }
}

TEST(SymplecticEulerReorder, AutoRuleAndParameter) {
  for (bool shuffle : {true, false}) {
    const Shuffled g(130, shuffle);   // 16900 vertices >= kReorderMinVertices
    auto scene = make_scene(g.x, g.v, g.m, g.pins, {0, -9.81, 0}, std::make_unique<TestSpringMaterial>(g.s, g.m));
    symplectic_euler::SymplecticEuler se{Params()};
    se.prepare(*scene, 1e-4);
    EXPECT_EQ(se.reordered(), shuffle);
  }
  EXPECT_EQ(symplectic_euler::SymplecticEuler(Params::from_string("reorder: rcm\n")).reorder_mode(), ReorderMode::Rcm);
  EXPECT_EQ(symplectic_euler::SymplecticEuler(Params()).reorder_mode(), ReorderMode::Auto);
  EXPECT_THROW(symplectic_euler::SymplecticEuler(Params::from_string("reorder: metis\n")), InputError);
}

// The key merge_springs (default true): a grid whose shear springs are doubled (each duplicate with
// its own stiffness, rest length and damper, given with its endpoints swapped) steps with half of
// them merged away, and 60 steps equal the run with merge_springs: false to rounding, in the
// mesh's order and in the RCM order.
TEST(SymplecticEulerMerge, MergeSpringsKeyAgreesWithEverySpring) {
  Shuffled g(40, false);
  const Index base = g.s.size();
  for (Index q = 0; q < base; ++q)
    if (g.s.kind[q] == SpringClass::Shear)
      g.s.add(g.s.j[q], g.s.i[q], g.s.rest_length[q] * 1.01, 300.0, 0.01, SpringClass::Shear);
  std::set<std::pair<Index, Index>> pairs;
  for (Index q = 0; q < g.s.size(); ++q) pairs.insert(std::minmax(g.s.i[q], g.s.j[q]));
  const Index dups = g.s.size() - static_cast<Index>(pairs.size());
  ASSERT_GT(dups, 1000);
  for (const char* order : {"none", "rcm"}) {
    std::vector<double> res[2];
    for (int merge : {0, 1}) {
      auto scene = make_scene(g.x, g.v, g.m, g.pins, {0, -9.81, 0}, std::make_unique<TestSpringMaterial>(g.s, g.m));
      symplectic_euler::SymplecticEuler se{Params::from_string(std::string("reorder: ") + order +
                                                               (merge ? "\n" : "\nmerge_springs: false\n"))};
      se.prepare(*scene, 1e-4);
      ASSERT_TRUE(se.fused());
      EXPECT_EQ(se.merged_springs(), merge ? dups : 0);
      EXPECT_EQ(se.swept_springs(), g.s.size() - (merge ? dups : 0));
      for (int st = 0; st < 60; ++st) se.step(*scene, 1e-4);
      res[merge] = scene->state.x;
      res[merge].insert(res[merge].end(), scene->state.v.begin(), scene->state.v.end());
    }
    expect_runs_agree(res, g.x, order);
  }
  EXPECT_THROW(symplectic_euler::SymplecticEuler(Params::from_string("merge_springs: maybe\n")), InputError);
}

// Issue 16: merge_duplicate_springs folds springs on the same two endpoints into one whose force
// is the group's sum at every length and velocity. Checked against the group's forces summed in
// long double by this test's own formula, on groups of one to three springs given in either
// endpoint order, with different stiffnesses, rest lengths and dampers, at lengths from 0.5 to 2
// rest lengths and random relative velocities; a set without duplicates comes back unchanged,
// and equal rest lengths are kept exactly.
TEST(SymplecticEulerFused, MergedDuplicateSpringsGiveTheGroupsForce) {
  std::mt19937 rng(7);
  std::uniform_real_distribution<double> U(0.0, 1.0);
  const Index nv = 400;
  SpringSet s;
  std::vector<int> group_size;
  for (Index a = 0; a + 1 < nv; a += 2) {
    const int g = 1 + static_cast<int>(a / 2) % 3;
    group_size.push_back(g);
    const double l0 = 0.01 + 0.02 * U(rng);
    for (int t = 0; t < g; ++t) {
      const bool same_length = (a / 2) % 5 == 0;
      const double l = same_length ? l0 : l0 * (1.0 + 0.2 * (U(rng) - 0.5));
      const double k = 10.0 + 5000.0 * U(rng), c = (a / 2) % 4 == 0 ? 0.0 : 0.1 * U(rng);
      if (t % 2 == 0) s.add(a, a + 1, l, k, c, SpringClass::Structural);
      else s.add(a + 1, a, l, k, c, SpringClass::Shear);
    }
  }
  Index merged = -1;
  const SpringSet m = merge_duplicate_springs(s, &merged);
  ASSERT_EQ(m.size(), static_cast<Index>(group_size.size()));
  EXPECT_EQ(merged, s.size() - m.size());
  Index first = 0;
  for (std::size_t gi = 0; gi < group_size.size(); ++gi) {
    const int g = group_size[gi];
    const Index a = 2 * static_cast<Index>(gi);
    ASSERT_EQ(std::min(m.i[gi], m.j[gi]), a);
    ASSERT_EQ(std::max(m.i[gi], m.j[gi]), a + 1);
    bool equal_lengths = true;
    for (int t = 1; t < g; ++t) equal_lengths = equal_lengths && s.rest_length[first + t] == s.rest_length[first];
    if (equal_lengths) {
      EXPECT_EQ(m.rest_length[gi], s.rest_length[first]) << gi;
    }
    for (int trial = 0; trial < 20; ++trial) {
      const double len = s.rest_length[first] * (0.5 + 1.5 * U(rng));
      const double rate = U(rng) - 0.5;   // d(length)/dt
      long double sum = 0;
      for (int t = 0; t < g; ++t) {
        const Index q = first + t;
        sum += static_cast<long double>(s.stiffness[q]) * (static_cast<long double>(len) - s.rest_length[q]) +
               static_cast<long double>(s.damping[q]) * rate;
      }
      const double got = m.stiffness[gi] * (len - m.rest_length[gi]) + m.damping[gi] * rate;
      long double scale = 0;
      for (int t = 0; t < g; ++t) scale += s.stiffness[first + t] * len;
      EXPECT_NEAR(got, static_cast<double>(sum), 1e-14 * static_cast<double>(scale)) << "group " << gi;
    }
    first += g;
  }
  // no duplicates: the same set, bit for bit
  SpringSet single;
  for (Index a = 0; a + 1 < nv; ++a) single.add(a + 1, a, 0.01 + 1e-5 * a, 100.0 + a, 0.01 * (a % 3), SpringClass::Bend);
  const SpringSet same = merge_duplicate_springs(single, &merged);
  EXPECT_EQ(merged, 0);
  EXPECT_EQ(same.i, single.i);
  EXPECT_EQ(same.j, single.j);
  EXPECT_EQ(same.rest_length, single.rest_length);
  EXPECT_EQ(same.stiffness, single.stiffness);
  EXPECT_EQ(same.damping, single.damping);
}

// The sweep merges duplicate springs by default (SpringSweep::merge_duplicates): on the cloth of
// TwinSegmentsAreBitIdentical (duplicates of every kind, each with its own constants) 30 steps
// of the merged sweep agree with the one-spring-at-a-time sweep over every spring to rounding,
// damped and undamped, on 1 and 2 threads (the same bits on both), with half the duplicates'
// springs gone.
TEST(SymplecticEulerFused, MergedDuplicatesAgreeWithEverySpringToRounding) {
  const int nx = 130;
  for (bool damped : {false, true}) {
    SweepCloth cl = sweep_cloth(nx, damped);
    const double cd = damped ? 0.03 : 0.0;
    Index dups = 0;
    for (int r = 0; r < nx; ++r)
      for (int col = 0; col < nx; ++col) {
        const int a = r * nx + col;
        if (col + 1 < nx) {
          cl.s.add(a + 1, a, 0.0201, 1500, cd, SpringClass::Structural);
          ++dups;
        }
        if (r + 1 < nx) {
          cl.s.add(a, a + nx, 0.0199, 2500, 0.5 * cd, SpringClass::Structural);
          ++dups;
        }
        if (col + 2 < nx && (r + col) % 2 == 0) {
          cl.s.add(a, a + 2, 0.041, 80, cd, SpringClass::Bend);
          ++dups;
        }
      }
    std::set<std::pair<Index, Index>> pairs;   // the distinct endpoint pairs, counted here
    for (Index q = 0; q < cl.s.size(); ++q) pairs.insert(std::minmax(cl.s.i[q], cl.s.j[q]));
    ASSERT_GT(static_cast<Index>(cl.s.size() - pairs.size()), dups);   // sweep_cloth's own duplicates too
    dups = cl.s.size() - static_cast<Index>(pairs.size());
    SpringSweep<double> merged, every;
    every.merge_duplicates = false;
    merged.build(cl.n, cl.s);
    every.build(cl.n, cl.s, false);
    ASSERT_TRUE(merged.grouped);
    EXPECT_EQ(merged.merged, dups);
    EXPECT_EQ(merged.size(), cl.s.size() - dups);
    EXPECT_EQ(every.size(), cl.s.size());
    for (const SpringSegment& G : merged.segs) EXPECT_EQ(G.twin, 0);   // nothing left to pair
    const double g[3] = {0.0, -9.81, 0.0};
    auto run = [&](const SpringSweep<double>& s, int threads) {
      omp_set_num_threads(threads);
      std::vector<double> x = cl.x0, v = cl.v0, f(x.size(), 0.0);
      for (int st = 0; st < 30; ++st) se_step_springs<double>(s, x.data(), v.data(), cl.w.data(), f.data(), 1e-4, g);
      x.insert(x.end(), v.begin(), v.end());
      return x;
    };
    const std::vector<double> ref = run(every, 1);
    const std::vector<double> one = run(merged, 1), two = run(merged, 2);
    const std::size_t m3 = cl.x0.size();
    double sx = 0, sv = 0, change = 0, dx = 0, dv = 0;
    for (std::size_t q = 0; q < m3; ++q) {
      sx = std::max(sx, std::abs(ref[q]));
      sv = std::max(sv, std::abs(ref[m3 + q]));
    }
    for (std::size_t q = 0; q < ref.size(); ++q) {
      ASSERT_EQ(one[q], two[q]) << q;
      (q < m3 ? dx : dv) = std::max(q < m3 ? dx : dv, std::abs(one[q] - ref[q]));
      change = std::max(change, std::abs(ref[q] - (q < m3 ? cl.x0[q] : cl.v0[q - m3])));
    }
    EXPECT_LE(dx, 1e-12 * sx) << "damped " << damped;
    EXPECT_LE(dv, 1e-9 * sv) << "damped " << damped;
    EXPECT_GT(change, 1e-6);   // the springs did act
    if (std::getenv("LOOM_TEST_VERBOSE"))
      std::printf("damped %d: merged - every spring after 30 steps: |dx| %.3g (of %.3g), |dv| %.3g (of %.3g)\n",
                  damped, dx, sx, dv, sv);
  }
  omp_set_num_threads(2);
}

// SelfCollision::resolve's filters by relative motion (the near list, the CCD passes over the
// whole lists and the fail-safe skip a pair whose distance at the lists' reference less the
// largest relative displacement of a vertex of each element, since the reference and within the
// step, is above the thickness / the CCD tolerance). Two layers translating together by several
// thicknesses per step while one sinks through the other: no intersecting triangle pair at any
// step, with the full response and with the fail-safe alone, and the near list holds only a
// part of the lists (the common translation does not make the sheet's neighbours near).
#include <gtest/gtest.h>

#include <algorithm>
#include <cstdio>
#include <cstdlib>
#include <random>
#include <vector>

#include "loom/intersection_check.hpp"
#include "loom/mesh.hpp"
#include "loom/self_collision.hpp"
#include "loom/state.hpp"

namespace {

using loom::Index;
using loom::Mesh;
using loom::SelfCollision;
using loom::State;

constexpr Index kSide = 10;       // vertices per side of each layer
constexpr double kDx = 0.01;      // spacing (m)
constexpr double kTh = 0.0025;    // thickness (m)

// Lower layer at y = 0, upper at y = 2.5 th, shifted by (0.37, 0.29) cells.
Mesh two_layers() {
  const Mesh g = loom::make_grid(kSide, kSide, (kSide - 1) * kDx, (kSide - 1) * kDx, loom::GridPlane::XZ);
  Mesh m;
  m.positions = g.positions;
  m.triangles = g.triangles;
  const Index nv = g.num_vertices();
  for (Index i = 0; i < nv; ++i) {
    m.positions.push_back(g.positions[3 * i] + 0.37 * kDx);
    m.positions.push_back(2.5 * kTh);
    m.positions.push_back(g.positions[3 * i + 2] + 0.29 * kDx);
  }
  for (Index t : g.triangles) m.triangles.push_back(t + nv);
  m.source = "two layers";
  return m;
}

struct LayerRun {
  int worst = 0;
  Index near = 0, candidates = 0;
};

// 20 steps of h = 0.01: every vertex moves by a common (3, 0.5, 2) thicknesses per step, the
// upper layer sinks by 0.6 thickness per step relative to the lower one (12 thicknesses over the
// run: it would pass through it), plus a random relative part of up to 0.2 thickness.
LayerRun run(const SelfCollision::Options& o, bool respond) {
  const Mesh mesh = two_layers();
  const Index n = mesh.num_vertices(), nv = kSide * kSide;
  State s;
  s.resize(n);
  for (Index i = 0; i < n; ++i) s.mass[i] = 0.001;
  s.update_inverse_masses();
  s.x = mesh.positions;
  SelfCollision sc(o, mesh);
  std::mt19937 rng(3);
  std::uniform_real_distribution<double> U(-1.0, 1.0);
  const double h = 0.01, common[3] = {3 * kTh, 0.5 * kTh, 2 * kTh};
  LayerRun r;
  for (int step = 0; step < 20; ++step) {
    const std::vector<double> x0 = s.x;
    sc.begin_step(s);
    for (Index i = 0; i < n; ++i)
      for (int k = 0; k < 3; ++k) {
        double d = common[k] + 0.2 * kTh * U(rng) / 1.7320508;
        if (k == 1 && i >= nv) d -= 0.6 * kTh;
        s.x[3 * i + k] = x0[3 * i + k] + d;
        s.v[3 * i + k] = d / h;
      }
    if (respond) {
      sc.resolve(s, h);
      r.near = std::max(r.near, sc.last_stats().near);
      r.candidates = std::max(r.candidates, sc.last_stats().candidates_vt + sc.last_stats().candidates_ee);
    }
    r.worst = std::max(r.worst, static_cast<int>(loom::count_intersecting_pairs(mesh, s.x)));
  }
  return r;
}

}  // namespace

TEST(SelfCollisionRelativeFilters, LayersTranslatingTogetherNeverIntersectAndOnlyStackedPairsAreNear) {
  const LayerRun control = run({kTh, 0.0}, false);
  EXPECT_GT(control.worst, 0);  // unprotected, the upper layer passes through the lower one

  const LayerRun full = run({kTh, 0.0}, true);
  EXPECT_EQ(full.worst, 0);
  EXPECT_GT(full.near, 0);
  // By the bound from absolute motion (3.7 thicknesses per step) almost every listed pair would be near.
  EXPECT_LT(full.near, full.candidates / 2);

  SelfCollision::Options failsafe{kTh, 0.0};
  failsafe.ccd_iterations = 0;
  failsafe.repulsion = false;
  const LayerRun alone = run(failsafe, true);
  EXPECT_EQ(alone.worst, 0);
  if (std::getenv("LOOM_TEST_VERBOSE"))
    std::printf("control %d intersecting pairs; full response: near %d of %d listed; fail-safe alone: %d\n",
                control.worst, static_cast<int>(full.near), static_cast<int>(full.candidates), alone.worst);
}

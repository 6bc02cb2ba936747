// Shared by the Baraff-Witkin contact-operator tests: the folding cloth of tests/self_collision
// (a 0.4 m square standing on its edge collapses in folds onto a plane), built through the
// plugin loader with a given solver and stepped by a linked BaraffWitkin so that its contacts
// can be read; and the 0.5 s fold run checked by the exact intersection count.
#pragma once

#include <gtest/gtest.h>

#include <algorithm>
#include <array>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <memory>
#include <string>
#include <vector>

#include "baraff_witkin.hpp"
#include "loom/intersection_check.hpp"
#include "loom/registry.hpp"
#include "loom/scene.hpp"
#include "loom/self_collision.hpp"
#include "loom/simulation.hpp"

namespace loom_test {

inline bool verbose() { return std::getenv("LOOM_TEST_VERBOSE") != nullptr; }

/// Subtracts from p (3 values) the impulse h f over a step of a linear spring of stiffness k
/// between vertices i and j, linearised about the start positions x0: f = k (e.u) e on i, e the
/// unit direction x0_j - x0_i and u the displacement of j relative to i over the step (x - x0).
/// The friction tests read a vertex's friction impulse from its momentum balance with this.
inline void subtract_linear_spring_impulse(const std::vector<double>& x0, const std::vector<double>& x, loom::Index i,
                                           loom::Index j, double h, double k, double* p) {
  double e[3], u[3], el = 0;
  for (int c = 0; c < 3; ++c) {
    e[c] = x0[3 * j + c] - x0[3 * i + c];
    u[c] = (x[3 * j + c] - x0[3 * j + c]) - (x[3 * i + c] - x0[3 * i + c]);
    el += e[c] * e[c];
  }
  el = std::sqrt(el);
  double eu = 0;
  for (int c = 0; c < 3; ++c) eu += e[c] / el * u[c];
  for (int c = 0; c < 3; ++c) p[c] -= h * k * eu * e[c] / el;
}

struct Fold {
  loom::Registry registry;
  loom::PluginLoader loader{registry};
  std::unique_ptr<loom::Simulation> sim;
  /// `integrator_keys`: more keys of the integrator map, e.g. ", substeps: 5".
  explicit Fold(const std::string& solver, const std::string& integrator_keys = "") {
    loom::Simulation::set_notes(false);
    sim = loom::Simulation::from_string(R"(
mesh: {grid: {nx: 14, ny: 14, width: 0.4, height: 0.4, plane: xy}}
material: {type: mass_spring, stencil: structural_shear_bend, stiffness: {structural: 300, shear: 300, bend: 0.2}, damping: 0.01, density: 0.2}
integrator: {type: baraff_witkin, dt: 2.0e-3)" + integrator_keys + R"(}
solver: )" + solver + R"(
threads: 1
gravity: [0, -9.81, 1.5]
colliders: [{type: plane, point: [0, -0.01, 0], normal: [0, 1, 0], friction: 0.8}]
self_collision: {thickness: 0.004, friction: 0.3}
)",
                                        "fold.yaml", std::string(LOOM_SOURCE_DIR) + "/scenes", {}, loader);
  }
  loom::Scene& scene() { return sim->scene(); }
};

constexpr double kFoldH = 2.0e-3;

inline void full_step(loom::Scene& sc, loom::BaraffWitkin& bw) {
  sc.self_collision->begin_step(sc.state);
  bw.step(sc, kFoldH);
  sc.self_collision->resolve(sc.state, kFoldH, &sc.colliders);
}

// Steps the folding cloth matrix-free until a step's solve holds at least `want` springs (the
// cloth lies in folds), checking after every step that the pattern is still the material's.
inline void fold_until_contacts(loom::Scene& sc, loom::BaraffWitkin& bw, loom::Index want,
                                loom::Index material_blocks) {
  for (int step = 0; step < 400; ++step) {
    full_step(sc, bw);
    ASSERT_EQ(bw.pattern_rebuilds(), 0) << "step " << step;
    ASSERT_EQ(bw.pattern().nnz_blocks(), material_blocks) << "step " << step;
    if (bw.self_contact()->stats().contacts >= want) return;
  }
  FAIL() << "the fold never held " << want << " springs";
}

// The springs of a matrix-free contact set assembled the way the other solvers get them:
// `as` becomes a copy of `mf` on the material's pattern extended by the springs' pairs (`P`).
inline void assemble_springs_pattern(const loom::ImplicitSelfContact& mf, loom::Scene& sc, loom::ImplicitSelfContact& as,
                                     loom::BsrPattern& P) {
  const loom::Index n = sc.state.size();
  as = mf;
  as.set_matrix_free(false);
  std::vector<std::array<loom::Index, 2>> pairs;
  sc.material->jacobian_pairs(pairs);
  const loom::BsrPattern material = loom::BsrPattern::from_pairs(n, pairs);
  const auto& extra = as.reserve_pairs(1u << 30);
  pairs.insert(pairs.end(), extra.begin(), extra.end());
  P = loom::BsrPattern::from_pairs(n, pairs);
  ASSERT_TRUE(as.bind(P, material));
}

// The folding cloth for 0.5 s (250 steps) with the springs matrix-free: no intersecting
// triangle pair at any fifth step (the exact count of loom check), the layers at least half
// the thickness apart, no vertex under the ground plane, and the pattern never extended.
inline void fold_run_never_intersects(const std::string& solver) {
  Fold f(solver);
  loom::Scene& sc = f.scene();
  loom::BaraffWitkin bw;
  bw.prepare(sc, kFoldH);
  ASSERT_TRUE(bw.self_contact_matrix_free());
  const loom::Index blocks = bw.pattern().nnz_blocks();
  const double th = sc.self_collision->options().thickness;
  long long springs = 0;
  int worst = 0;
  double dmin = 1e9, ymin = 1e9;
  for (int step = 0; step < 250; ++step) {
    full_step(sc, bw);
    springs += bw.self_contact()->stats().contacts;
    if (step % 5 == 4) {
      worst = std::max(worst, static_cast<int>(loom::count_intersecting_pairs(sc.mesh, sc.state.x)));
      dmin = std::min(dmin, sc.self_collision->min_distance(sc.state.x, th));
    }
    for (std::size_t i = 1; i < sc.state.x.size(); i += 3) ymin = std::min(ymin, sc.state.x[i]);
  }
  if (verbose())
    std::printf("springs %lld, worst intersections %d, min distance / thickness %.3f, lowest %.6f\n", springs, worst,
                dmin / th, ymin);
  EXPECT_GT(springs, 0);
  EXPECT_EQ(worst, 0);
  EXPECT_GE(dmin, 0.5 * th);
  EXPECT_GE(ymin, -0.01 - 1e-9);
  EXPECT_EQ(bw.pattern_rebuilds(), 0);
  EXPECT_EQ(bw.pattern().nnz_blocks(), blocks);
}

}  // namespace loom_test

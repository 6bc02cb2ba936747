// The self-contact springs of baraff_witkin applied matrix-free by filtered_pcg
// (ImplicitSelfContact as a loom::ExtraOperator, plugins/integrators/baraff_witkin/self_contact.hpp):
// on a real contact set of the folding cloth, the operator and its diagonal blocks equal the
// assembled blocks (the path the other solvers take) to rounding, A + E is symmetric positive
// definite, a step solved matrix-free equals the step solved with the assembled terms by a
// direct solver, and the pattern never grows.
#include <gtest/gtest.h>

#include <Eigen/Dense>

#include "dense_matrix.hpp"
#include "fold_scene.hpp"
#include <algorithm>
#include <array>
#include <filesystem>
#include <fstream>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <memory>
#include <random>
#include <span>
#include <sstream>
#include <string>
#include <vector>

#include "baraff_witkin.hpp"
#include "loom/forwarding_solver.hpp"
#include "loom/intersection_check.hpp"
#include "loom/registry.hpp"
#include "loom/scene.hpp"
#include "loom/self_collision.hpp"
#include "loom/simulation.hpp"

namespace {

using loom::BaraffWitkin;
using loom::Index;
using loom::Scene;

using loom_test::Fold;
using loom_test::fold_until_contacts;
using loom_test::full_step;
using loom_test::verbose;

constexpr double kH = loom_test::kFoldH;
const std::string kPcg = "{type: filtered_pcg, filtered_pcg: {tolerance: 1.0e-12, max_iterations: 5000}}";

using loom_test::dense;

// The matrix-free operator E as a dense matrix, column by column (E e_j).
Eigen::MatrixXd dense(const loom::ImplicitSelfContact& ic, Index n) {
  const Index N = 3 * n;
  Eigen::MatrixXd E = Eigen::MatrixXd::Zero(N, N);
  std::vector<double> e(N, 0.0), y(N);
  for (Index j = 0; j < N; ++j) {
    e[j] = 1;
    std::fill(y.begin(), y.end(), 0.0);
    ic.apply_add(e.data(), y.data(), 1.0);
    for (Index r = 0; r < N; ++r) E(r, j) = y[r];
    e[j] = 0;
  }
  return E;
}

}  // namespace

// On a real contact set (the folding cloth after it has collapsed, matrix-free steps), the
// operator the solver applies equals the springs' blocks assembled the way the other solvers
// get them (ImplicitSelfContact::add_terms on the pattern extended by reserve_pairs / bind):
// E x for random x and E's diagonal blocks agree to 1e-12 relative; E is symmetric and
// positive semidefinite, and A + E is positive definite; the pattern never grew.
TEST(BwContactOperator, MatrixFreeTermEqualsTheAssembledBlocksOnAFoldedCloth) {
  Fold f(kPcg);
  Scene& sc = f.scene();
  BaraffWitkin bw;
  bw.prepare(sc, kH);
  ASSERT_TRUE(bw.self_contact_matrix_free());
  const Index material_blocks = bw.pattern().nnz_blocks();
  fold_until_contacts(sc, bw, 40, material_blocks);
  const loom::ImplicitSelfContact& mf = *bw.self_contact();
  const Index n = sc.state.size(), N = 3 * n;
  ASSERT_GE(static_cast<Index>(mf.contacts().size()), 40);

  // The assembled term, from a copy of the same contact set.
  loom::ImplicitSelfContact as = mf;
  loom::BsrPattern P;
  loom_test::assemble_springs_pattern(mf, sc, as, P);
  if (HasFatalFailure()) return;
  loom::BsrMatrix E(&P);
  std::vector<double> b(N, 0.0);
  as.add_terms(E, b, sc.state.v, kH);

  std::mt19937 rng(7);
  std::uniform_real_distribution<double> U(-1.0, 1.0);
  std::vector<double> x(N), y_mf(N), y_as(N);
  for (int trial = 0; trial < 3; ++trial) {
    for (double& v : x) v = U(rng);
    std::fill(y_mf.begin(), y_mf.end(), 0.0);
    mf.apply_add(x.data(), y_mf.data(), 1.0);
    E.multiply(x, y_as);
    double diff = 0, scale = 0;
    for (Index k = 0; k < N; ++k) {
      diff = std::max(diff, std::abs(y_mf[k] - y_as[k]));
      scale = std::max(scale, std::abs(y_as[k]));
    }
    ASSERT_GT(scale, 0);
    EXPECT_LE(diff, 1e-12 * scale) << "trial " << trial;
  }
  std::vector<double> D(9 * static_cast<std::size_t>(n), 0.0);
  mf.add_diagonal(D.data());
  double ddiff = 0, dscale = 0;
  for (Index i = 0; i < n; ++i)
    for (int e = 0; e < 9; ++e) {
      const double a = E.block(P.diag[i])[e];
      ddiff = std::max(ddiff, std::abs(D[9 * static_cast<std::size_t>(i) + e] - a));
      dscale = std::max(dscale, std::abs(a));
    }
  EXPECT_LE(ddiff, 1e-12 * dscale);

  // Symmetric positive semidefinite E; A + E (A: the material's system of the same step)
  // symmetric positive definite.
  const Eigen::MatrixXd Ed = dense(mf, n), Ad = dense(bw.system_matrix());
  EXPECT_LE((Ed - Ed.transpose()).cwiseAbs().maxCoeff(), 1e-12 * Ed.cwiseAbs().maxCoeff());
  const Eigen::SelfAdjointEigenSolver<Eigen::MatrixXd> es(0.5 * (Ed + Ed.transpose()));
  EXPECT_GE(es.eigenvalues().minCoeff(), -1e-12 * es.eigenvalues().maxCoeff());
  const Eigen::MatrixXd M = Ad + Ed;
  EXPECT_LE((M - M.transpose()).cwiseAbs().maxCoeff(), 1e-12 * M.cwiseAbs().maxCoeff());
  const Eigen::LLT<Eigen::MatrixXd> llt(0.5 * (M + M.transpose()));
  EXPECT_EQ(llt.info(), Eigen::Success);
  if (verbose())
    std::printf("contacts %d, E eigenvalues [%.3g, %.3g]\n", static_cast<int>(mf.contacts().size()),
                es.eigenvalues().minCoeff(), es.eigenvalues().maxCoeff());
}

// One step from the same folded state, solved matrix-free by filtered_pcg (tolerance 1e-12) and
// with the terms assembled into A by eigen_ldlt (a direct solve): the same springs and releases
// (the PCG's release solves at a looser tolerance, 1e-9, then one more at 1e-12; its friction
// solves at 1e-10, then one more at 1e-12), and the same end positions and velocities to 1e-9
// relative. The contact-free solve that picks
// the springs differs between the two solvers only by the PCG's tolerance.
TEST(BwContactOperator, AStepSolvedMatrixFreeEqualsTheAssembledDirectSolve) {
  Fold pcg(kPcg), ldlt("{type: eigen_ldlt}");
  Scene& a = pcg.scene();
  Scene& b = ldlt.scene();
  BaraffWitkin bw_a, bw_b;
  bw_a.prepare(a, kH);
  bw_b.prepare(b, kH);
  ASSERT_TRUE(bw_a.self_contact_matrix_free());
  ASSERT_FALSE(bw_b.self_contact_matrix_free());
  fold_until_contacts(a, bw_a, 40, bw_a.pattern().nnz_blocks());
  b.state = a.state;
  bw_b.set_restart_state(bw_a.restart_state());  // the collider contacts of the last step
  const long long fa0 = bw_a.friction_solves(), fb0 = bw_b.friction_solves();
  bw_a.step(a, kH);
  bw_b.step(b, kH);
  const auto& sa = bw_a.self_contact()->stats();
  const auto& sb = bw_b.self_contact()->stats();
  EXPECT_GT(sa.contacts, 0);
  EXPECT_EQ(sa.contacts, sb.contacts);
  EXPECT_EQ(sa.released, sb.released);
  // The PCG decides the releases at ImplicitSelfContact::kReleaseToleranceScale times its
  // tolerance and ends with one solve at its own: one solve more than the direct solver. It
  // sizes the friction dampers at kFrictionToleranceScale times its tolerance and ends with a
  // solve at its own: one friction solve more than the direct solver, unless the direct
  // solver took all kFrictionSolves (then the PCG's last is the one at its tolerance).
  EXPECT_EQ(sa.solves, sb.solves + 1);
  const long long fa = bw_a.friction_solves() - fa0, fb = bw_b.friction_solves() - fb0;
  ASSERT_GT(fb, 0);  // the fold holds contacts with friction
  EXPECT_EQ(fa, fb < loom::ImplicitSelfContact::kFrictionSolves ? fb + 1 : fb);
  EXPECT_GE(bw_b.pattern_rebuilds(), 1);  // the assembled path had to extend its pattern
  EXPECT_EQ(bw_a.pattern_rebuilds(), 0);
  double dx = 0, xs = 0, dv = 0, vs = 0;
  for (std::size_t k = 0; k < a.state.x.size(); ++k) {
    dx = std::max(dx, std::abs(a.state.x[k] - b.state.x[k]));
    xs = std::max(xs, std::abs(b.state.x[k]));
    dv = std::max(dv, std::abs(a.state.v[k] - b.state.v[k]));
    vs = std::max(vs, std::abs(b.state.v[k]));
  }
  if (verbose())
    std::printf("springs %d (released %d, solves %d): max |dx| %.3g m, max |dv| %.3g m/s (max |v| %.3g)\n",
                static_cast<int>(sa.contacts), static_cast<int>(sa.released), sa.solves, dx, dv, vs);
  EXPECT_LE(dx, 1e-9 * xs);
  // The friction dampers' corrections are sized from the PCG's solves at kFrictionToleranceScale
  // times 1e-12 (1e-10 relative residual): the velocities agree to about that (10 times it).
  EXPECT_LE(dv, 10 * loom::ImplicitSelfContact::kFrictionToleranceScale * 1e-12 * std::max(vs, 1.0));
}

namespace {
// filtered_pcg with a record of every solve: the tolerance scale it ran at, whether the
// matrix-free springs were applied, and its iterations.
class RecordingSolver final : public loom::ForwardingSolver {
 public:
  struct Solve {
    double scale;
    bool extra;
    int iterations;
  };
  using ForwardingSolver::ForwardingSolver;
  loom::SolveReport solve(const loom::BsrMatrix& A, const loom::Filter& S, std::span<const double> b,
                          std::span<const double> z, std::span<double> dv) override {
    const loom::SolveReport r = ForwardingSolver::solve(A, S, b, z, dv);
    solves.push_back({scale_, extra_ != nullptr, r.iterations});
    return r;
  }
  void set_extra_operator(const loom::ExtraOperator* E) override {
    extra_ = E;
    ForwardingSolver::set_extra_operator(E);
  }
  bool set_tolerance_scale(double t) override {
    scale_ = t;
    return ForwardingSolver::set_tolerance_scale(t);
  }
  std::vector<Solve> solves;

 private:
  double scale_ = 1.0;
  const loom::ExtraOperator* extra_ = nullptr;
};
}  // namespace

// Friction inside the solve with an iterative solver (issue 12): on the folded cloth (collider
// friction 0.8 on the plane, self friction 0.3), the solves with friction dampers that a
// correction may still follow run at ImplicitSelfContact::kFrictionToleranceScale times the
// tolerance, the step's last solve runs at the scene's tolerance with the springs applied,
// and the springs' last solve (whose normal impulses bound the dampers) at the scene's
// tolerance too, the ones before it at kReleaseToleranceScale times it. (The end state equals
// eigen_ldlt's, a direct solve of the assembled terms: AStepSolvedMatrixFreeEquals... above.)
TEST(BwContactOperator, FrictionSolvesSizeTheDampersLooselyAndEndAtTheScenesTolerance) {
  Fold f("{type: filtered_pcg, filtered_pcg: {tolerance: 1.0e-8, max_iterations: 5000}}");
  Scene& sc = f.scene();
  auto rec = std::make_unique<RecordingSolver>(std::move(sc.solver));
  RecordingSolver* r = rec.get();
  sc.solver = std::move(rec);
  BaraffWitkin bw;
  bw.prepare(sc, kH);
  ASSERT_TRUE(bw.self_contact_matrix_free());
  fold_until_contacts(sc, bw, 40, bw.pattern().nnz_blocks());
  if (HasFatalFailure()) return;
  int checked = 0;
  for (int step = 0; step < 5; ++step) {
    r->solves.clear();
    const long long f0 = bw.friction_solves();
    full_step(sc, bw);
    const long long fs = bw.friction_solves() - f0;
    const auto& st = bw.self_contact()->stats();
    ASSERT_FALSE(r->solves.empty());
    const RecordingSolver::Solve& last = r->solves.back();
    EXPECT_EQ(last.scale, 1.0) << "step " << step;  // the step ends at the scene's tolerance
    if (st.contacts == 0 || fs == 0) continue;
    ++checked;
    EXPECT_TRUE(last.extra) << "step " << step;     // with the springs
    // The solves: the contact-free one(s) at scale 1, the springs' (st.solves: all loose but
    // the last), then fs with dampers (all loose but the last).
    const std::size_t ns = r->solves.size(), nf = static_cast<std::size_t>(fs);
    const std::size_t nsp = static_cast<std::size_t>(st.solves);
    ASSERT_GE(ns, nsp + nf);
    ASSERT_GE(nsp, 2u) << "a loose spring solve and the one at the tolerance";
    ASSERT_GE(nf, 2u) << "a loose friction solve and the one at the tolerance";
    EXPECT_LE(fs, loom::ImplicitSelfContact::kFrictionSolves + 1);
    for (std::size_t k = ns - nf; k + 1 < ns; ++k)
      EXPECT_EQ(r->solves[k].scale, loom::ImplicitSelfContact::kFrictionToleranceScale) << "step " << step << " solve " << k;
    EXPECT_EQ(r->solves[ns - nf - 1].scale, 1.0) << "step " << step;  // the springs' last
    for (std::size_t k = ns - nf - nsp; k + 1 < ns - nf; ++k)
      EXPECT_EQ(r->solves[k].scale, loom::ImplicitSelfContact::kReleaseToleranceScale) << "step " << step << " solve " << k;
    if (verbose())
      std::printf("step %d: springs %d, %d spring solves, %lld friction solves, last %d iterations\n", step,
                  static_cast<int>(st.contacts), st.solves, fs, last.iterations);
  }
  EXPECT_GT(checked, 0) << "no step had springs and friction dampers";
}

// The folding cloth for 0.5 s (250 steps) under baraff_witkin with filtered_pcg (the springs
// matrix-free): no intersecting triangle pair at any step (the exact count of loom check), the
// layers at least half the thickness apart, no vertex under the ground plane, and the pattern
// never extended (fold_scene.hpp).
TEST(BwContactOperator, FoldingClothMatrixFreeNeverIntersects) { loom_test::fold_run_never_intersects("{type: filtered_pcg}"); }

// A correction rule that settles on coupled contacts (issue 12): two free vertices of a 2 x 2
// grid (0.1 m, springs k = 400 N/m along its edges and both diagonals, the two vertices at
// x = 0 pinned) rest on a rough plane (mu 0.5, h = 5 ms); S, the far corner, is thrown at
// v0 = 0.06 m/s along the diagonal d away from the pinned corner, H, its neighbour on the
// plane, starts at rest. Analysis: H is held (the pull of the S-H spring, h^2 k |v_S . z|,
// stays below mu m_H g h; asserted below), so S slides against its three springs with the
// pinned vertices and H fixed; along d its stiffness is 2 k (x x^T + z z^T + d d^T has the
// eigenvalue 2 along d) and
//   v_S = (m_S v0 - mu m_S g h) / (m_S + 2 h^2 k)   (along d),  v_H = 0.
// S's first damper is sized with its mass alone, and its response along d is m_S + 2 h^2 k,
// 4 times that: it misses the bound. The correction that reads S's response from its row of
// A, with H as solved (held), meets it at once, so the step takes 2 solves with dampers (a
// direct solver: the first and the corrected one). The rule before (the response from the
// frictionless solve, where H moved too) took all 3 and left S's friction 2 % above the bound.
// The bound is checked by each vertex's momentum balance, independent of the dampers: the
// friction impulse is m dv - h f(x1) in the tangent plane, f the springs' force linear about
// the rest state (k (e.u) e per spring, e its unit direction, u the relative displacement;
// no force at rest), and the normal impulse m g h (the vertices stay on the plane).
TEST(BwContactOperator, CollidersFrictionCorrectionSettlesOnCoupledContacts) {
  const double h = 0.005, k = 400.0, mu = 0.5, v0 = 0.06, g = 9.81, w = 0.1;
  loom::Registry registry;
  loom::PluginLoader loader{registry};
  loom::Simulation::set_notes(false);
  std::ostringstream y;
  y << "mesh: {grid: {nx: 2, ny: 2, width: " << w << ", height: " << w << ", plane: xz}}\n"
    << "material: {type: mass_spring, stencil: structural_shear_bend, stiffness: " << k << ", density: 2.0}\n"
    << "integrator: {type: baraff_witkin, dt: " << h << "}\n"
    << "solver: {type: eigen_ldlt}\n"
    << "threads: 1\n"
    << "gravity: [0, " << -g << ", 0]\n"
    << "pins: [{name: left, box: {min: [-1, -1, -1], max: [0.01, 1, 1]}}]\n"
    << "colliders: [{type: plane, point: [0, -0.002, 0], normal: [0, 1, 0], thickness: 0.002, friction: " << mu
    << "}]\n";
  auto sim = loom::Simulation::from_string(y.str(), "coupled.yaml", LOOM_SOURCE_DIR, {}, loader);
  Scene& sc = sim->scene();
  loom::State& s = sc.state;
  ASSERT_EQ(s.size(), 4);
  Index S = -1, H = -1;
  for (Index i = 0; i < 4; ++i) {
    if (s.pinned[i]) continue;
    if (std::abs(s.x[3 * i + 2] + w) < 1e-12) S = i;  // the grid spans z in [-w, 0]
    if (std::abs(s.x[3 * i + 2]) < 1e-12) H = i;
  }
  ASSERT_GE(S, 0);
  ASSERT_GE(H, 0);
  ASSERT_NEAR(s.x[3 * S], w, 1e-12);
  const double d[3] = {1 / std::sqrt(2.0), 0, -1 / std::sqrt(2.0)};
  for (int c = 0; c < 3; ++c) s.v[3 * S + c] = v0 * d[c];
  const std::vector<double> x0 = s.x, vstart = s.v;
  BaraffWitkin bw;
  bw.prepare(sc, h);
  const long long f0 = bw.friction_solves();
  bw.step(sc, h);
  EXPECT_EQ(bw.friction_solves() - f0, 2) << "solves with dampers";
  const double mS = s.mass[S], mH = s.mass[H];
  const double vS = (mS * v0 - mu * mS * g * h) / (mS + 2 * h * h * k);
  ASSERT_LE(h * h * k * vS / std::sqrt(2.0), mu * mH * g * h) << "H is held (the analysis above)";
  // The friction impulse of each free vertex: m dv - h f(x1), in the plane (y = 0).
  auto friction = [&](Index i, double* p) {
    for (int c = 0; c < 3; ++c) p[c] = s.mass[i] * (s.v[3 * i + c] - vstart[3 * i + c]);
    for (Index j = 0; j < 4; ++j) {
      if (j == i) continue;
      loom_test::subtract_linear_spring_impulse(x0, s.x, i, j, h, k, p);
    }
  };
  double pS[3], pH[3];
  friction(S, pS);
  friction(H, pH);
  const double tolS = loom::kernels::kCoulombTolerance * mu * mS * g * h;
  EXPECT_NEAR(std::hypot(pS[0], pS[2]), mu * mS * g * h, tolS) << "S slides with the kinetic bound";
  EXPECT_LE(std::hypot(pH[0], pH[2]), mu * mH * g * h * (1 + loom::kernels::kCoulombTolerance)) << "H within the static bound";
  for (int c = 0; c < 3; ++c) EXPECT_NEAR(s.v[3 * S + c], vS * d[c], tolS / mS) << c;
  EXPECT_NEAR(std::hypot(s.v[3 * H], s.v[3 * H + 2]), 0.0, 1e-6 * vS) << "H held";
  EXPECT_NEAR(s.v[3 * S + 1], 0.0, 1e-9);
  EXPECT_NEAR(s.v[3 * H + 1], 0.0, 1e-9);
}

// The corrections stop on the aggregate (issue 12): a step's collider contacts are corrected
// only while they miss their Coulomb bounds, in sum, by more than kFrictionStopTolerance of
// the bounds' sum (kernels::FrictionTally). The cloth is two pieces on a rough plane (mu 0.5,
// h = 5 ms, eigen_ldlt, springs k = 400 N/m along the mesh edges): the coupled pair of
// CollidersFrictionCorrectionSettlesOnCoupledContacts (a 0.1 m square, its x = 0 side pinned,
// its far corner S thrown at 0.06 m/s along the diagonal), and a 10 x 10 sheet (0.9 m square)
// sliding as one at 0.5 m/s along x. Analysis: a sheet sliding as one has no spring force and
// each vertex's first damper, sized with its mass, is exact: every sheet vertex loses exactly
// mu g h. S's first damper, sized with its mass against a response about 4 times larger,
// misses its bound (by more than kCoulombTolerance: the per-contact rule before took a second
// solve to correct it), but its miss is at most m_S v0 + mu m_S g h (friction cannot more
// than stop it within the step), far below kFrictionStopTolerance times the sheet's bounds
// (mu g h times its mass, 1.6 kg): the step stops after its first solve with dampers, and the
// friction impulses, read from each vertex's momentum balance (independent of the dampers),
// miss their bounds in sum by at most kFrictionStopTolerance of the bounds' sum.
TEST(BwContactOperator, FrictionCorrectionsStopWhenTheContactsMeetTheirBoundsInSum) {
  namespace fs = std::filesystem;
  const double h = 0.005, k = 400.0, mu = 0.5, v0 = 0.06, u = 0.5, g = 9.81, w = 0.1;
  const int nsheet = 10;
  const fs::path dir = fs::temp_directory_path() / "loom_friction_stop";
  fs::create_directories(dir);
  {
    std::ofstream obj(dir / "two_pieces.obj");
    // Piece 1: vertices 1-4 (pinned 1, 2 at x = 0; H = 3 at (w, 0, 0); S = 4 at (w, 0, -w)).
    obj << "v 0 0 0\nv 0 0 " << -w << "\nv " << w << " 0 0\nv " << w << " 0 " << -w << "\n";
    obj << "f 1 3 4\nf 1 4 2\n";
    // Piece 2: the sheet, x in [0.5, 1.4], z in [-0.9, 0].
    for (int r = 0; r < nsheet; ++r)
      for (int c = 0; c < nsheet; ++c) obj << "v " << 0.5 + w * c << " 0 " << -w * r << "\n";
    auto id = [&](int r, int c) { return 5 + r * nsheet + c; };
    for (int r = 0; r + 1 < nsheet; ++r)
      for (int c = 0; c + 1 < nsheet; ++c)
        obj << "f " << id(r, c) << " " << id(r, c + 1) << " " << id(r + 1, c + 1) << "\nf " << id(r, c) << " "
            << id(r + 1, c + 1) << " " << id(r + 1, c) << "\n";
  }
  loom::Registry registry;
  loom::PluginLoader loader{registry};
  loom::Simulation::set_notes(false);
  std::ostringstream y;
  y << "mesh: {obj: " << (dir / "two_pieces.obj").string() << "}\n"
    << "material: {type: mass_spring, stencil: mesh_edges, stiffness: " << k << ", density: 2.0}\n"
    << "integrator: {type: baraff_witkin, dt: " << h << "}\n"
    << "solver: {type: eigen_ldlt}\n"
    << "threads: 1\n"
    << "gravity: [0, " << -g << ", 0]\n"
    << "pins: [{vertices: [0, 1]}]\n"
    << "colliders: [{type: plane, point: [0, -0.002, 0], normal: [0, 1, 0], thickness: 0.002, friction: " << mu
    << "}]\n";
  auto sim = loom::Simulation::from_string(y.str(), "two_pieces.yaml", LOOM_SOURCE_DIR, {}, loader);
  Scene& sc = sim->scene();
  loom::State& s = sc.state;
  ASSERT_EQ(s.size(), 4 + nsheet * nsheet);
  const Index H = 2, S = 3;
  ASSERT_NEAR(s.x[3 * S], w, 1e-12);
  ASSERT_NEAR(s.x[3 * S + 2], -w, 1e-12);
  const double d[3] = {1 / std::sqrt(2.0), 0, -1 / std::sqrt(2.0)};
  for (int c = 0; c < 3; ++c) s.v[3 * S + c] = v0 * d[c];
  double sheet_mass = 0;
  for (Index i = 4; i < s.size(); ++i) {
    s.v[3 * i] = u;
    sheet_mass += s.mass[i];
  }
  const double tau = loom::kernels::kFrictionStopTolerance;
  ASSERT_LT(s.mass[S] * v0 + mu * s.mass[S] * g * h, tau * mu * sheet_mass * g * h) << "the analysis above";
  const std::vector<double> x0 = s.x, vstart = s.v;
  BaraffWitkin bw;
  bw.prepare(sc, h);
  const long long f0 = bw.friction_solves();
  bw.step(sc, h);
  EXPECT_EQ(bw.friction_solves() - f0, 1) << "solves with dampers";
  // Friction impulses from the momentum balance: m dv - h f(x1) in the plane (the springs
  // linear about the rest state; the sheet's stay at rest length).
  const std::array<std::array<Index, 2>, 5> springs{{{0, 2}, {2, 3}, {3, 1}, {1, 0}, {0, 3}}};
  auto friction = [&](Index i) {
    double p[3];
    for (int c = 0; c < 3; ++c) p[c] = s.mass[i] * (s.v[3 * i + c] - vstart[3 * i + c]);
    for (const auto& e : springs) {
      if (e[0] == i) loom_test::subtract_linear_spring_impulse(x0, s.x, i, e[1], h, k, p);
      if (e[1] == i) loom_test::subtract_linear_spring_impulse(x0, s.x, i, e[0], h, k, p);
    }
    return std::hypot(p[0], p[2]);
  };
  double miss = 0, bounds = 0;
  for (Index i = 4; i < s.size(); ++i) {
    const double b = mu * s.mass[i] * g * h;
    EXPECT_NEAR(s.v[3 * i], u - mu * g * h, 1e-9) << "sheet vertex " << i;
    EXPECT_NEAR(s.v[3 * i + 2], 0.0, 1e-9) << "sheet vertex " << i;
    miss += std::abs(friction(i) - b);
    bounds += b;
  }
  const double bS = mu * s.mass[S] * g * h, bH = mu * s.mass[H] * g * h;
  const double pS = friction(S), pH = friction(H);
  EXPECT_GT(std::abs(pS - bS), loom::kernels::kCoulombTolerance * bS) << "S misses: the per-contact rule corrects";
  miss += std::abs(pS - bS) + std::max(0.0, pH - bH);
  bounds += bS + bH;
  if (verbose())
    std::printf("S: friction %.4g of its bound; H %.4g; aggregate miss %.3g of the bounds\n", pS / bS, pH / bH,
                miss / bounds);
  EXPECT_LE(miss, tau * bounds);
  EXPECT_NEAR(bw.collider_friction().miss / bw.collider_friction().bound, miss / bounds, 1e-4)
      << "the integrator's tally and the momentum balance";
}

// The friction responses the first dampers start from are part of the restart state (issue 12):
// the folding cloth (collider friction 0.8, self friction 0.3, springs matrix-free) stepped on
// from a copy of its state with the integrator's restart state follows the original within
// rounding, and with the state as written before the responses (dv and the contact flags only:
// first dampers from the mass and 1/W again) it does not.
TEST(BwContactOperator, RestartStateCarriesTheFrictionResponses) {
  Fold a(kPcg), b(kPcg), c(kPcg);
  BaraffWitkin bw_a, bw_b, bw_c;
  bw_a.prepare(a.scene(), kH);
  bw_b.prepare(b.scene(), kH);
  bw_c.prepare(c.scene(), kH);
  fold_until_contacts(a.scene(), bw_a, 40, bw_a.pattern().nnz_blocks());
  if (HasFatalFailure()) return;
  ASSERT_GT(bw_a.collider_friction().contacts + bw_a.pair_friction().contacts, 0);
  const std::vector<double> rs = bw_a.restart_state();
  const std::size_t n = static_cast<std::size_t>(a.scene().state.size());
  ASSERT_GT(rs.size(), 3 * n + 2 * n) << "dv, flags, the collider responses and the pairs'";
  b.scene().state = a.scene().state;
  c.scene().state = a.scene().state;
  // The self-collision lists too: they are kept between steps in a frame that follows the
  // cloth's mean motion, so fresh lists would visit the pairs in another order (solves then
  // agree to their tolerance, not to the bit); with a's lists the restart state alone decides.
  ASSERT_TRUE(a.scene().self_collision && b.scene().self_collision && c.scene().self_collision);
  *b.scene().self_collision = *a.scene().self_collision;
  *c.scene().self_collision = *a.scene().self_collision;
  ASSERT_TRUE(bw_b.set_restart_state(rs));
  ASSERT_TRUE(bw_c.set_restart_state(std::vector<double>(rs.begin(), rs.begin() + static_cast<std::ptrdiff_t>(4 * n))));
  for (int step = 0; step < 3; ++step) {
    full_step(a.scene(), bw_a);
    full_step(b.scene(), bw_b);
    full_step(c.scene(), bw_c);
  }
  double db = 0, dc = 0;
  for (std::size_t k = 0; k < 3 * n; ++k) {
    db = std::max(db, std::abs(a.scene().state.x[k] - b.scene().state.x[k]));
    dc = std::max(dc, std::abs(a.scene().state.x[k] - c.scene().state.x[k]));
  }
  if (verbose()) std::printf("restart with the responses: max |dx| %.3g m; without: %.3g m\n", db, dc);
  EXPECT_LE(db, 1e-12);
  EXPECT_GT(dc, 1e3 * std::max(db, 1e-15));
}

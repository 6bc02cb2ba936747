// The self-contact springs of baraff_witkin applied matrix-free by filtered_pcg with the
// multilevel preconditioner sa_amg: the outer PCG applies A + E, the hierarchy is built from
// A's pattern with E's diagonal blocks on level 0 (and through the Galerkin products on the
// coarse levels). On a real contact set of the folding cloth the solve equals a direct solve
// (eigen_ldlt) of the assembled A + E, the V-cycle stays symmetric positive definite and PCG
// decreases the error monotonically in the (A + E)-norm, the pattern never grows, and a fold
// run under sa_amg never intersects.
#include <gtest/gtest.h>

#include <Eigen/Dense>

#include <algorithm>
#include <array>
#include <cmath>
#include <cstdio>
#include <memory>
#include <string>
#include <vector>

#include "baraff_witkin.hpp"
#include "dense_matrix.hpp"
#include "eigen_ldlt.hpp"
#include "eigen_pcg.hpp"
#ifdef LOOM_TEST_CHOLMOD
#include "cholmod_solver.hpp"
#endif
#include "fold_scene.hpp"

namespace {

using loom::BaraffWitkin;
using loom::BaraffWitkinOptions;
using loom::Index;
using loom::Scene;
using loom_test::verbose;

const std::string kAmg =
    "{type: filtered_pcg, filtered_pcg: {tolerance: 1.0e-10, max_iterations: 2000, preconditioner: sa_amg, "
    "sa_amg: {coarse_dofs: 24}}}";

// E with its diagonal blocks hidden from the preconditioner: the hierarchy is A's alone.
struct WithoutDiagonal final : loom::ExtraOperator {
  const loom::ExtraOperator& E;
  explicit WithoutDiagonal(const loom::ExtraOperator& e) : E(e) {}
  void apply_add(const double* x, double* y, double s) const override { E.apply_add(x, y, s); }
  void add_diagonal(double*) const override {}
};

// A linear system of a real folded state: the folding cloth stepped under sa_amg (springs
// matrix-free) until a step holds at least 40 springs; A, S and b of that step's last solve,
// E its springs, and M = A + E assembled on the pattern extended for them (the path of the
// direct solvers). Friction as a velocity correction after the solve (implicit_friction off):
// the last solve is then the one with the springs alone, without the friction dampers that the
// default adds to A in one more solve (with them in A, E's diagonal on level 0 took 54-55 PCG
// iterations against 46 hidden, 2026-11-29; not investigated).
BaraffWitkinOptions springs_only() {
  BaraffWitkinOptions o;
  o.implicit_friction = false;
  return o;
}
struct FoldedSystem {
  loom_test::Fold fold{kAmg};
  BaraffWitkin bw{springs_only()};
  Index n = 0;
  std::unique_ptr<loom::ImplicitSelfContact> E;
  loom::BsrPattern P;
  std::unique_ptr<loom::BsrMatrix> M;
  std::vector<double> b, z;
  Index material_blocks = 0;

  void build() {
    Scene& sc = fold.scene();
    bw.prepare(sc, loom_test::kFoldH);
    ASSERT_TRUE(bw.self_contact_matrix_free());
    material_blocks = bw.pattern().nnz_blocks();
    loom_test::fold_until_contacts(sc, bw, 40, material_blocks);
    n = sc.state.size();
    E = std::make_unique<loom::ImplicitSelfContact>(*bw.self_contact());
    b.assign(bw.rhs().begin(), bw.rhs().end());
    z.assign(3 * static_cast<std::size_t>(n), 0.0);
    loom::ImplicitSelfContact as = *E;
    loom_test::assemble_springs_pattern(*E, sc, as, P);
    if (::testing::Test::HasFatalFailure()) return;
    ASSERT_GT(P.nnz_blocks(), material_blocks);  // the springs couple vertices the material does not
    M = std::make_unique<loom::BsrMatrix>(&P);
    const loom::BsrMatrix& A = bw.system_matrix();
    const loom::BsrPattern& Ap = A.pattern();
    for (Index i = 0; i < n; ++i)
      for (Index k = Ap.row_ptr[i]; k < Ap.row_ptr[i + 1]; ++k) {
        const Index t = P.find(i, Ap.col[k]);
        ASSERT_GE(t, 0);
        std::copy_n(A.block(k), 9, M->block(t));
      }
    std::vector<double> bdummy(3 * static_cast<std::size_t>(n), 0.0);
    as.add_terms(*M, bdummy, sc.state.v, loom_test::kFoldH);
  }
  const loom::Filter& S() const { return bw.filter(); }
  // eigen_ldlt on the assembled A + E (ref) and the dense S (A + E) S (Md).
  void reference(std::vector<double>& ref, Eigen::MatrixXd& Md) {
    loom::EigenLdlt ldlt;
    ldlt.analyze_pattern(*M, S());
    loom::SolveReport f;
    ASSERT_TRUE(ldlt.factorize(*M, S(), f)) << f.message;
    ref.assign(3 * static_cast<std::size_t>(n), 0.0);
    ASSERT_TRUE(ldlt.solve(*M, S(), b, z, ref).converged);
    const Eigen::MatrixXd Sd = projector();
    Md = Sd * loom_test::dense(*M) * Sd;
  }
  std::span<const double> x() { return fold.scene().state.x; }

  // The dense projected matrix S M S + (I - S) and the filter as a dense projector.
  Eigen::MatrixXd projector() const {
    const Index N = 3 * n;
    Eigen::MatrixXd Sd = Eigen::MatrixXd::Identity(N, N);
    for (Index i : S().constrained())
      for (int a = 0; a < 3; ++a)
        for (int c = 0; c < 3; ++c) Sd(3 * i + a, 3 * i + c) = S().projector(i)[3 * a + c];
    return Sd;
  }
};

loom::PcgOptions amg_options(double tol, int maxit, bool coarse) {
  loom::PcgOptions o;
  o.preconditioner = loom::PcgPreconditioner::SaAmg;
  o.tolerance = tol;
  o.max_iterations = maxit;
  o.amg.coarse_dofs = 24;  // several levels on the 196-vertex cloth
  o.amg.extra_on_coarse_levels = coarse;
  return o;
}

// One solve by filtered_pcg + sa_amg of A (+ extra) from dv = 0.
loom::SolveReport pcg_solve(FoldedSystem& fs, const loom::BsrMatrix& A, const loom::ExtraOperator* extra,
                            loom::PcgOptions o, std::vector<double>& dv) {
  o.float_spmv = false;
  loom::EigenPcg p(o);
  p.set_coordinates(fs.x());
  p.set_extra_operator(extra);
  p.analyze_pattern(A, fs.S());
  loom::SolveReport f;
  EXPECT_TRUE(p.factorize(A, fs.S(), f)) << f.message;
  dv.assign(3 * static_cast<std::size_t>(fs.n), 0.0);
  return p.solve(A, fs.S(), fs.b, fs.z, dv);
}

}  // namespace

// The matrix-free solve (A from the integrator, E applied by the springs) equals eigen_ldlt on
// the assembled A + E: its true residual, recomputed with the assembled matrix, meets the
// tolerance, and the two answers agree to the tolerance times the condition bound. Every
// placement of E in the preconditioner (coarse levels or level 0 only, or none) converges to
// the same answer; the iteration counts are printed with LOOM_TEST_VERBOSE.
TEST(BwContactAmg, MatrixFreeSaAmgSolveEqualsLdltOnTheAssembledSum) {
  FoldedSystem fs;
  fs.build();
  if (HasFatalFailure()) return;
  const Index N = 3 * fs.n;
  std::vector<double> ref;
  Eigen::MatrixXd Md;
  fs.reference(ref, Md);
  if (HasFatalFailure()) return;
  const Eigen::MatrixXd Sd = fs.projector();
  const Eigen::Map<const Eigen::VectorXd> bv(fs.b.data(), N), rv(ref.data(), N);
  const Eigen::VectorXd sb = Sd * bv;
  const double ref_norm = std::sqrt(rv.dot(Md * rv));
  const double tol = 1e-10;
  const WithoutDiagonal hidden(*fs.E);
  struct Variant {
    const char* name;
    const loom::ExtraOperator* extra;
    bool coarse;
  };
  int its[3] = {0, 0, 0};
  const Variant variants[3] = {{"E's diagonal on every level", fs.E.get(), true},
                               {"E's diagonal on level 0 only", fs.E.get(), false},
                               {"E not in the preconditioner", &hidden, true}};
  for (int v = 0; v < 3; ++v) {
    std::vector<double> dv;
    const loom::SolveReport rep = pcg_solve(fs, fs.bw.system_matrix(), variants[v].extra,
                                            amg_options(tol, 2000, variants[v].coarse), dv);
    ASSERT_TRUE(rep.converged) << variants[v].name << ": " << rep.message;
    its[v] = rep.iterations;
    const Eigen::Map<const Eigen::VectorXd> d(dv.data(), N);
    const double res = (sb - Md * d).norm() / sb.norm();  // the assembled operator's residual
    EXPECT_LE(res, tol * (1 + 1e-3)) << variants[v].name;
    const Eigen::VectorXd e = d - rv;
    EXPECT_LE(std::sqrt(e.dot(Md * e)), 1e-6 * ref_norm) << variants[v].name;
    if (verbose())
      std::printf("%-30s iterations %3d, residual on assembled A+E %.3g, error %.3g\n", variants[v].name,
                  rep.iterations, res, std::sqrt(e.dot(Md * e)) / ref_norm);
  }
  // E's diagonal blocks must help, not hurt: with them on level 0 PCG takes no more
  // iterations than with E hidden from the hierarchy.
  EXPECT_LE(its[0], its[2]);
  EXPECT_LE(its[1], its[2]);
  // The assembled path for reference: sa_amg built from A + E (its pattern extended).
  std::vector<double> dv;
  const loom::SolveReport rep = pcg_solve(fs, *fs.M, nullptr, amg_options(tol, 2000, true), dv);
  ASSERT_TRUE(rep.converged) << rep.message;
  if (verbose())
    std::printf("%-30s iterations %3d (springs %zu, %d vertices)\n", "assembled A + E", rep.iterations,
                fs.E->contacts().size(), static_cast<int>(fs.n));
  EXPECT_EQ(fs.bw.pattern_rebuilds(), 0);
  EXPECT_EQ(fs.bw.pattern().nnz_blocks(), fs.material_blocks);
}

// The solves of one step share A and S and differ in E (springs added, then released): a
// factorize() whose only change is E refreshes level 0's diagonal alone (no new set-up of the
// hierarchy), and the answer is still eigen_ldlt's on the assembled A + E. A change in A's
// values sets the hierarchy up again.
TEST(BwContactAmg, AFactorizeThatOnlyChangesERefreshesLevel0Alone) {
  FoldedSystem fs;
  fs.build();
  if (HasFatalFailure()) return;
  const Index N = 3 * fs.n;
  const loom::BsrMatrix& A = fs.bw.system_matrix();
  std::vector<double> ref;
  Eigen::MatrixXd Md;
  fs.reference(ref, Md);
  if (HasFatalFailure()) return;
  const Eigen::Map<const Eigen::VectorXd> rv(ref.data(), N);
  loom::SolveReport f;

  loom::PcgOptions o = amg_options(1e-10, 2000, true);
  o.float_spmv = false;
  loom::EigenPcg p(o);
  p.set_coordinates(fs.x());
  const WithoutDiagonal hidden(*fs.E);  // a different E's diagonal (none) at the first set-up
  p.set_extra_operator(&hidden);
  p.analyze_pattern(A, fs.S());
  ASSERT_TRUE(p.factorize(A, fs.S(), f)) << f.message;
  ASSERT_EQ(p.amg()->refreshes(), 1);
  p.set_extra_operator(fs.E.get());
  ASSERT_TRUE(p.factorize(A, fs.S(), f)) << f.message;
  EXPECT_EQ(p.amg()->refreshes(), 1);  // level 0's diagonal only
  std::vector<double> dv(N, 0.0);
  const loom::SolveReport rep = p.solve(A, fs.S(), fs.b, fs.z, dv);
  ASSERT_TRUE(rep.converged) << rep.message;
  const Eigen::VectorXd e = Eigen::Map<const Eigen::VectorXd>(dv.data(), N) - rv;
  EXPECT_LE(std::sqrt(e.dot(Md * e)), 1e-6 * std::sqrt(rv.dot(Md * rv)));
  // The V-cycle with E's diagonal on level 0 and none on the coarse levels is SPD: the
  // iterates above would otherwise have failed (r.s <= 0) or lost monotonicity; check directly.
  std::vector<double> u(N), y(N);
  for (int t = 0; t < 5; ++t) {
    for (Index k = 0; k < N; ++k) u[k] = std::sin(1.0 + 7.0 * k + 3.0 * t);
    p.amg()->apply(u.data(), y.data());
    double d = 0;
    for (Index k = 0; k < N; ++k) d += u[k] * y[k];
    EXPECT_GT(d, 0.0);
  }
  // New values of A: the whole hierarchy again.
  loom::BsrMatrix A2 = A;
  for (Index i = 0; i < fs.n; ++i)
    for (int a = 0; a < 3; ++a) A2.block(A2.pattern().diag[i])[4 * a] *= 1.5;
  ASSERT_TRUE(p.factorize(A2, fs.S(), f)) << f.message;
  EXPECT_EQ(p.amg()->refreshes(), 2);
  if (verbose()) std::printf("after the level-0 refresh: %d iterations\n", rep.iterations);
}

// With E's diagonal blocks in the hierarchy (on every level, or on level 0 only) the V-cycle is
// symmetric positive definite (dense: applied to every unit vector), and PCG with it decreases
// the error monotonically in the norm of the assembled S (A + E) S: ||dv_k - dv*|| never grows.
TEST(BwContactAmg, PreconditionerStaysSpdAndPcgIsMonotoneInTheSumNorm) {
  FoldedSystem fs;
  fs.build();
  if (HasFatalFailure()) return;
  const Index N = 3 * fs.n;
  const Eigen::MatrixXd Sd = fs.projector();
  const Eigen::MatrixXd Md = Sd * loom_test::dense(*fs.M) * Sd + (Eigen::MatrixXd::Identity(N, N) - Sd);
  const Eigen::Map<const Eigen::VectorXd> bv(fs.b.data(), N);
  const Eigen::VectorXd ref = Md.ldlt().solve(Sd * bv);
  for (const bool coarse : {true, false}) {
    // The V-cycle as a dense matrix.
    loom::EigenPcg p(amg_options(1e-10, 10, coarse));
    p.set_coordinates(fs.x());
    p.set_extra_operator(fs.E.get());
    p.analyze_pattern(fs.bw.system_matrix(), fs.S());
    loom::SolveReport f;
    ASSERT_TRUE(p.factorize(fs.bw.system_matrix(), fs.S(), f)) << f.message;
    Eigen::MatrixXd B(N, N);
    std::vector<double> e(N, 0.0), y(N);
    for (Index j = 0; j < N; ++j) {
      e[j] = 1;
      p.amg()->apply(e.data(), y.data());
      B.col(j) = Eigen::Map<const Eigen::VectorXd>(y.data(), N);
      e[j] = 0;
    }
    const double bmax = B.cwiseAbs().maxCoeff();
    EXPECT_LE((B - B.transpose()).cwiseAbs().maxCoeff(), 1e-5 * bmax) << "coarse " << coarse;  // float storage
    const Eigen::SelfAdjointEigenSolver<Eigen::MatrixXd> es(0.5 * (B + B.transpose()));
    EXPECT_GT(es.eigenvalues().minCoeff(), 0.0) << "coarse " << coarse;
    // PCG stopped after k iterations, k = 1, 2, ...: the (A + E)-norm error never grows.
    double prev = INFINITY;
    int steps = 0;
    for (int k = 1; k <= 200; ++k) {
      std::vector<double> dv;
      const loom::SolveReport rep = pcg_solve(fs, fs.bw.system_matrix(), fs.E.get(), amg_options(1e-12, k, coarse), dv);
      const Eigen::VectorXd err = Eigen::Map<const Eigen::VectorXd>(dv.data(), N) - ref;
      const double ea = std::sqrt(std::max(0.0, err.dot(Md * err)));
      EXPECT_LE(ea, prev * (1 + 1e-9) + 1e-14) << "iteration " << k << " coarse " << coarse;
      prev = ea;
      ++steps;
      if (rep.converged) break;
    }
    EXPECT_GT(steps, 2);
    if (verbose())
      std::printf("coarse %d: V-cycle eigenvalues [%.3g, %.3g], PCG monotone over %d iterations\n", coarse,
                  es.eigenvalues().minCoeff(), es.eigenvalues().maxCoeff(), steps);
  }
}

// The alternative for the direct solvers (docs/CONTACT.md): keep the factorization of A for the
// whole step and solve A + E by PCG preconditioned with it. E has rank at most the number of
// springs m (each spring is rank one), so A^-1 (A + E) = I + A^-1 E has at most m eigenvalues
// other than 1 and PCG converges in at most m + 1 iterations (exact arithmetic); the counts
// this takes on the folded cloth are printed with LOOM_TEST_VERBOSE (dense, independent of the
// solvers).
TEST(BwContactAmg, FactorOfAAsPreconditionerOfTheSumConvergesWithinTheRankBound) {
  FoldedSystem fs;
  fs.build();
  if (HasFatalFailure()) return;
  const Index N = 3 * fs.n;
  const Eigen::MatrixXd Sd = fs.projector();
  const Eigen::MatrixXd I = Eigen::MatrixXd::Identity(N, N);
  const Eigen::MatrixXd Ad = Sd * loom_test::dense(fs.bw.system_matrix()) * Sd + (I - Sd);
  const Eigen::MatrixXd Md = Sd * loom_test::dense(*fs.M) * Sd + (I - Sd);
  const Eigen::LLT<Eigen::MatrixXd> fa(Ad);
  ASSERT_EQ(fa.info(), Eigen::Success);
  const Eigen::Map<const Eigen::VectorXd> bv(fs.b.data(), N);
  const Eigen::VectorXd b = Sd * bv;
  const int m = static_cast<int>(fs.E->contacts().size());
  for (const double tol : {1e-5, 1e-8}) {
    Eigen::VectorXd x = Eigen::VectorXd::Zero(N), r = b, s = fa.solve(r), c = s;
    double delta = r.dot(s);
    int it = 0;
    while (r.norm() > tol * b.norm() && it < 10 * m) {
      const Eigen::VectorXd q = Md * c;
      const double alpha = delta / c.dot(q);
      x += alpha * c;
      r -= alpha * q;
      s = fa.solve(r);
      const double dn = r.dot(s);
      c = s + (dn / delta) * c;
      delta = dn;
      ++it;
    }
    EXPECT_LE(it, m + 1) << "tolerance " << tol;
    EXPECT_LE((b - Md * x).norm(), tol * b.norm());
    if (verbose()) std::printf("A's factor as preconditioner: %d iterations to %.0e (%d springs)\n", it, tol, m);
  }
}

// The folding cloth for 0.5 s under sa_amg with the springs matrix-free: no intersecting pair
// by the exact check, layers at least half the thickness apart, the pattern never extended.
TEST(BwContactAmg, FoldingClothUnderSaAmgNeverIntersects) {
  loom_test::fold_run_never_intersects("{type: filtered_pcg, filtered_pcg: {preconditioner: sa_amg}}");
}

// ---------------------------------------------------------------------------------------------
// The direct solvers' mode `contact_springs: factor_preconditioned_pcg` (loom/factor_pcg.hpp):
// the solver factors A~ = S A S + (I - S) alone and solves A + E by the filtered PCG with that
// factor as preconditioner. Checked for eigen_ldlt and (when built) cholmod against eigen_ldlt
// on the assembled A + E, with pins and a direction constraint in the filter and prescribed
// values on them.

namespace {

struct DirectMode {
  const char* name;
  std::unique_ptr<loom::LinearSolver> (*make)(bool factor_pcg, double tol, int maxit);
  int (*factorizations)(const loom::LinearSolver&);
};

std::unique_ptr<loom::LinearSolver> make_ldlt(bool factor_pcg, double tol, int maxit) {
  loom::LdltOptions o;
  if (factor_pcg) o.contact_springs = "factor_preconditioned_pcg";
  o.contact_tolerance = tol;
  o.contact_max_iterations = maxit;
  return std::make_unique<loom::EigenLdlt>(o);
}
int ldlt_count(const loom::LinearSolver& s) { return static_cast<const loom::EigenLdlt&>(s).numeric_factorizations(); }
#ifdef LOOM_TEST_CHOLMOD
std::unique_ptr<loom::LinearSolver> make_cholmod(bool factor_pcg, double tol, int maxit) {
  loom::CholmodOptions o;
  if (factor_pcg) o.contact_springs = "factor_preconditioned_pcg";
  o.contact_tolerance = tol;
  o.contact_max_iterations = maxit;
  return std::make_unique<loom::CholmodSolver>(o);
}
int cholmod_count(const loom::LinearSolver& s) {
  return static_cast<const loom::CholmodSolver&>(s).numeric_factorizations();
}
#endif

std::vector<DirectMode> direct_modes() {
  std::vector<DirectMode> m{{"eigen_ldlt", &make_ldlt, &ldlt_count}};
#ifdef LOOM_TEST_CHOLMOD
  m.push_back({"cholmod", &make_cholmod, &cholmod_count});
#endif
  return m;
}

// The folded system's filter with two pinned vertices and one direction constraint added, and
// prescribed values z = (I - S) w on them.
struct PinnedFilter {
  loom::Filter S;
  std::vector<double> z;
  std::vector<Index> pinned{0, 97};
  Index slid = 150;
  explicit PinnedFilter(const FoldedSystem& fs) : S(fs.S()) {
    for (Index i : pinned) S.constrain_all(i);
    const double d[3] = {0.0, 0.6, 0.8};
    S.constrain_direction(slid, d);
    z.assign(3 * static_cast<std::size_t>(fs.n), 0.0);
    for (std::size_t k = 0; k < z.size(); ++k) z[k] = 0.01 * std::cos(0.7 * static_cast<double>(k));
    S.apply_complement(z);
  }
  Eigen::MatrixXd dense(Index n) const {
    Eigen::MatrixXd Sd = Eigen::MatrixXd::Identity(3 * n, 3 * n);
    for (Index i : S.constrained())
      for (int a = 0; a < 3; ++a)
        for (int c = 0; c < 3; ++c) Sd(3 * i + a, 3 * i + c) = S.projector(i)[3 * a + c];
    return Sd;
  }
};

// m rank-one springs of the self-contact form: E = sum_j k_j u_j u_j^T, u_j = sum_b w_b e_b (x) n.
struct FewSprings final : loom::ExtraOperator {
  struct Spring {
    std::array<Index, 4> v;
    std::array<double, 4> w;
    std::array<double, 3> nrm;
    double k;
  };
  std::vector<Spring> springs;
  void apply_add(const double* x, double* y, double scale) const override {
    for (const Spring& s : springs) {
      double d = 0;
      for (int b = 0; b < 4; ++b)
        for (int a = 0; a < 3; ++a) d += s.w[b] * s.nrm[a] * x[3 * s.v[b] + a];
      for (int b = 0; b < 4; ++b)
        for (int a = 0; a < 3; ++a) y[3 * s.v[b] + a] += scale * s.k * s.w[b] * d * s.nrm[a];
    }
  }
  void add_diagonal(double* D) const override {
    for (const Spring& s : springs)
      for (int b = 0; b < 4; ++b)
        for (int a = 0; a < 3; ++a)
          for (int c = 0; c < 3; ++c) D[9 * s.v[b] + 3 * a + c] += s.k * s.w[b] * s.w[b] * s.nrm[a] * s.nrm[c];
  }
  Eigen::MatrixXd dense(Index n) const {
    Eigen::MatrixXd E = Eigen::MatrixXd::Zero(3 * n, 3 * n);
    for (const Spring& s : springs) {
      Eigen::VectorXd u = Eigen::VectorXd::Zero(3 * n);
      for (int b = 0; b < 4; ++b)
        for (int a = 0; a < 3; ++a) u[3 * s.v[b] + a] += s.w[b] * s.nrm[a];
      E += s.k * u * u.transpose();
    }
    return E;
  }
};

}  // namespace

// On the folded cloth's real contact set (E = its springs) with pins: the mode's answer equals
// eigen_ldlt on the assembled A + E (its residual on the assembled matrix within the
// tolerance, error 1e-8 in the (A + E)-norm), the prescribed values are exact, PCG stays within
// the rank bound m + 1, and a factorize() whose only change is E does not refactor (one whose A
// changed does).
TEST(BwContactDirect, FactorPreconditionedPcgEqualsLdltOnTheAssembledSumWithPins) {
  FoldedSystem fs;
  fs.build();
  if (HasFatalFailure()) return;
  const Index N = 3 * fs.n;
  const PinnedFilter pf(fs);
  const loom::BsrMatrix& A = fs.bw.system_matrix();
  // Reference: eigen_ldlt, assembled.
  loom::EigenLdlt ref_solver;
  ref_solver.analyze_pattern(*fs.M, pf.S);
  loom::SolveReport f;
  ASSERT_TRUE(ref_solver.factorize(*fs.M, pf.S, f)) << f.message;
  std::vector<double> ref(N, 0.0);
  ASSERT_TRUE(ref_solver.solve(*fs.M, pf.S, fs.b, pf.z, ref).converged);
  const Eigen::MatrixXd Sd = pf.dense(fs.n);
  const Eigen::MatrixXd Md = Sd * loom_test::dense(*fs.M) * Sd;
  const Eigen::Map<const Eigen::VectorXd> bv(fs.b.data(), N), zv(pf.z.data(), N), rv(ref.data(), N);
  const Eigen::VectorXd bh = Sd * (bv - loom_test::dense(*fs.M) * zv);
  const double ref_norm = std::sqrt(rv.dot(Md * rv));
  const int m = static_cast<int>(fs.E->contacts().size());
  const double tol = 1e-10;
  for (const DirectMode& mode : direct_modes()) {
    auto solver = mode.make(true, tol, 100);
    ASSERT_TRUE(solver->supports_extra_operator()) << mode.name;
    ASSERT_FALSE(mode.make(false, tol, 100)->supports_extra_operator()) << mode.name;  // assembled by default
    solver->set_extra_operator(fs.E.get());
    solver->analyze_pattern(A, pf.S);
    ASSERT_TRUE(solver->factorize(A, pf.S, f)) << mode.name << ": " << f.message;
    EXPECT_EQ(mode.factorizations(*solver), 1) << mode.name;
    std::vector<double> dv(N, 0.0);
    const loom::SolveReport rep = solver->solve(A, pf.S, fs.b, pf.z, dv);
    ASSERT_TRUE(rep.converged) << mode.name << ": " << rep.message;
    EXPECT_LE(rep.iterations, m + 1) << mode.name;
    const Eigen::Map<const Eigen::VectorXd> d(dv.data(), N);
    const Eigen::VectorXd full = Sd * (bv - loom_test::dense(*fs.M) * d);
    EXPECT_LE(full.norm() / bh.norm(), tol * (1 + 1e-3)) << mode.name;
    const Eigen::VectorXd e = d - rv;
    EXPECT_LE(std::sqrt(e.dot(Md * e)), 1e-8 * ref_norm) << mode.name;
    for (Index i : pf.pinned)
      for (int a = 0; a < 3; ++a) EXPECT_EQ(dv[3 * i + a], pf.z[3 * i + a]) << mode.name << " vertex " << i;
    // Only E changed (the solves of one step): no numeric factorization.
    solver->set_extra_operator(nullptr);
    ASSERT_TRUE(solver->factorize(A, pf.S, f));
    solver->set_extra_operator(fs.E.get());
    ASSERT_TRUE(solver->factorize(A, pf.S, f));
    EXPECT_EQ(mode.factorizations(*solver), 1) << mode.name;
    // New values of A: refactored.
    loom::BsrMatrix A2 = A;
    for (Index i = 0; i < fs.n; ++i) A2.block(A2.pattern().diag[i])[0] *= 1.5;
    ASSERT_TRUE(solver->factorize(A2, pf.S, f));
    EXPECT_EQ(mode.factorizations(*solver), 2) << mode.name;
    if (verbose())
      std::printf("%s factor_preconditioned_pcg: %d iterations for %d springs, residual %.3g, error %.3g\n",
                  mode.name, rep.iterations, m, full.norm() / bh.norm(), std::sqrt(e.dot(Md * e)) / ref_norm);
  }
}

// The rank bound on a small set: 3 rank-one springs, stiff (10 x A's largest diagonal entry),
// one touching a pinned vertex: PCG with A~'s factor converges within m + 1 = 4 iterations to
// 1e-11, to the dense solve of S (A + E) S + (I - S). With a cap of 1 iteration the solve fails
// with a message naming the key (no silent wrong answer).
TEST(BwContactDirect, FewSpringsConvergeWithinTheRankBound) {
  FoldedSystem fs;
  fs.build();
  if (HasFatalFailure()) return;
  const Index N = 3 * fs.n;
  const PinnedFilter pf(fs);
  const loom::BsrMatrix& A = fs.bw.system_matrix();
  double amax = 0;
  for (Index i = 0; i < fs.n; ++i) amax = std::max(amax, A.block(A.pattern().diag[i])[0]);
  FewSprings E;
  const double s = 1.0 / std::sqrt(3.0);
  E.springs.push_back({{10, 11, 24, 160}, {1.0, -0.3, -0.3, -0.4}, {0.0, 0.0, 1.0}, 10 * amax});
  E.springs.push_back({{97, 40, 41, 55}, {1.0, -0.5, -0.25, -0.25}, {s, s, s}, 20 * amax});
  E.springs.push_back({{150, 3, 4, 18}, {1.0, -0.2, -0.4, -0.4}, {0.6, -0.8, 0.0}, 5 * amax});
  const Eigen::MatrixXd Sd = pf.dense(fs.n);
  const Eigen::MatrixXd I = Eigen::MatrixXd::Identity(N, N);
  const Eigen::MatrixXd Ad = loom_test::dense(A) + E.dense(fs.n);
  const Eigen::Map<const Eigen::VectorXd> bv(fs.b.data(), N), zv(pf.z.data(), N);
  const Eigen::VectorXd x = (Sd * Ad * Sd + (I - Sd)).ldlt().solve(Sd * (bv - Ad * zv)) + zv;
  for (const DirectMode& mode : direct_modes()) {
    auto solver = mode.make(true, 1e-11, 100);
    solver->set_extra_operator(&E);
    loom::SolveReport f;
    ASSERT_TRUE(solver->factorize(A, pf.S, f)) << mode.name << ": " << f.message;
    std::vector<double> dv(N, 0.0);
    const loom::SolveReport rep = solver->solve(A, pf.S, fs.b, pf.z, dv);
    ASSERT_TRUE(rep.converged) << mode.name << ": " << rep.message;
    EXPECT_LE(rep.iterations, 4) << mode.name;
    EXPECT_GE(rep.iterations, 1) << mode.name;
    const Eigen::VectorXd e = Eigen::Map<const Eigen::VectorXd>(dv.data(), N) - x;
    EXPECT_LE(e.norm(), 1e-8 * x.norm()) << mode.name;
    if (verbose()) std::printf("%s: %d iterations for 3 springs\n", mode.name, rep.iterations);
    // A cap below what the springs need: a failed solve, and the message says which key.
    auto capped = mode.make(true, 1e-11, 1);
    capped->set_extra_operator(&E);
    ASSERT_TRUE(capped->factorize(A, pf.S, f));
    std::fill(dv.begin(), dv.end(), 0.0);
    const loom::SolveReport bad = capped->solve(A, pf.S, fs.b, pf.z, dv);
    EXPECT_FALSE(bad.converged) << mode.name;
    EXPECT_NE(bad.message.find("contact_springs"), std::string::npos) << bad.message;
  }
}

// The folding cloth for 0.5 s with eigen_ldlt (and cholmod) in the mode: the springs
// matrix-free, the pattern never extended, no intersecting pair.
TEST(BwContactDirect, FoldingClothUnderLdltFactorPcgNeverExtendsThePattern) {
  loom_test::fold_run_never_intersects("{type: eigen_ldlt, eigen_ldlt: {contact_springs: factor_preconditioned_pcg}}");
}
#ifdef LOOM_TEST_CHOLMOD
TEST(BwContactDirect, FoldingClothUnderCholmodFactorPcgNeverExtendsThePattern) {
  loom_test::fold_run_never_intersects("{type: cholmod, cholmod: {contact_springs: factor_preconditioned_pcg}}");
}
#endif

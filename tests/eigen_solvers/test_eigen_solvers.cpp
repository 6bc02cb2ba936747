// eigen_pcg (modified PCG, NUMERICS.md 3.3) and eigen_ldlt (projected direct solve, 3.4)
// on random systems with pins, 1- and 2-DOF direction constraints and nonzero prescribed z,
// against each other and against a dense solve of the projected system built here
// independently; preconditioner effect; indefinite systems; caps and edge cases.
#include <gtest/gtest.h>
#include <omp.h>

#include <Eigen/Dense>
#include <algorithm>
#include <cmath>
#include <random>
#include <vector>

#include "eigen_ldlt.hpp"
#include "eigen_pcg.hpp"
#include "loom/bsr.hpp"
#include "loom/params.hpp"
#include "loom/solver_common.hpp"

namespace {

using loom::BsrMatrix;
using loom::BsrPattern;
using loom::Filter;
using loom::Index;

struct System {
  BsrPattern pattern;
  BsrMatrix A;
  Filter S;
  std::vector<double> b, z;
  std::vector<double> mass;
  Index n = 0;
};

struct SystemSpec {
  Index n = 40;
  unsigned seed = 1;
  double mass_lo = 1e-2, mass_hi = 1e-2;   // log-uniform masses
  double h2k_lo = 0.1, h2k_hi = 10;         // h^2 k per spring (log-uniform)
  double transverse = 0.3;                  // transverse stiffness fraction (negative: compressed, unclamped)
  bool constraints = true;
  bool nonzero_z = true;
  int extra_neighbours = 4;
};

// A = M + sum_springs h^2 k [n n^T + t (I - n n^T)] (Laplacian-like blocks).
void make_system(System& sys, const SystemSpec& sp) {
  std::mt19937 rng(sp.seed);
  std::uniform_real_distribution<double> U(0.0, 1.0);
  std::normal_distribution<double> N01(0.0, 1.0);
  const Index n = sp.n;
  sys.n = n;
  std::vector<std::array<double, 3>> pos(n);
  for (auto& p : pos) p = {U(rng), U(rng), U(rng)};
  std::vector<std::array<Index, 2>> pairs;
  for (Index i = 0; i + 1 < n; ++i) pairs.push_back({i, i + 1});
  for (Index i = 0; i < n; ++i)
    for (int e = 0; e < sp.extra_neighbours / 2; ++e) {
      Index j = static_cast<Index>(U(rng) * n) % n;
      if (j != i) pairs.push_back({i, j});
    }
  sys.pattern = BsrPattern::from_pairs(n, pairs);
  sys.A = BsrMatrix(&sys.pattern);
  sys.mass.resize(n);
  for (Index i = 0; i < n; ++i) {
    const double m = sp.mass_lo * std::pow(sp.mass_hi / sp.mass_lo, U(rng));
    sys.mass[i] = m;
    double* D = sys.A.block(sys.pattern.diag[i]);
    D[0] += m;
    D[4] += m;
    D[8] += m;
  }
  std::sort(pairs.begin(), pairs.end(), [](auto a, auto b) {
    return std::minmax(a[0], a[1]) < std::minmax(b[0], b[1]);
  });
  for (auto [i, j] : pairs) {
    double d[3], l = 0;
    for (int c = 0; c < 3; ++c) {
      d[c] = pos[j][c] - pos[i][c];
      l += d[c] * d[c];
    }
    l = std::sqrt(l);
    const double k = sp.h2k_lo * std::pow(sp.h2k_hi / sp.h2k_lo, U(rng));
    double K[9];
    for (int a = 0; a < 3; ++a)
      for (int c = 0; c < 3; ++c) {
        const double nn = d[a] * d[c] / (l * l);
        K[3 * a + c] = k * (nn + sp.transverse * ((a == c) - nn));
      }
    const Index kii = sys.pattern.find(i, i), kij = sys.pattern.find(i, j), kji = sys.pattern.find(j, i),
                kjj = sys.pattern.find(j, j);
    for (int q = 0; q < 9; ++q) {
      sys.A.block(kii)[q] += K[q];
      sys.A.block(kjj)[q] += K[q];
      sys.A.block(kij)[q] -= K[q];
      sys.A.block(kji)[q] -= K[q];
    }
  }
  sys.S.reset(n);
  sys.z.assign(3 * n, 0.0);
  if (sp.constraints) {
    for (Index i = 0; i < n; ++i) {
      const int kind = i % 7;
      if (kind == 0) sys.S.constrain_all(i);
      if (kind == 1 || kind == 2) {
        double p[3] = {N01(rng), N01(rng), N01(rng)};
        const double l = std::sqrt(p[0] * p[0] + p[1] * p[1] + p[2] * p[2]);
        for (double& c : p) c /= l;
        sys.S.constrain_direction(i, p);
        if (kind == 2) {
          double q[3] = {N01(rng), N01(rng), N01(rng)};
          const double lq = std::sqrt(q[0] * q[0] + q[1] * q[1] + q[2] * q[2]);
          for (double& c : q) c /= lq;
          sys.S.constrain_direction(i, q);
        }
      }
    }
    if (sp.nonzero_z) {
      for (Index i : sys.S.constrained()) {
        double r[3] = {N01(rng), N01(rng), N01(rng)};
        double sr[3] = {r[0], r[1], r[2]};
        loom::solver::filter_vertex(sys.S, i, sr);
        for (int c = 0; c < 3; ++c) sys.z[3 * i + c] = r[c] - sr[c];  // (I - S) r
      }
    }
  }
  sys.b.resize(3 * n);
  for (double& v : sys.b) v = N01(rng);
}

// Dense reference: A~ = S A S + (I - S), b~ = S (b - A z) + z, solved by dense LU.
Eigen::VectorXd dense_projected_solve(const System& sys, double* min_eig = nullptr) {
  const Index N = 3 * sys.n;
  const std::vector<double> d = sys.A.to_dense();
  Eigen::MatrixXd A(N, N);
  for (Index r = 0; r < N; ++r)
    for (Index c = 0; c < N; ++c) A(r, c) = d[static_cast<std::size_t>(r) * N + c];
  Eigen::MatrixXd S = Eigen::MatrixXd::Identity(N, N);
  for (Index i = 0; i < sys.n; ++i) {
    const auto& P = sys.S.projector(i);
    for (int a = 0; a < 3; ++a)
      for (int c = 0; c < 3; ++c) S(3 * i + a, 3 * i + c) = sys.S.free_dofs(i) == 0 ? 0.0 : P[3 * a + c];
  }
  const Eigen::MatrixXd I = Eigen::MatrixXd::Identity(N, N);
  const Eigen::MatrixXd At = S * A * S + (I - S);
  const Eigen::Map<const Eigen::VectorXd> b(sys.b.data(), N), z(sys.z.data(), N);
  const Eigen::VectorXd bt = S * (b - A * z) + z;
  if (min_eig) {
    Eigen::SelfAdjointEigenSolver<Eigen::MatrixXd> es(0.5 * (At + At.transpose()));
    *min_eig = es.eigenvalues().minCoeff();
  }
  return At.partialPivLu().solve(bt);
}

double rel_diff(std::span<const double> a, const Eigen::VectorXd& b) {
  double num = 0, den = 0;
  for (std::size_t k = 0; k < a.size(); ++k) {
    num += (a[k] - b[static_cast<Eigen::Index>(k)]) * (a[k] - b[static_cast<Eigen::Index>(k)]);
    den += b[static_cast<Eigen::Index>(k)] * b[static_cast<Eigen::Index>(k)];
  }
  return std::sqrt(num / den);
}

// (I - S) dv == z bit for bit, and the filtered residual is small.
void expect_constraints_exact(const System& sys, std::span<const double> dv) {
  for (Index i : sys.S.constrained()) {
    if (sys.S.free_dofs(i) != 0) continue;  // partial constraints: exact up to rounding (checked below)
    for (int c = 0; c < 3; ++c) EXPECT_EQ(dv[3 * i + c], sys.z[3 * i + c]) << "vertex " << i;
  }
  for (Index i : sys.S.constrained()) {
    double comp[3] = {dv[3 * i], dv[3 * i + 1], dv[3 * i + 2]};
    loom::solver::filter_vertex(sys.S, i, comp);  // S dv
    for (int c = 0; c < 3; ++c) EXPECT_NEAR(dv[3 * i + c] - comp[c], sys.z[3 * i + c], 1e-13);
  }
}

struct Solved {
  std::vector<double> dv;
  loom::SolveReport rep;
  bool factorized = false;
};

Solved run(loom::LinearSolver& s, const System& sys, std::vector<double> guess = {}) {
  Solved out;
  out.dv = guess.empty() ? std::vector<double>(3 * sys.n, 0.0) : guess;
  s.analyze_pattern(sys.A, sys.S);
  out.factorized = s.factorize(sys.A, sys.S, out.rep);
  if (out.factorized) out.rep = s.solve(sys.A, sys.S, sys.b, sys.z, out.dv);
  return out;
}

loom::PcgOptions pcg(loom::PcgPreconditioner p, double tol = 1e-12, int maxit = 5000) {
  loom::PcgOptions o;
  o.preconditioner = p;
  o.tolerance = tol;
  o.max_iterations = maxit;
  return o;
}

}  // namespace

TEST(EigenSolvers, PcgAndLdltAgreeWithDenseProjectedSolve) {
  for (unsigned seed = 1; seed <= 12; ++seed) {
    System sys;
    SystemSpec sp;
    sp.seed = seed;
    sp.n = seed <= 10 ? 30 + 3 * static_cast<Index>(seed) : 300;  // the last ones: parallel helpers
    sp.mass_lo = 1e-3;
    sp.mass_hi = 1.0;
    sp.nonzero_z = seed % 3 != 0;
    make_system(sys, sp);
    // Dense reference for the small systems; the large ones compare PCG with LDLT.
    loom::EigenLdlt l;
    Solved c = run(l, sys);
    ASSERT_TRUE(c.factorized) << c.rep.message;
    ASSERT_TRUE(c.rep.converged) << c.rep.message;
    const Eigen::VectorXd ref =
        sp.n < 100 ? dense_projected_solve(sys) : Eigen::Map<const Eigen::VectorXd>(c.dv.data(), 3 * sp.n);
    for (auto pc : {loom::PcgPreconditioner::BlockJacobi, loom::PcgPreconditioner::Jacobi}) {
      loom::EigenPcg p(pcg(pc));
      Solved a = run(p, sys);
      ASSERT_TRUE(a.factorized) << a.rep.message;
      ASSERT_TRUE(a.rep.converged) << a.rep.message;
      EXPECT_LE(a.rep.residual, 1e-12);
      EXPECT_GT(a.rep.iterations, 1);
      EXPECT_LT(rel_diff(a.dv, ref), 1e-8) << "seed " << seed;
      expect_constraints_exact(sys, a.dv);
    }
    EXPECT_EQ(c.rep.iterations, 1);
    EXPECT_LT(c.rep.residual, 1e-10);
    EXPECT_LT(rel_diff(c.dv, ref), 1e-8) << "seed " << seed;
    expect_constraints_exact(sys, c.dv);
  }
}

TEST(EigenSolvers, SameAnswerOnOneAndTwoThreads) {
  System sys;
  SystemSpec sp;
  sp.n = 600;
  sp.seed = 99;
  sp.constraints = true;
  make_system(sys, sp);
  const int saved = omp_get_max_threads();
  auto o = pcg(loom::PcgPreconditioner::BlockJacobi, 1e-10);
  o.parallel_min_rows = 0;  // the threaded iteration, on a small system
  omp_set_num_threads(1);
  loom::EigenPcg p1(o);
  Solved a = run(p1, sys);
  omp_set_num_threads(2);
  loom::EigenPcg p2(o);
  Solved b = run(p2, sys);
  omp_set_num_threads(saved);
  ASSERT_TRUE(a.rep.converged && b.rep.converged);
  const Eigen::Map<const Eigen::VectorXd> bv(b.dv.data(), static_cast<Eigen::Index>(b.dv.size()));
  EXPECT_LT(rel_diff(a.dv, bv), 1e-8);
}

// threads: auto's start-up rule reads it (Simulation::build): the PCG's loops run in parallel from
// its parallel_min_rows (kParallelMinRows unless the scene sets it); the direct solve never.
TEST(EigenSolvers, ParallelMinRowsIsThePcgsSettingAndNoneForTheDirectSolver) {
  loom::EigenLdlt direct;
  EXPECT_EQ(direct.parallel_min_rows(), -1);
  loom::EigenPcg p(pcg(loom::PcgPreconditioner::BlockJacobi));
  EXPECT_EQ(p.parallel_min_rows(), loom::kParallelMinRows);
  auto o = pcg(loom::PcgPreconditioner::Jacobi);
  o.parallel_min_rows = 100;
  EXPECT_EQ(loom::EigenPcg(o).parallel_min_rows(), 100);
}

TEST(EigenSolvers, PcgToleranceIsRelativeResidual) {
  System sys;
  SystemSpec sp;
  sp.seed = 5;
  make_system(sys, sp);
  for (double tol : {1e-3, 1e-5, 1e-8}) {
    loom::EigenPcg p(pcg(loom::PcgPreconditioner::BlockJacobi, tol));
    Solved a = run(p, sys);
    ASSERT_TRUE(a.rep.converged);
    EXPECT_LE(a.rep.residual, tol);
    // independent check of the reported residual
    std::vector<double> r(3 * sys.n);
    std::vector<double> zero(3 * sys.n, 0.0);
    const double num = std::sqrt(loom::solver::filtered_residual(sys.A, sys.S, sys.b, a.dv, r));
    const double den = std::sqrt(loom::solver::filtered_residual(sys.A, sys.S, sys.b, sys.z, r));
    EXPECT_NEAR(a.rep.residual, num / den, 1e-12 + 1e-6 * num / den);
  }
}

// set_tolerance_scale (Baraff-Witkin's release solves): a PCG at 1e-10 scaled by 1e4 solves
// as a PCG built at 1e-6 (the same iterations, residual <= 1e-6), and scale 1 restores 1e-10;
// the direct solver does not honour it.
TEST(EigenSolvers, ToleranceScaleLoosensTheNextSolvesAndOneRestoresIt) {
  System sys;
  SystemSpec sp;
  sp.seed = 7;
  make_system(sys, sp);
  loom::EigenPcg scaled(pcg(loom::PcgPreconditioner::BlockJacobi, 1e-10));
  loom::EigenPcg tight(pcg(loom::PcgPreconditioner::BlockJacobi, 1e-10));
  loom::EigenPcg loose(pcg(loom::PcgPreconditioner::BlockJacobi, 1e-6));
  EXPECT_TRUE(scaled.set_tolerance_scale(1e4));
  const Solved a = run(scaled, sys), l = run(loose, sys);
  ASSERT_TRUE(a.rep.converged);
  EXPECT_LE(a.rep.residual, 1e-6);
  EXPECT_GT(a.rep.residual, 1e-10);  // it did stop early
  EXPECT_EQ(a.rep.iterations, l.rep.iterations);
  EXPECT_TRUE(scaled.set_tolerance_scale(1.0));
  const Solved b = run(scaled, sys), t = run(tight, sys);
  EXPECT_LE(b.rep.residual, 1e-10);
  EXPECT_EQ(b.rep.iterations, t.rep.iterations);
  EXPECT_GT(b.rep.iterations, a.rep.iterations);
  loom::EigenLdlt direct;
  EXPECT_FALSE(direct.set_tolerance_scale(1e4));
}

TEST(EigenSolvers, WarmStartFromSolutionNeedsNoIterations) {
  System sys;
  SystemSpec sp;
  sp.seed = 7;
  make_system(sys, sp);
  loom::EigenPcg p(pcg(loom::PcgPreconditioner::BlockJacobi, 1e-8));
  Solved a = run(p, sys);
  ASSERT_TRUE(a.rep.converged);
  Solved again = run(p, sys, a.dv);
  ASSERT_TRUE(again.rep.converged);
  EXPECT_EQ(again.rep.iterations, 0);
  // A nearby guess (a perturbed solution) needs fewer iterations than a cold start.
  std::vector<double> near = a.dv;
  std::mt19937 rng(3);
  std::normal_distribution<double> N01(0.0, 1.0);
  double scale = 0;
  for (double v : a.dv) scale = std::max(scale, std::abs(v));
  for (double& v : near) v += 1e-3 * scale * N01(rng);
  loom::EigenPcg p3(pcg(loom::PcgPreconditioner::BlockJacobi, 1e-8));
  Solved warm = run(p3, sys, near);
  ASSERT_TRUE(warm.rep.converged);
  EXPECT_LT(warm.rep.iterations, a.rep.iterations);
  // A bad guess is discarded (the solve restarts from z), it does not slow the solve down.
  std::vector<double> bad(near.size());
  for (double& v : bad) v = 1e6 * N01(rng);
  Solved badrun = run(p3, sys, bad);
  ASSERT_TRUE(badrun.rep.converged);
  EXPECT_LE(badrun.rep.iterations, a.rep.iterations);
}

TEST(EigenSolvers, BlockJacobiReducesIterationsWithExtremeMassRatios) {
  System sys;
  SystemSpec sp;
  sp.n = 200;
  sp.seed = 11;
  sp.mass_lo = 1e-4;  // six orders of magnitude between particles
  sp.mass_hi = 1e2;
  sp.h2k_lo = 1e-3;
  sp.h2k_hi = 1e1;
  sp.transverse = 0.0;  // stiff along the springs only: strongly anisotropic diagonal blocks
  make_system(sys, sp);
  int its[3];
  const loom::PcgPreconditioner pcs[3] = {loom::PcgPreconditioner::None, loom::PcgPreconditioner::Jacobi,
                                          loom::PcgPreconditioner::BlockJacobi};
  const Eigen::VectorXd ref = dense_projected_solve(sys);
  for (int k = 0; k < 3; ++k) {
    loom::EigenPcg p(pcg(pcs[k], 1e-8, 20000));
    Solved a = run(p, sys);
    ASSERT_TRUE(a.rep.converged) << a.rep.message;
    EXPECT_LT(rel_diff(a.dv, ref), 1e-5);
    its[k] = a.rep.iterations;
  }
  std::printf("iterations: none %d, jacobi %d, block_jacobi %d\n", its[0], its[1], its[2]);
  EXPECT_LT(2 * its[1], its[0]);       // Jacobi at least halves the count of plain CG
  EXPECT_LT(10 * its[2], 8 * its[1]);  // block Jacobi saves at least 20% more
}

TEST(EigenSolvers, IndefiniteSystemIsReportedByBoth) {
  // Compressed springs with the transverse term unclamped (NUMERICS.md 3.5): t = 1 - l0/l < 0.
  for (double h2k_scale : {1.0, 20.0}) {
    System sys;
    SystemSpec sp;
    sp.seed = 21;
    sp.n = 60;
    sp.transverse = 1.0 - 1.0 / 0.7;  // springs 30% compressed
    sp.h2k_lo = 0.02 * h2k_scale;
    sp.h2k_hi = 0.05 * h2k_scale;
    sp.mass_lo = sp.mass_hi = 0.01;
    make_system(sys, sp);
    double min_eig = 0;
    dense_projected_solve(sys, &min_eig);
    ASSERT_LT(min_eig, 0.0) << "test setup: the projected system should be indefinite";
    for (auto pc : {loom::PcgPreconditioner::None, loom::PcgPreconditioner::Jacobi,
                    loom::PcgPreconditioner::BlockJacobi}) {
      loom::EigenPcg p(pcg(pc, 1e-8));
      Solved a = run(p, sys);
      EXPECT_FALSE(a.factorized && a.rep.converged) << "PCG returned an answer for an indefinite system";
      EXPECT_FALSE(a.rep.message.empty());
      EXPECT_NE(a.rep.message.find("positive"), std::string::npos) << a.rep.message;
    }
    loom::EigenLdlt l;
    Solved c = run(l, sys);
    EXPECT_FALSE(c.factorized);
    EXPECT_NE(c.rep.message.find("not positive definite"), std::string::npos) << c.rep.message;
  }
}

TEST(EigenSolvers, IterationCapIsReported) {
  System sys;
  SystemSpec sp;
  sp.seed = 4;
  sp.n = 100;
  sp.h2k_hi = 1e3;
  make_system(sys, sp);
  loom::EigenPcg p(pcg(loom::PcgPreconditioner::Jacobi, 1e-10, 3));
  Solved a = run(p, sys);
  ASSERT_TRUE(a.factorized);
  EXPECT_FALSE(a.rep.converged);
  EXPECT_EQ(a.rep.iterations, 3);
  EXPECT_GT(a.rep.residual, 1e-10);
  EXPECT_NE(a.rep.message.find("not converged in 3 iterations"), std::string::npos) << a.rep.message;
}

TEST(EigenSolvers, ZeroRightHandSideGivesPrescribedValues) {
  System sys;
  SystemSpec sp;
  sp.seed = 8;
  make_system(sys, sp);
  // b = A z makes b-hat = S(b - A z) = 0: the answer is dv = z.
  std::vector<double> az(3 * sys.n);
  loom::solver::multiply(sys.A, sys.z, az);
  sys.b = az;
  loom::EigenPcg p(pcg(loom::PcgPreconditioner::BlockJacobi, 1e-10));
  std::vector<double> guess(3 * sys.n, 1.0);
  Solved a = run(p, sys, guess);
  ASSERT_TRUE(a.rep.converged);
  double maxdiff = 0;
  for (std::size_t k = 0; k < a.dv.size(); ++k) maxdiff = std::max(maxdiff, std::abs(a.dv[k] - sys.z[k]));
  EXPECT_LT(maxdiff, 1e-12);
  loom::EigenLdlt l;
  Solved c = run(l, sys);
  ASSERT_TRUE(c.rep.converged);
  maxdiff = 0;
  for (std::size_t k = 0; k < c.dv.size(); ++k) maxdiff = std::max(maxdiff, std::abs(c.dv[k] - sys.z[k]));
  EXPECT_LT(maxdiff, 1e-12);
}

TEST(EigenSolvers, ProjectedCsrAndCscMatchDense) {
  System sys;
  SystemSpec sp;
  sp.seed = 13;
  sp.n = 20;
  make_system(sys, sp);
  const auto spat = loom::solver::make_scalar_pattern(sys.pattern);
  std::vector<double> csr(spat.inner.size()), csc(spat.inner.size());
  loom::solver::fill_projected_csr(sys.A, sys.S, spat, csr.data());
  loom::solver::fill_projected_csc(sys.A, sys.S, spat, csc.data());
  const Index N = 3 * sys.n;
  Eigen::MatrixXd Dr = Eigen::MatrixXd::Zero(N, N), Dc = Eigen::MatrixXd::Zero(N, N);
  for (Index r = 0; r < N; ++r)
    for (int q = spat.outer[r]; q < spat.outer[r + 1]; ++q) {
      Dr(r, spat.inner[q]) = csr[q];
      Dc(spat.inner[q], r) = csc[q];
    }
  // Same projected matrix as the dense construction.
  const std::vector<double> d = sys.A.to_dense();
  Eigen::MatrixXd A(N, N), S = Eigen::MatrixXd::Identity(N, N);
  for (Index r = 0; r < N; ++r)
    for (Index c = 0; c < N; ++c) A(r, c) = d[static_cast<std::size_t>(r) * N + c];
  for (Index i = 0; i < sys.n; ++i)
    for (int a = 0; a < 3; ++a)
      for (int c = 0; c < 3; ++c)
        S(3 * i + a, 3 * i + c) = sys.S.free_dofs(i) == 0 ? 0.0 : sys.S.projector(i)[3 * a + c];
  const Eigen::MatrixXd At = S * A * S + (Eigen::MatrixXd::Identity(N, N) - S);
  EXPECT_LT((Dr - At).cwiseAbs().maxCoeff(), 1e-12);
  EXPECT_LT((Dc - At).cwiseAbs().maxCoeff(), 1e-12);
}

TEST(EigenSolvers, ParametersAreChecked) {
  using loom::Params;
  auto o = loom::parse_pcg_options(
      Params::from_string("{tolerance: 1.0e-7, max_iterations: 50, preconditioner: jacobi}"));
  EXPECT_EQ(o.tolerance, 1e-7);
  EXPECT_EQ(o.max_iterations, 50);
  EXPECT_EQ(o.preconditioner, loom::PcgPreconditioner::Jacobi);
  EXPECT_THROW(loom::parse_pcg_options(Params::from_string("{preconditioner: ilu}")), loom::InputError);
  EXPECT_THROW(loom::parse_pcg_options(Params::from_string("{tolerance: -1}")), loom::InputError);
  EXPECT_THROW(loom::parse_pcg_options(Params::from_string("{max_iterations: 0}")), loom::InputError);
  EXPECT_EQ(loom::parse_pcg_options(Params()).preconditioner, loom::PcgPreconditioner::BlockJacobi);
  EXPECT_THROW(loom::parse_ldlt_options(Params::from_string("{pivot_tolerance: 2}")), loom::InputError);
}

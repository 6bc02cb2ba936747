// Tests of the `cholmod` solver against a dense reference of the projected system
// (NUMERICS.md 3.4), on random spring networks with pins, direction constraints and
// nonzero z, and on a hanging-cloth matrix.
#include <gtest/gtest.h>
#include <omp.h>
#include <sys/resource.h>

#include <cstdlib>
#include <string>

#include "cholmod_solver.hpp"
#include "loom/params.hpp"
#include "loom/registry.hpp"
#include "solver_systems.hpp"

using namespace loom;
using testsys::System;

namespace {

/// Checks dv against the dense LDLT reference and the two constraint equations.
void expect_solution_ok(const System& s, std::span<const double> dv, double tol) {
  const Eigen::VectorXd ref = testsys::dense_solution(s);
  EXPECT_LT(testsys::rel_diff(dv, ref), tol);
  // (I - S) dv = z exactly (up to rounding), S (A dv - b) = 0.
  std::vector<double> c(dv.begin(), dv.end());
  s.S.apply_complement(c);
  double cerr = 0;
  for (std::size_t i = 0; i < c.size(); ++i) cerr = std::max(cerr, std::abs(c[i] - s.z[i]));
  EXPECT_LT(cerr, 1e-14);
  std::vector<double> r(dv.size());
  s.A.multiply(dv, r);
  for (std::size_t i = 0; i < r.size(); ++i) r[i] -= s.b[i];
  s.S.apply(r);
  double rn = 0, bn = 0;
  for (std::size_t i = 0; i < r.size(); ++i) {
    rn += r[i] * r[i];
    bn += s.b[i] * s.b[i];
  }
  EXPECT_LT(std::sqrt(rn / bn), 1e-9);
}

SolveReport factor_and_solve(LinearSolver& solver, const System& s, std::vector<double>& dv, bool analyze = true) {
  if (analyze) solver.analyze_pattern(s.A, s.S);
  SolveReport f;
  EXPECT_TRUE(solver.factorize(s.A, s.S, f)) << f.message;
  dv.assign(3 * s.n, 0.0);
  return solver.solve(s.A, s.S, s.b, s.z, dv);
}

// `steps` factorize-and-solve steps of one solver on a matrix that drifts as positions do in a
// simulation (x scaled by 1 + rate * step, then reassembled); check(step, report, dv) sees each
// converged solve.
template <class Check>
void drifting_solves(System& s, CholmodSolver& solver, int steps, double rate, Check check) {
  solver.analyze_pattern(s.A, s.S);
  for (int step = 0; step < steps; ++step) {
    for (double& xi : s.x) xi *= 1.0 + rate * step;
    testsys::assemble(s, true);
    SolveReport f;
    ASSERT_TRUE(solver.factorize(s.A, s.S, f)) << f.message;
    std::vector<double> dv(3 * s.n, 0.0);
    const SolveReport rep = solver.solve(s.A, s.S, s.b, s.z, dv);
    ASSERT_TRUE(rep.converged) << rep.message;
    check(step, rep, dv);
  }
}

}  // namespace

TEST(Cholmod, RandomNetworksAgreeWithDenseLdlt) {
  for (std::uint64_t seed = 1; seed <= 12; ++seed) {
    System s = testsys::random_network(60 + 10 * static_cast<Index>(seed), seed);
    ASSERT_GT(testsys::min_eig_on_range(s), 0.0);
    CholmodSolver solver;
    std::vector<double> dv;
    const SolveReport rep = factor_and_solve(solver, s, dv);
    ASSERT_TRUE(rep.converged) << rep.message;
    EXPECT_EQ(rep.iterations, 1);
    EXPECT_LT(rep.residual, 1e-10);
    EXPECT_TRUE(solver.is_supernodal());
    expect_solution_ok(s, dv, 1e-8);
  }
}

TEST(Cholmod, OrderingsAndSimplicialAgree) {
  System s = testsys::random_network(150, 77);
  const Eigen::VectorXd ref = testsys::dense_solution(s);
  for (const char* ord : {"amd", "metis", "nesdis", "natural"})
    for (const char* fac : {"supernodal", "simplicial"}) {
      CholmodOptions o;
      o.ordering = ord;
      o.factorization = fac;
      CholmodSolver solver(o);
      std::vector<double> dv;
      const SolveReport rep = factor_and_solve(solver, s, dv);
      ASSERT_TRUE(rep.converged) << ord << " " << fac << ": " << rep.message;
      EXPECT_EQ(solver.ordering_used(), ord);
      EXPECT_EQ(solver.is_supernodal(), std::string(fac) == "supernodal");
      EXPECT_LT(testsys::rel_diff(dv, ref), 1e-8) << ord << " " << fac;
    }
}

TEST(Cholmod, HangingClothMatrix) {
  System s = testsys::cloth(16, 1e-3, 1e3);
  CholmodSolver solver;
  std::vector<double> dv;
  const SolveReport rep = factor_and_solve(solver, s, dv);
  ASSERT_TRUE(rep.converged) << rep.message;
  expect_solution_ok(s, dv, 1e-8);
  // pinned corners do not move
  for (Index v : s.S.constrained())
    for (int c = 0; c < 3; ++c) EXPECT_EQ(dv[3 * v + c], 0.0);
}

TEST(Cholmod, ZeroRightHandSideGivesZ) {
  System s = testsys::random_network(50, 5);
  // b = A z makes S (b - A z) = 0
  std::vector<double> Az(3 * s.n);
  s.A.multiply(s.z, Az);
  s.b = Az;
  CholmodSolver solver;
  std::vector<double> dv;
  const SolveReport rep = factor_and_solve(solver, s, dv);
  EXPECT_TRUE(rep.converged);
  EXPECT_LT(rep.residual, 1e-14);
  for (Index i = 0; i < 3 * s.n; ++i) EXPECT_NEAR(dv[i], s.z[i], 1e-14);
  // b = 0, z = 0: exactly zero right-hand side, dv = 0, residual reported as 0.
  std::fill(s.b.begin(), s.b.end(), 0.0);
  std::fill(s.z.begin(), s.z.end(), 0.0);
  SolveReport f;
  ASSERT_TRUE(solver.factorize(s.A, s.S, f));
  std::fill(dv.begin(), dv.end(), 1.0);  // a warm start is ignored by the direct solver
  const SolveReport zero = solver.solve(s.A, s.S, s.b, s.z, dv);
  EXPECT_TRUE(zero.converged);
  EXPECT_EQ(zero.residual, 0.0);
  for (double d : dv) EXPECT_EQ(d, 0.0);
}

TEST(Cholmod, IndefiniteMatrixFailsWithPivotMessage) {
  // Strongly compressed springs without the clamp and a large step: A indefinite on
  // range(S) while its diagonal stays positive (so the Cholesky pivot, not the diagonal
  // check, must catch it).
  int checked = 0;
  for (int t = 0; t < 60 && checked < 3; ++t) {
    const double h = 0.005 * (1 + t % 6);
    System s = testsys::random_network(40, 100 + t, h, /*compress*/ 0.6, 3, /*clamp*/ false);
    const Eigen::MatrixXd At = testsys::projected_matrix(s);
    if (testsys::min_eig_on_range(s) > -1e-3 || At.diagonal().minCoeff() <= 0.0) continue;
    ++checked;
    CholmodSolver solver;
    solver.analyze_pattern(s.A, s.S);
    SolveReport f;
    EXPECT_FALSE(solver.factorize(s.A, s.S, f));
    EXPECT_NE(f.message.find("not positive definite"), std::string::npos) << f.message;
    EXPECT_NE(f.message.find("pivot failed"), std::string::npos) << f.message;
    std::vector<double> dv(3 * s.n, 0.0);
    const SolveReport rep = solver.solve(s.A, s.S, s.b, s.z, dv);
    EXPECT_FALSE(rep.converged);
    EXPECT_FALSE(rep.message.empty());
  }
  EXPECT_EQ(checked, 3) << "no indefinite-with-positive-diagonal test system was generated";
}

TEST(Cholmod, NegativeDiagonalAndNanFailClearly) {
  System s = testsys::random_network(40, 3);
  Index v = 0;
  while (s.S.free_dofs(v) != 3) ++v;
  s.A.block(s.pattern->diag[v])[4] = -1.0;  // vertex v, component 1
  CholmodSolver solver;
  solver.analyze_pattern(s.A, s.S);
  SolveReport f;
  EXPECT_FALSE(solver.factorize(s.A, s.S, f));
  EXPECT_NE(f.message.find("not positive definite"), std::string::npos) << f.message;
  EXPECT_NE(f.message.find("vertex " + std::to_string(v) + ", component 1"), std::string::npos) << f.message;

  s.A.block(s.pattern->diag[v])[4] = std::nan("");
  SolveReport g;
  EXPECT_FALSE(solver.factorize(s.A, s.S, g));
  EXPECT_NE(g.message.find("NaN"), std::string::npos) << g.message;
}

TEST(Cholmod, ReusedFactorMeetsToleranceAndRefactorsEveryN) {
  System s = testsys::cloth(12, 1e-3, 1e3);
  CholmodOptions o;
  o.reuse_factorization_steps = 3;
  o.tolerance = 1e-12;
  CholmodSolver solver(o);
  int stale_solves = 0;
  drifting_solves(s, solver, 7, 0.002, [&](int step, const SolveReport& rep, const std::vector<double>& dv) {
    EXPECT_LE(rep.residual, 1e-12);
    if (step % 3 != 0) {
      EXPECT_GT(rep.iterations, 1) << "step " << step;  // refined with the stale factor
      ++stale_solves;
    }
    expect_solution_ok(s, dv, 1e-9);
  });
  EXPECT_EQ(stale_solves, 4);
  EXPECT_EQ(solver.numeric_factorizations(), 3);  // steps 0, 3, 6
}

TEST(Cholmod, StaleFactorThatCannotConvergeIsRefactored) {
  System s = testsys::cloth(10, 1e-3, 1e3);
  CholmodOptions o;
  o.reuse_factorization_steps = 100;
  o.max_iterations = 0;  // no refinement allowed: a stale solve must refactor
  CholmodSolver solver(o);
  std::vector<double> dv;
  factor_and_solve(solver, s, dv);
  for (double& xi : s.x) xi *= 1.05;
  testsys::assemble(s, true);
  SolveReport f;
  ASSERT_TRUE(solver.factorize(s.A, s.S, f));
  EXPECT_EQ(solver.numeric_factorizations(), 1);
  const SolveReport rep = solver.solve(s.A, s.S, s.b, s.z, dv);
  ASSERT_TRUE(rep.converged) << rep.message;
  EXPECT_EQ(solver.numeric_factorizations(), 2);
  expect_solution_ok(s, dv, 1e-8);
}

TEST(Cholmod, ChangedFilterForcesRefactorisation) {
  System s = testsys::random_network(80, 11);
  CholmodOptions o;
  o.reuse_factorization_steps = 10;
  CholmodSolver solver(o);
  std::vector<double> dv;
  factor_and_solve(solver, s, dv);
  // pin one more vertex: same pattern, different S
  Index v = 0;
  while (s.S.free_dofs(v) != 3) ++v;
  s.S.constrain_all(v);
  SolveReport f;
  ASSERT_TRUE(solver.factorize(s.A, s.S, f));
  EXPECT_EQ(solver.numeric_factorizations(), 2);
  dv.assign(3 * s.n, 0.0);
  const SolveReport rep = solver.solve(s.A, s.S, s.b, s.z, dv);
  ASSERT_TRUE(rep.converged);
  EXPECT_EQ(rep.iterations, 1);
  expect_solution_ok(s, dv, 1e-8);
}

TEST(Cholmod, BlasIsOpenBlasWithBoundedThreads) {
  const std::string lib = cholmod_blas_library();
  EXPECT_NE(lib.find("openblas"), std::string::npos) << "dgemm_ resolves to " << lib;
  EXPECT_NE(cholmod_openblas_config().find("OpenBLAS"), std::string::npos);
  CholmodOptions o;
  o.blas_threads = 1;
  CholmodSolver one(o);
  EXPECT_EQ(cholmod_blas_threads(), 1);
  o.blas_threads = 2;
  CholmodSolver two(o);
  EXPECT_EQ(cholmod_blas_threads(), 2);
}

TEST(Cholmod, ParametersAreChecked) {
  auto opts = CholmodOptions::from_params(Params::from_string(
      "tolerance: 1.0e-9\nreuse_factorization_steps: 4\nordering: amd\nmax_iterations: 7\nblas_threads: 1\n"));
  EXPECT_EQ(opts.tolerance, 1e-9);
  EXPECT_EQ(opts.reuse_factorization_steps, 4);
  EXPECT_EQ(opts.ordering, "amd");
  EXPECT_EQ(opts.max_iterations, 7);
  EXPECT_THROW(CholmodOptions::from_params(Params::from_string("reuse_factorization_steps: 0\n")), InputError);
  EXPECT_THROW(CholmodOptions::from_params(Params::from_string("ordering: colamd\n")), InputError);
  EXPECT_THROW(CholmodOptions::from_params(Params::from_string("tolerance: -1\n")), InputError);
}

TEST(Cholmod, ModuleLoadsAndRejectsUnknownKeys) {
  Registry registry;
  PluginLoader loader(registry, {std::string(LOOM_BINARY_DIR) + "/lib/loom/plugins"});
  loader.ensure(PluginKind::Solver, "cholmod");
  ASSERT_TRUE(registry.has(PluginKind::Solver, "cholmod"));
  auto solver = registry.make_solver("cholmod", "cpu", Params::from_string("tolerance: 1.0e-9\n"));
  ASSERT_TRUE(solver);
  EXPECT_EQ(solver->name(), "cholmod");
  try {
    registry.make_solver("cholmod", "cpu", Params::from_string("tolerence: 1.0e-9\n"));
    FAIL() << "unknown key accepted";
  } catch (const InputError& e) {
    EXPECT_NE(std::string(e.what()).find("tolerance"), std::string::npos) << e.what();
  }
  System s = testsys::random_network(50, 9);
  std::vector<double> dv;
  const SolveReport rep = factor_and_solve(*solver, s, dv);
  EXPECT_TRUE(rep.converged);
  expect_solution_ok(s, dv, 1e-8);
}

// The stale factor as a preconditioner with contacts: the cloth with pins and 1- and
// 2-direction constraints (contacts) held fixed while the matrix drifts step to step. The
// stale solves are PCG iterations (reported, more than one) and still reach the dense
// projected solution, including a nonzero z on the constrained directions.
TEST(Cholmod, StaleFactorPreconditionsPcgWithPinsAndContacts) {
  System s = testsys::cloth(12, 1e-3, 1e3, 3);
  std::mt19937_64 rng(9);
  testsys::random_constraints(s, rng, 0.03, 0.1, 0.05, true);
  CholmodOptions o;
  o.reuse_factorization_steps = 4;
  o.tolerance = 1e-11;
  CholmodSolver solver(o);
  int stale = 0;
  drifting_solves(s, solver, 4, 0.003, [&](int step, const SolveReport& rep, const std::vector<double>& dv) {
    EXPECT_LE(rep.residual, 1e-11);
    if (step > 0) {
      EXPECT_GT(rep.iterations, 1) << "step " << step;
      ++stale;
    }
    // Against the dense projected solve; the residual recomputed here relative to
    // |S(b - A z)| (the stopping rule's scale: with a nonzero z it is far above |b|).
    EXPECT_LT(testsys::rel_diff(dv, testsys::dense_solution(s)), 1e-8) << "step " << step;
    std::vector<double> r(dv.size()), r0(dv.size());
    s.A.multiply(dv, r);
    s.A.multiply(s.z, r0);
    double rn = 0, r0n = 0, cerr = 0;
    for (std::size_t i = 0; i < r.size(); ++i) {
      r[i] = s.b[i] - r[i];
      r0[i] = s.b[i] - r0[i];
    }
    s.S.apply(r);
    s.S.apply(r0);
    for (std::size_t i = 0; i < r.size(); ++i) {
      rn += r[i] * r[i];
      r0n += r0[i] * r0[i];
    }
    EXPECT_LE(std::sqrt(rn / r0n), 1.01e-11) << "step " << step;
    std::vector<double> c(dv.begin(), dv.end());
    s.S.apply_complement(c);
    for (std::size_t i = 0; i < c.size(); ++i) cerr = std::max(cerr, std::abs(c[i] - s.z[i]));
    EXPECT_LT(cerr, 1e-14);
  });
  EXPECT_EQ(stale, 3);
  EXPECT_EQ(solver.numeric_factorizations(), 1);
}

// CHOLMOD's supernodal factorisation asks OpenMP for teams of CHOLMOD_OMP_NUM_THREADS (4)
// whatever the run's count; the solver caps them while it calls CHOLMOD. On 1 thread no team
// forms, so the factorisation and solve never block: voluntary context switches (getrusage:
// every thread of the process) stay near zero. Uncapped, these 3 factorisations and solves of
// a 48 x 48 cloth (the ground_plane scene's size) made 12,694 on the development VM (a team
// woken and put to sleep per large supernode); capped, 0-2.
TEST(Cholmod, OneThreadRunsCholmodOnOneThread) {
  const int saved = omp_get_max_threads();
  omp_set_num_threads(1);
  System s = testsys::cloth(48);
  CholmodOptions o;
  o.blas_threads = 1;
  CholmodSolver solver(o);
  solver.analyze_pattern(s.A, s.S);
  std::vector<double> dv;
  rusage before{}, after{};
  getrusage(RUSAGE_SELF, &before);
  for (int k = 0; k < 3; ++k) {
    SolveReport f;
    ASSERT_TRUE(solver.factorize(s.A, s.S, f)) << f.message;
    dv.assign(3 * s.n, 0.0);
    ASSERT_TRUE(solver.solve(s.A, s.S, s.b, s.z, dv).converged);
  }
  getrusage(RUSAGE_SELF, &after);
  omp_set_num_threads(saved);
  EXPECT_LT(after.ru_nvcsw - before.ru_nvcsw, 30) << "voluntary context switches in 3 factorisations";
  RecordProperty("voluntary_switches", static_cast<int>(after.ru_nvcsw - before.ru_nvcsw));
  // The caller's OpenMP settings are restored.
  EXPECT_GT(omp_get_max_active_levels(), 0);
  EXPECT_EQ(omp_get_dynamic(), 0);
}

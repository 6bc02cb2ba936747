// Serial tests of the `petsc` solver against a dense reference of the projected system
// (NUMERICS.md 3.4). The distributed (mpirun -n 2) check is petsc_mpi_check.cpp.
#include <gtest/gtest.h>

#include <string>

#include "loom/params.hpp"
#include "loom/registry.hpp"
#include "petsc_solver.hpp"
#include "solver_systems.hpp"

using namespace loom;
using testsys::System;

namespace {

PetscSolverOptions opts(const std::string& pc, double tol = 1e-12, const std::string& options = "") {
  PetscSolverOptions o;
  o.pc = pc;
  o.tolerance = tol;
  o.options = options;
  return o;
}

SolveReport factor_and_solve(LinearSolver& solver, const System& s, std::vector<double>& dv) {
  solver.analyze_pattern(s.A, s.S);
  SolveReport f;
  EXPECT_TRUE(solver.factorize(s.A, s.S, f)) << f.message;
  dv.assign(3 * s.n, 0.0);
  return solver.solve(s.A, s.S, s.b, s.z, dv);
}

void expect_constraints_exact(const System& s, const std::vector<double>& dv) {
  std::vector<double> c(dv);
  s.S.apply_complement(c);
  for (std::size_t i = 0; i < c.size(); ++i) EXPECT_NEAR(c[i], s.z[i], 1e-14);
}

}  // namespace

TEST(Petsc, RandomNetworksAgreeWithDenseLdlt) {
  for (const char* pc : {"jacobi", "bjacobi", "gamg"}) {
    for (std::uint64_t seed = 1; seed <= 4; ++seed) {
      System s = testsys::random_network(80 + 20 * static_cast<Index>(seed), seed);
      PetscSolver solver(opts(pc));
      EXPECT_EQ(solver.ranks(), 1);
      std::vector<double> dv;
      const SolveReport rep = factor_and_solve(solver, s, dv);
      ASSERT_TRUE(rep.converged) << pc << ": " << rep.message;
      EXPECT_LE(rep.residual, 1e-12 * 1.01) << pc;
      EXPECT_GT(rep.iterations, 0);
      EXPECT_LT(testsys::rel_diff(dv, testsys::dense_solution(s)), 1e-8) << pc << " seed " << seed;
      expect_constraints_exact(s, dv);
    }
  }
}

TEST(Petsc, HangingClothAgreesWithDenseLdlt) {
  System s = testsys::cloth(14, 1e-3, 1e3);
  const Eigen::VectorXd ref = testsys::dense_solution(s);
  for (const char* pc : {"jacobi", "bjacobi", "gamg"}) {
    PetscSolver solver(opts(pc));
    std::vector<double> dv;
    const SolveReport rep = factor_and_solve(solver, s, dv);
    ASSERT_TRUE(rep.converged) << pc << ": " << rep.message;
    EXPECT_EQ(solver.pc_type(), pc);
    EXPECT_EQ(solver.ksp_type(), "cg");
    EXPECT_LT(testsys::rel_diff(dv, ref), 1e-8) << pc;
    for (Index v : s.S.constrained())
      for (int c = 0; c < 3; ++c) EXPECT_EQ(dv[3 * v + c], 0.0);
  }
}

// The AMG preconditioners selectable by name, with block size 3 and the rigid-body
// near-null space built from the vertex positions: gamg and hypre BoomerAMG (nodal
// coarsening; the rigid modes are attached but BoomerAMG uses them only with vector
// interpolation, an `options` choice) solve the hanging cloth with pins and
// contact constraints to the dense answer; the near-null space is attached exactly when
// positions are given (auto), and near_null_space: rigid without positions is an error.
TEST(Petsc, GamgAndBoomerAmgWithRigidBodyNearNullSpace) {
  System s = testsys::cloth(16, 1e-3, 1e3, 5);
  std::mt19937_64 rng(3);
  testsys::random_constraints(s, rng, 0.02, 0.1, 0.05, true);
  const Eigen::VectorXd ref = testsys::dense_solution(s);
  for (const char* pc : {"gamg", "boomeramg"}) {
    for (bool coords : {true, false}) {
      PetscSolver solver(opts(pc, 1e-10));
      if (coords) solver.set_coordinates(s.x);
      std::vector<double> dv;
      const SolveReport rep = factor_and_solve(solver, s, dv);
      ASSERT_TRUE(rep.converged) << pc << ": " << rep.message;
      EXPECT_EQ(solver.has_near_null_space(), coords) << pc;
      EXPECT_EQ(solver.pc_type(), std::string(pc) == "gamg" ? "gamg" : "hypre");
      EXPECT_EQ(solver.matrix_type(), "seqaij");
      EXPECT_LT(testsys::rel_diff(dv, ref), 1e-7) << pc;
      expect_constraints_exact(s, dv);
      std::printf("petsc %s, near-null space %s: %d iterations\n", pc, coords ? "rigid" : "none", rep.iterations);
    }
  }
  PetscSolverOptions o = opts("gamg", 1e-10);
  o.near_null_space = "rigid";
  PetscSolver solver(o);
  solver.analyze_pattern(s.A, s.S);
  SolveReport f;
  EXPECT_FALSE(solver.factorize(s.A, s.S, f));
  EXPECT_NE(f.message.find("near_null_space"), std::string::npos) << f.message;
}

TEST(Petsc, ToleranceIsTheTrueRelativeResidual) {
  System s = testsys::cloth(12, 1e-3, 1e3);
  for (double tol : {1e-4, 1e-7, 1e-10}) {
    PetscSolver solver(opts("jacobi", tol));
    std::vector<double> dv;
    const SolveReport rep = factor_and_solve(solver, s, dv);
    ASSERT_TRUE(rep.converged);
    // recompute |S (b - A dv)| / |S (b - A z)| independently
    std::vector<double> r(3 * s.n), r0(3 * s.n);
    s.A.multiply(dv, r);
    s.A.multiply(s.z, r0);
    double rn = 0, r0n = 0;
    for (Index i = 0; i < 3 * s.n; ++i) {
      r[i] = s.b[i] - r[i];
      r0[i] = s.b[i] - r0[i];
    }
    s.S.apply(r);
    s.S.apply(r0);
    for (Index i = 0; i < 3 * s.n; ++i) {
      rn += r[i] * r[i];
      r0n += r0[i] * r0[i];
    }
    const double rel = std::sqrt(rn / r0n);
    EXPECT_LE(rel, tol * 1.01);
    EXPECT_GT(rel, tol * 1e-4);  // CG stops soon after reaching the tolerance
    EXPECT_NEAR(rep.residual, rel, 1e-3 * rel + 1e-15);
  }
}

TEST(Petsc, WarmStartFromTheSolutionNeedsNoIterations) {
  System s = testsys::cloth(10, 1e-3, 1e3);
  PetscSolver solver(opts("bjacobi", 1e-10));
  std::vector<double> dv;
  const SolveReport first = factor_and_solve(solver, s, dv);
  ASSERT_TRUE(first.converged);
  EXPECT_GT(first.iterations, 3);
  const SolveReport again = solver.solve(s.A, s.S, s.b, s.z, dv);  // dv holds the answer
  ASSERT_TRUE(again.converged);
  EXPECT_LE(again.iterations, 1);
}

TEST(Petsc, IndefiniteMatrixReportsKspReason) {
  // Unclamped compressed springs: find a system that is indefinite on range(S) with a
  // positive diagonal, and use its most negative eigenvector as b: CG (no PC) meets the
  // negative curvature in its first iteration.
  for (int t = 0; t < 60; ++t) {
    System s = testsys::random_network(40, 100 + t, 0.005 * (1 + t % 6), 0.6, 3, false);
    const Eigen::MatrixXd At = testsys::projected_matrix(s);
    if (At.diagonal().minCoeff() <= 0.0) continue;
    const Eigen::MatrixXd A = testsys::dense(s.A), S = testsys::dense_filter(s.S);
    const Eigen::Index N = A.rows();
    Eigen::SelfAdjointEigenSolver<Eigen::MatrixXd> es(
        S * A * S + 1e12 * (Eigen::MatrixXd::Identity(N, N) - S));
    if (es.eigenvalues()(0) > -1e-3) continue;
    const Eigen::VectorXd v = es.eigenvectors().col(0);
    for (Eigen::Index i = 0; i < N; ++i) s.b[i] = v[i];
    std::fill(s.z.begin(), s.z.end(), 0.0);
    PetscSolver solver(opts("none", 1e-10));
    std::vector<double> dv;
    solver.analyze_pattern(s.A, s.S);
    SolveReport f;
    ASSERT_TRUE(solver.factorize(s.A, s.S, f)) << f.message;
    dv.assign(3 * s.n, 0.0);
    const SolveReport rep = solver.solve(s.A, s.S, s.b, s.z, dv);
    EXPECT_FALSE(rep.converged);
    EXPECT_NE(rep.message.find("DIVERGED_INDEFINITE"), std::string::npos) << rep.message;
    EXPECT_NE(rep.message.find("not positive definite"), std::string::npos) << rep.message;
    return;
  }
  FAIL() << "no indefinite test system was generated";
}

TEST(Petsc, NegativeDiagonalIsRejectedInFactorize) {
  System s = testsys::random_network(40, 3);
  Index v = 0;
  while (s.S.free_dofs(v) != 3) ++v;
  s.A.block(s.pattern->diag[v])[8] = -2.0;
  PetscSolver solver(opts("bjacobi"));
  solver.analyze_pattern(s.A, s.S);
  SolveReport f;
  EXPECT_FALSE(solver.factorize(s.A, s.S, f));
  EXPECT_NE(f.message.find("vertex " + std::to_string(v) + ", component 2"), std::string::npos) << f.message;
  std::vector<double> dv(3 * s.n, 0.0);
  EXPECT_FALSE(solver.solve(s.A, s.S, s.b, s.z, dv).converged);
}

TEST(Petsc, IterationLimitReportsDivergedIts) {
  System s = testsys::cloth(12, 1e-3, 1e3);
  PetscSolverOptions o = opts("jacobi", 1e-12);
  o.max_iterations = 3;
  PetscSolver solver(o);
  std::vector<double> dv;
  const SolveReport rep = factor_and_solve(solver, s, dv);
  EXPECT_FALSE(rep.converged);
  EXPECT_EQ(rep.iterations, 3);
  EXPECT_NE(rep.message.find("DIVERGED_ITS"), std::string::npos) << rep.message;
  EXPECT_NE(rep.message.find("max_iterations"), std::string::npos) << rep.message;
}

TEST(Petsc, OptionsStringOverridesDefaultsPerInstance) {
  System s = testsys::cloth(10, 1e-3, 1e3);
  const Eigen::VectorXd ref = testsys::dense_solution(s);
  PetscSolver a(opts("jacobi", 1e-12, "-ksp_type cg -pc_type gamg"));
  PetscSolver b(opts("jacobi", 1e-12, "-pc_type bjacobi -sub_pc_type icc"));
  PetscSolver c(opts("jacobi", 1e-12));
  std::vector<double> dv;
  for (PetscSolver* solver : {&a, &b, &c}) {
    const SolveReport rep = factor_and_solve(*solver, s, dv);
    ASSERT_TRUE(rep.converged) << rep.message;
    EXPECT_LT(testsys::rel_diff(dv, ref), 1e-8);
  }
  EXPECT_EQ(a.pc_type(), "gamg");
  EXPECT_EQ(b.pc_type(), "bjacobi");
  EXPECT_EQ(c.pc_type(), "jacobi");
}

TEST(Petsc, ReusedPreconditionerIsRebuiltEveryN) {
  System s = testsys::cloth(10, 1e-3, 1e3);
  PetscSolverOptions o = opts("gamg", 1e-10);
  o.reuse_preconditioner_steps = 3;
  PetscSolver solver(o);
  solver.analyze_pattern(s.A, s.S);
  for (int step = 0; step < 7; ++step) {
    for (double& xi : s.x) xi *= 1.0 + 0.002 * step;
    testsys::assemble(s, true);
    SolveReport f;
    ASSERT_TRUE(solver.factorize(s.A, s.S, f));
    std::vector<double> dv(3 * s.n, 0.0);
    const SolveReport rep = solver.solve(s.A, s.S, s.b, s.z, dv);
    ASSERT_TRUE(rep.converged) << rep.message;
    EXPECT_LT(testsys::rel_diff(dv, testsys::dense_solution(s)), 1e-7);
  }
  EXPECT_EQ(solver.preconditioner_setups(), 3);  // steps 0, 3, 6
}

TEST(Petsc, ParametersAreChecked) {
  auto o = PetscSolverOptions::from_params(Params::from_string(
      "pc: gamg\nksp: cg\ntolerance: 1.0e-9\nmax_iterations: 50\noptions: \"-pc_gamg_threshold 0.05\"\n"));
  EXPECT_EQ(o.pc, "gamg");
  EXPECT_EQ(o.tolerance, 1e-9);
  EXPECT_EQ(o.max_iterations, 50);
  EXPECT_EQ(o.options, "-pc_gamg_threshold 0.05");
  EXPECT_THROW(PetscSolverOptions::from_params(Params::from_string("pc: amg\n")), InputError);
  EXPECT_THROW(PetscSolverOptions::from_params(Params::from_string("max_iterations: 0\n")), InputError);
}

TEST(Petsc, LauncherRankFromEnvironment) {
  unsetenv("OMPI_COMM_WORLD_RANK");
  unsetenv("PMI_RANK");
  unsetenv("PMIX_RANK");
  unsetenv("MV2_COMM_WORLD_RANK");
  EXPECT_EQ(launcher_rank(), 0);
  setenv("PMI_RANK", "3", 1);
  EXPECT_EQ(launcher_rank(), 3);
  setenv("OMPI_COMM_WORLD_RANK", "1", 1);
  EXPECT_EQ(launcher_rank(), 1);
  unsetenv("OMPI_COMM_WORLD_RANK");
  unsetenv("PMI_RANK");
}

// Loads the real module (RTLD_LOCAL, as the CLI does): PETSc and Open MPI must start from it.
TEST(Petsc, ModuleLoadsAndSolves) {
  Registry registry;
  PluginLoader loader(registry, {std::string(LOOM_BINARY_DIR) + "/lib/loom/plugins"});
  loader.ensure(PluginKind::Solver, "petsc");
  auto solver = registry.make_solver("petsc", "cpu",
                                     Params::from_string("pc: gamg\ntolerance: 1.0e-12\noptions: \"-ksp_norm_type unpreconditioned\"\n"));
  ASSERT_TRUE(solver);
  EXPECT_EQ(solver->name(), "petsc");
  EXPECT_THROW(registry.make_solver("petsc", "cpu", Params::from_string("preconditioner: gamg\n")), InputError);
  System s = testsys::random_network(60, 21);
  std::vector<double> dv;
  const SolveReport rep = factor_and_solve(*solver, s, dv);
  ASSERT_TRUE(rep.converged) << rep.message;
  EXPECT_LT(testsys::rel_diff(dv, testsys::dense_solution(s)), 1e-8);
}

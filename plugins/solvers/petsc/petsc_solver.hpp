// `petsc` linear solver: PETSc KSP (CG by default) on a block (bs = 3) BAIJ matrix of the
// projected system A~ = S A S + (I - S) (NUMERICS.md 3.4), serially or under mpirun -n N:
// each rank owns a contiguous range of block rows, assembles only those rows, KSP solves the
// distributed system and the solution is gathered to every rank.
#pragma once

#include <mpi.h>

#include <memory>
#include <string>

#include "loom/launcher.hpp"  // launcher_rank(): the one MPI-rank rule
#include "loom/linear_solver.hpp"
#include "loom/param_spec.hpp"
#include "loom/params.hpp"

namespace loom {

struct PetscSolverOptions {
  std::string ksp = "cg";          ///< KSP type (cg, cr, minres, gmres, ...)
  std::string pc = "bjacobi";      ///< jacobi | bjacobi | gamg | hypre | boomeramg | none | ... (any PC type name)
  double tolerance = 1e-8;         ///< relative residual |S(b - A dv)| / |S(b - A z)|
  int max_iterations = 10000;
  int reuse_preconditioner_steps = 1;  ///< rebuild the PC every N factorize() calls
  std::string options;             ///< PETSc options, e.g. "-ksp_type cg -pc_type gamg"
  std::string matrix = "auto";     ///< auto (BAIJ, AIJ for gamg/hypre) | baij | aij
  /// auto: the rigid-body modes of the vertex positions (MatNullSpaceCreateRigidBody, 6 per
  /// vertex) as the near-null space for gamg / hypre / boomeramg when the integrator passes
  /// positions (set_coordinates); rigid: always (an error without positions); none: never.
  std::string near_null_space = "auto";
  /// The keys of petsc, read by from_params.
  static const ParamSpec& spec();
  static PetscSolverOptions from_params(const Params& p);
};

class PetscSolver final : public LinearSolver {
 public:
  /// comm: the communicator the solve is distributed over (MPI_COMM_WORLD by default;
  /// MPI_COMM_SELF for a serial solve on each rank).
  explicit PetscSolver(const PetscSolverOptions& options = {}, MPI_Comm comm = MPI_COMM_WORLD);
  explicit PetscSolver(const Params& p) : PetscSolver(PetscSolverOptions::from_params(p)) {}
  ~PetscSolver() override;
  PetscSolver(const PetscSolver&) = delete;
  PetscSolver& operator=(const PetscSolver&) = delete;

  std::string name() const override { return "petsc"; }
  void analyze_pattern(const BsrMatrix& A, const Filter& S) override;
  bool factorize(const BsrMatrix& A, const Filter& S, SolveReport& report) override;
  SolveReport solve(const BsrMatrix& A, const Filter& S, std::span<const double> b,
                    std::span<const double> z, std::span<double> dv) override;
  void set_coordinates(std::span<const double> x) override;

  int rank() const;
  /// Whether the last preconditioner set-up had the rigid-body near-null space attached.
  bool has_near_null_space() const;
  int ranks() const;
  /// Block rows [begin, end) owned by this rank.
  Index row_begin() const;
  Index row_end() const;
  double assemble_seconds() const;    ///< projection + MatSetValuesBlocked + assembly, last factorize
  double setup_seconds() const;       ///< KSPSetUp (preconditioner), last factorize
  std::string ksp_type() const;       ///< after options were applied
  std::string pc_type() const;
  int preconditioner_setups() const;
  std::string matrix_type() const;    ///< seqbaij, mpibaij, seqaij or mpiaij

 private:
  struct Impl;
  std::unique_ptr<Impl> impl_;
};

/// Initialise PETSc (and MPI, when not yet initialised) once per process; finalised at exit.
/// Safe to call more than once. Throws SolverError when PETSc cannot start.
void petsc_ensure_initialized();
}  // namespace loom

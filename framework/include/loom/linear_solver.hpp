// LinearSolver: three phases (analyze_pattern once, factorize per matrix, solve), after
// polysolve. Solves A dv = b on the range of the constraint filter S with the prescribed
// constrained part z: (I - S) dv = z and S (A dv - b) = 0 (NUMERICS.md 3.3/3.4).
#pragma once

#include <span>
#include <string>

#include "loom/bsr.hpp"
#include "loom/common.hpp"

namespace loom {

struct SolveReport {
  bool converged = false;
  int iterations = 0;          ///< 1 for direct solvers
  double residual = 0;         ///< relative residual |S(b - A dv)| / |S(b - A z)| (0 if b-hat is 0)
  double analyze_seconds = 0;
  double factorize_seconds = 0;
  double solve_seconds = 0;
  std::string message;         ///< why it failed, when it failed
};

/// A symmetric positive semidefinite operator E that a solver adds to A without storing it
/// (matrix-free terms, e.g. baraff_witkin's self-contact springs: their blocks couple vertices
/// the material does not, and would otherwise grow A's pattern whenever contacts come and go).
/// The solve is then of (A + E) on range(S): S (A + E) dv = S b, (I - S) dv = z.
class ExtraOperator {
 public:
  virtual ~ExtraOperator() = default;
  /// y += scale E x (3n entries each; E's rows and columns over every vertex, unfiltered).
  virtual void apply_add(const double* x, double* y, double scale) const = 0;
  /// D_i += E_ii for every vertex i (D: 9 doubles per vertex, row-major).
  virtual void add_diagonal(double* D) const = 0;
};

class LinearSolver {
 public:
  virtual ~LinearSolver() = default;
  virtual std::string name() const = 0;
  /// Symbolic phase: called once per sparsity pattern.
  virtual void analyze_pattern(const BsrMatrix& A, const Filter& S) = 0;
  /// Numeric phase: called each time A's values (or S) change. Returns false (with
  /// report.message) when A is not positive definite on range(S).
  virtual bool factorize(const BsrMatrix& A, const Filter& S, SolveReport& report) = 0;
  /// Solve. dv holds the initial guess on entry (warm start) and the solution on exit.
  virtual SolveReport solve(const BsrMatrix& A, const Filter& S, std::span<const double> b,
                            std::span<const double> z, std::span<double> dv) = 0;
  /// Vertex positions (3n), given before factorize() by integrators that have them. Solvers
  /// that use geometry read them (the rigid-body near-null space of eigen_pcg's sa_amg and of
  /// petsc's gamg / boomeramg); the others ignore them.
  virtual void set_coordinates(std::span<const double> x) { (void)x; }
  /// Whether set_extra_operator() is honoured (the CPU filtered_pcg, every preconditioner);
  /// an integrator assembles the terms into A for the others (docs/CONTACT.md says why the
  /// direct solvers keep that path).
  virtual bool supports_extra_operator() const { return false; }
  /// From the next factorize() on, solve with A + E (E's diagonal blocks join the
  /// preconditioner's); null removes it. E must stay alive and unchanged until then.
  virtual void set_extra_operator(const ExtraOperator* E) { (void)E; }
  /// Iterative solvers: multiply the relative tolerance of the next solves by s (> 0; 1
  /// restores the scene's), e.g. for intermediate solves whose answer only decides which
  /// constraints stay. Returns whether the solver honours it (direct solvers: false).
  virtual bool set_tolerance_scale(double s) {
    (void)s;
    return false;
  }
  /// The smallest system, in block rows, whose solve runs its loops on the OpenMP threads (the
  /// rule of common.hpp in rows, kParallelMinRows, or the solver's own setting); -1 when its
  /// solve never does (direct solvers, whose factorisation uses its own BLAS threads). The
  /// start-up rule of `threads: auto` reads it (Simulation::build, loom/threads.hpp): an
  /// iterative solve is most of an implicit step, so a mesh of at least this many vertices
  /// starts on the free cores although it is below kParallelMinVertices.
  virtual Index parallel_min_rows() const { return -1; }
};

}  // namespace loom

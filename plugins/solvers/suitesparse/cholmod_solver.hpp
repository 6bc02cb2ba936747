// `cholmod` linear solver: SuiteSparse CHOLMOD supernodal Cholesky of the projected system
// A~ = S A S + (I - S) (NUMERICS.md 3.4). Symbolic analysis (fill-reducing ordering) once per
// pattern, numeric factorisation per factorize() or every `reuse_factorization_steps` calls;
// with a stale factor the solve runs PCG preconditioned by that factor until `tolerance`.
#pragma once

#include <memory>
#include <string>
#include <vector>

#include "loom/factor_pcg.hpp"
#include "loom/linear_solver.hpp"
#include "loom/param_spec.hpp"
#include "loom/params.hpp"

namespace loom {

struct CholmodOptions {
  double tolerance = 1e-10;         ///< relative residual |S(b - A dv)| / |S(b - A z)|
  int reuse_factorization_steps = 1;  ///< refactor every N factorize() calls (1 = always)
  int max_iterations = 50;          ///< PCG iterations with a stale factor before refactoring
  std::string ordering = "auto";    ///< auto | amd | metis | nesdis | natural
  std::string factorization = "supernodal";  ///< supernodal | simplicial | auto
  int blas_threads = 0;             ///< 0: $OPENBLAS_NUM_THREADS if set, else omp_get_max_threads()
  /// assembled | factor_preconditioned_pcg: how an extra operator E (self-contact springs) is
  /// solved; as eigen_ldlt's key of the same name (loom/factor_pcg.hpp).
  std::string contact_springs = "assembled";
  double contact_tolerance = factor_pcg::kDefaultTolerance;  ///< factor_preconditioned_pcg: true relative residual on A + E
  int contact_max_iterations = factor_pcg::kDefaultMaxIterations;  ///< factor_preconditioned_pcg: iterations before the solve fails
  /// The keys of cholmod, read by from_params.
  static const ParamSpec& spec();
  static CholmodOptions from_params(const Params& p);
};

class CholmodSolver final : public LinearSolver {
 public:
  explicit CholmodSolver(const CholmodOptions& options = {});
  explicit CholmodSolver(const Params& p) : CholmodSolver(CholmodOptions::from_params(p)) {}
  ~CholmodSolver() override;
  CholmodSolver(const CholmodSolver&) = delete;
  CholmodSolver& operator=(const CholmodSolver&) = delete;

  std::string name() const override { return "cholmod"; }
  void analyze_pattern(const BsrMatrix& A, const Filter& S) override;
  bool factorize(const BsrMatrix& A, const Filter& S, SolveReport& report) override;
  SolveReport solve(const BsrMatrix& A, const Filter& S, std::span<const double> b,
                    std::span<const double> z, std::span<double> dv) override;

  /// contact_springs: factor_preconditioned_pcg takes E matrix-free.
  bool supports_extra_operator() const override;
  void set_extra_operator(const ExtraOperator* E) override;

  // Introspection (tests, benchmarks, `loom validate`).
  int numeric_factorizations() const;    ///< how many times the numeric factorisation ran
  std::string ordering_used() const;     ///< e.g. "metis", "amd"
  bool is_supernodal() const;
  double factor_nnz() const;             ///< nnz(L)
  double factor_flops() const;           ///< flop count of one factorisation (CHOLMOD's estimate)

 private:
  struct Impl;
  std::unique_ptr<Impl> impl_;
};

/// Name of the BLAS library that dgemm_ resolves to at run time (path of the shared object),
/// and OpenBLAS's configuration string when it is OpenBLAS (empty otherwise).
std::string cholmod_blas_library();
std::string cholmod_openblas_config();
/// Number of BLAS threads OpenBLAS uses now (-1 when the BLAS is not OpenBLAS).
int cholmod_blas_threads();

}  // namespace loom

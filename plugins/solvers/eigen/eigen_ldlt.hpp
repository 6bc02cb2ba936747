// eigen_ldlt: sparse LDL^T (Eigen::SimplicialLDLT) of the projected system of
// NUMERICS.md 3.4, A~ = S A S + (I - S), b~ = S (b - A z) + z. The scalar structure and the
// symbolic analysis (AMD ordering, elimination tree) are built once per pattern; each
// factorize() only rewrites the values and refactorizes numerically.
#pragma once

#include <Eigen/SparseCholesky>
#include <Eigen/SparseCore>
#include <span>
#include <string>
#include <vector>

#include "loom/factor_pcg.hpp"
#include "loom/linear_solver.hpp"
#include "loom/param_spec.hpp"
#include "loom/params.hpp"
#include "loom/solver_common.hpp"

namespace loom {

struct LdltOptions {
  /// A pivot d_k <= pivot_tolerance * max_k |d_k| counts as non-positive (A not SPD).
  double pivot_tolerance = 1e-14;
  /// assembled: an extra operator E (self-contact springs) is assembled into A by the
  /// integrator (the pattern grows, each solve refactors). factor_preconditioned_pcg: the
  /// solver takes E matrix-free, factors A~ alone (again only when A or S changed) and solves
  /// A + E by the filtered PCG preconditioned with that factor (loom/factor_pcg.hpp).
  std::string contact_springs = "assembled";
  double contact_tolerance = factor_pcg::kDefaultTolerance;  ///< that PCG's true relative residual on S (A + E)
  int contact_max_iterations = factor_pcg::kDefaultMaxIterations;  ///< that PCG's cap; past it the solve fails (clear message)
};

/// The keys of eigen_ldlt (pivot_tolerance), read by parse_ldlt_options.
const ParamSpec& ldlt_spec();
LdltOptions parse_ldlt_options(const Params& p);

class EigenLdlt final : public LinearSolver {
 public:
  explicit EigenLdlt(LdltOptions options = {});
  std::string name() const override { return "eigen_ldlt"; }
  void analyze_pattern(const BsrMatrix& A, const Filter& S) override;
  bool factorize(const BsrMatrix& A, const Filter& S, SolveReport& report) override;
  SolveReport solve(const BsrMatrix& A, const Filter& S, std::span<const double> b,
                    std::span<const double> z, std::span<double> dv) override;

  /// contact_springs: factor_preconditioned_pcg takes E matrix-free.
  bool supports_extra_operator() const override { return factor_pcg_; }
  void set_extra_operator(const ExtraOperator* E) override { extra_ = factor_pcg_ ? E : nullptr; }
  /// How many numeric factorizations ran (tests, benchmarks).
  int numeric_factorizations() const { return numeric_count_; }
  /// The projected matrix of the last factorize() (tests).
  const Eigen::SparseMatrix<double>& projected_matrix() const { return mat_; }

 private:
  LdltOptions options_;
  const BsrPattern* pattern_ = nullptr;
  Index n_ = -1;
  solver::ScalarPattern sp_;
  Eigen::SparseMatrix<double> mat_;  // column-major, full (both triangles)
  Eigen::SimplicialLDLT<Eigen::SparseMatrix<double>> ldlt_;
  Eigen::VectorXd rhs_, sol_;
  std::vector<double> work_;
  bool factorized_ = false;
  double analyze_seconds_ = 0;
  bool factor_pcg_ = false;            // contact_springs: factor_preconditioned_pcg
  const ExtraOperator* extra_ = nullptr;
  std::vector<double> factored_values_;  // A~'s values of the factor (factor_pcg_: skip a refactor)
  std::vector<double> r_, c_, q_, s_;    // the PCG's work vectors
  int numeric_count_ = 0;
};

}  // namespace loom

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

#include "loom/linear_solver.hpp"
#include "loom/param_spec.hpp"
#include "loom/params.hpp"
#include "loom/solver_common.hpp"

namespace loom {

struct LdltOptions {
  /// A pivot d_k <= pivot_tolerance * max_k |d_k| counts as non-positive (A not SPD).
  double pivot_tolerance = 1e-14;
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
};

}  // namespace loom

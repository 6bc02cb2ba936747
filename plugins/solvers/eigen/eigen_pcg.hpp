// eigen_pcg: the corrected modified (filtered) PCG of Baraff & Witkin (NUMERICS.md 3.3)
// with the Ascher-Boxerman start, run directly on the 3x3 block-sparse matrix.
#pragma once

#include <memory>
#include <span>
#include <string>
#include <vector>

#include "loom/linear_solver.hpp"
#include "loom/param_spec.hpp"
#include "loom/params.hpp"
#include "sa_amg.hpp"
#include "float_spmv.hpp"
#include "upper_spmv.hpp"

namespace loom {

enum class PcgPreconditioner { None, Jacobi, BlockJacobi, SaAmg };

struct PcgOptions {
  PcgPreconditioner preconditioner = PcgPreconditioner::BlockJacobi;
  double tolerance = 1e-5;     ///< relative: |S(b - A dv)| <= tolerance |S(b - A z)|
  int max_iterations = 1000;
  /// The iteration runs on all OpenMP threads only from this many vertices on (below it
  /// the per-iteration barriers cost more than they save, and far more when the machine is
  /// oversubscribed). 0 = always parallel.
  Index parallel_min_rows = kParallelMinRows;  // the rule in common.hpp (a scene may override it)
  amg::SaAmgOptions amg;       ///< preconditioner: sa_amg (the `sa_amg:` map)
  /// true: the iteration's SpMV reads only the blocks on and above the diagonal
  /// (upper_spmv.hpp) whenever A is symmetric to rounding (checked at every factorize).
  /// Off by default: on one thread of this machine it was not faster than the full rows
  /// (docs/plugins/solvers.md); the benchmark's `_upperspmv` variant measures it.
  bool upper_triangle_spmv = false;
  /// true (`spmv_storage: float`): the iteration's SpMV q = S A c reads a float copy of A's
  /// values, written at every factorize() (float_spmv.hpp); c, q, the residuals, the iterates
  /// and every sum stay double, and the start and the stopping rule use the double A (the true
  /// residual), so the answer still meets `tolerance` on A. Takes precedence over
  /// upper_triangle_spmv. Off by default (docs/plugins/solvers.md has what it saves).
  bool float_spmv = false;
};

/// The keys of filtered_pcg (cpu and cuda): tolerance, max_iterations, preconditioner (none |
/// jacobi | block_jacobi | sa_amg), and for cpu parallel_min_rows and the sa_amg: map.
const ParamSpec& filtered_pcg_spec();
/// The same keys under the deprecated name eigen_pcg.
const ParamSpec& pcg_spec();
/// Reads them through `spec`; `backend` other than cpu leaves the cpu-only keys unread and
/// refuses preconditioner: sa_amg.
PcgOptions parse_pcg_options(const Params& p, const ParamSpec& spec = filtered_pcg_spec(),
                             const std::string& backend = "cpu");

class EigenPcg final : public LinearSolver {
 public:
  /// `name`: filtered_pcg, or eigen_pcg (its former, deprecated name).
  explicit EigenPcg(PcgOptions options = {}, std::string name = "filtered_pcg");
  std::string name() const override { return name_; }
  void analyze_pattern(const BsrMatrix& A, const Filter& S) override;
  bool factorize(const BsrMatrix& A, const Filter& S, SolveReport& report) override;
  SolveReport solve(const BsrMatrix& A, const Filter& S, std::span<const double> b,
                    std::span<const double> z, std::span<double> dv) override;
  void set_coordinates(std::span<const double> x) override;
  /// The matrix-free term E (linear_solver.hpp) joins the SpMV and the residuals, and its
  /// diagonal blocks the preconditioner: the (block) Jacobi blocks, or with sa_amg level 0's
  /// diagonal blocks (and through the Galerkin products the coarse levels; the hierarchy's
  /// pattern stays A's). Every preconditioner.
  bool supports_extra_operator() const override { return true; }
  void set_extra_operator(const ExtraOperator* E) override;
  bool set_tolerance_scale(double s) override {
    tolerance_scale_ = s;
    return true;
  }
  Index parallel_min_rows() const override { return options_.parallel_min_rows; }
  const PcgOptions& options() const { return options_; }
  /// The multigrid hierarchy (preconditioner: sa_amg), null before the first factorize().
  amg::SaAmg* amg() { return amg_.get(); }

 private:
  PcgOptions options_;
  std::unique_ptr<amg::SaAmg> amg_;
  std::vector<double> coords_;
  Index n_ = 0;
  std::vector<double> pinv_;  // 9 per vertex: S_i P_i^{-1} S_i
  const ExtraOperator* extra_ = nullptr;  // E of set_extra_operator (null: none)
  // sa_amg with E: A's values at the last full set-up (kept once an E has been set), so that
  // a factorize() whose only change is E refreshes level 0's diagonal alone.
  bool extra_seen_ = false;
  std::vector<double> amg_values_;
  double tolerance_scale_ = 1.0;          // set_tolerance_scale
  std::vector<double> diag_;  // 9 per vertex: A_ii + E_ii (with extra_)
  std::vector<double> r_, c_, q_, s_;
  std::string name_;
  UpperTriangleSpmv upper_;
  const BsrPattern* upper_pattern_ = nullptr;
  Index upper_nnz_ = -1;
  bool use_upper_ = false;  // A symmetric to rounding at the last factorize
  std::vector<float> af_;   // float_spmv: A's values in float, 9 per block, 4 zeros of padding

 public:
  /// Whether the last factorize() found A symmetric and the SpMV uses its upper triangle.
  bool upper_triangle_in_use() const { return use_upper_; }
};

}  // namespace loom

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
};

/// The keys of eigen_pcg: tolerance, max_iterations, preconditioner (none | jacobi |
/// block_jacobi | sa_amg), parallel_min_rows and the sa_amg: map.
const ParamSpec& pcg_spec();
/// Reads them through pcg_spec().
PcgOptions parse_pcg_options(const Params& p);

class EigenPcg final : public LinearSolver {
 public:
  explicit EigenPcg(PcgOptions options = {});
  std::string name() const override { return "eigen_pcg"; }
  void analyze_pattern(const BsrMatrix& A, const Filter& S) override;
  bool factorize(const BsrMatrix& A, const Filter& S, SolveReport& report) override;
  SolveReport solve(const BsrMatrix& A, const Filter& S, std::span<const double> b,
                    std::span<const double> z, std::span<double> dv) override;
  void set_coordinates(std::span<const double> x) override;
  const PcgOptions& options() const { return options_; }
  /// The multigrid hierarchy (preconditioner: sa_amg), null before the first factorize().
  amg::SaAmg* amg() { return amg_.get(); }

 private:
  // One PCG run from the current dv and residual r (in range(S)); returns the iterations
  // taken and sets status: 0 converged, 1 iteration cap, 2 non-positive curvature,
  // 3 non-positive or non-finite r^T P r.
  int iterate(const BsrMatrix& A, const Filter& S, std::span<double> dv, double threshold2,
              int max_iterations, int& status, double& curvature);

  // The same iteration with the V-cycle as preconditioner (s = S M r).
  int iterate_amg(const BsrMatrix& A, const Filter& S, std::span<double> dv, double threshold2,
                  int max_iterations, int& status, double& curvature);

  PcgOptions options_;
  std::unique_ptr<amg::SaAmg> amg_;
  std::vector<double> coords_;
  Index n_ = 0;
  std::vector<double> pinv_;  // 9 per vertex: S_i P_i^{-1} S_i
  std::vector<double> r_, c_, q_, s_;
  struct alignas(64) Partial { double v[4]; };
  std::vector<Partial> partial_;
  double rr_ = 0;             // |r|^2 of the current residual
};

}  // namespace loom

// Modified (filtered) preconditioned CG of NUMERICS.md 3.3 on device vectors: SpMV through the
// seam (cuSPARSE bsrmv; a Thrust SpMV in the OpenMP test build), dot products as Thrust
// reductions, the constraint filter S applied vertex by vertex (only constrained vertices).
//   dv <- S dv + z (warm start) or z;  r <- S(b - A dv);  c <- S Pm^-1 r;  delta <- r.c
//   delta0 <- bh.Pm^-1 bh with bh = S(b - A z);  loop while delta > tol^2 delta0:
//   q <- S A c;  alpha <- delta / c.q;  dv += alpha c;  r -= alpha q;  s <- Pm^-1 r;
//   delta' <- r.s;  c <- S(s + (delta'/delta) c)
// Pm is diag(A) (jacobi), its 3x3 block diagonal (block_jacobi, default) or I (none).
#pragma once

#include <string>

#include "device_model.hpp"
#include "loom/bsr.hpp"
#include "loom/linear_solver.hpp"
#include "loom/param_spec.hpp"
#include "loom/params.hpp"

namespace loom::cuda {

struct PcgOptions {
  double tolerance = 1e-6;     ///< on sqrt(r.Pm^-1 r / bh.Pm^-1 bh)
  int max_iterations = 10000;
  enum class Preconditioner { None, Jacobi, BlockJacobi } preconditioner = Preconditioner::BlockJacobi;
};
/// The keys of cusparse_pcg: tolerance, max_iterations, preconditioner (none | jacobi |
/// block_jacobi), read by parse_pcg_options.
const ParamSpec& cusparse_pcg_spec();
PcgOptions parse_pcg_options(const Params& p);

/// The constraint filter on the device: free DOF count and projector per vertex, and the
/// list of constrained vertices.
template <class T>
struct DeviceFilter {
  Index n = 0, num_constrained = 0;
  DVec<unsigned char> free;
  DVec<T> proj;
  DVec<Index> constrained;
  void upload(const Filter& S);
};

template <class T>
class DevicePcg {
 public:
  explicit DevicePcg(PcgOptions o = {}) : opt_(o) {}
  const PcgOptions& options() const { return opt_; }
  /// Allocate work vectors for n block rows.
  void analyze(Index n);
  /// Build the preconditioner from A's diagonal blocks; false (with a message) when a diagonal
  /// (block) is not positive definite.
  bool factorize(const DeviceBsr<T>& A, SolveReport& report);
  /// Solve on range(S) with (I - S) dv = z; dv holds the warm start on entry.
  SolveReport solve(const DeviceBsr<T>& A, const DeviceFilter<T>& S, const DVec<T>& b, const DVec<T>& z,
                    DVec<T>& dv);

 private:
  PcgOptions opt_;
  Index n_ = 0;
  DVec<T> pinv_, r_, c_, q_, s_, t_;
};

/// cusparse_pcg as a LinearSolver (host interface: uploads A, S, b, z, dv per call); the
/// CUDA baraff_witkin uses its DevicePcg directly on device data.
class CusparsePcg final : public LinearSolver {
 public:
  explicit CusparsePcg(const Params& p = Params()) : pcg_(parse_pcg_options(p)) {}
  explicit CusparsePcg(PcgOptions o) : pcg_(o) {}
  std::string name() const override { return "cusparse_pcg"; }
  void analyze_pattern(const BsrMatrix& A, const Filter& S) override;
  bool factorize(const BsrMatrix& A, const Filter& S, SolveReport& report) override;
  SolveReport solve(const BsrMatrix& A, const Filter& S, std::span<const double> b, std::span<const double> z,
                    std::span<double> dv) override;
  const PcgOptions& options() const { return pcg_.options(); }

 private:
  DevicePcg<double> pcg_;
  DeviceBsr<double> A_;
  DeviceFilter<double> S_;
  DVec<double> b_, z_, dv_;
  std::vector<double> host_;
};

}  // namespace loom::cuda

// The filtered PCG of loom/filtered_pcg.hpp on device vectors: the one loop of every backend,
// instantiated here with device operations: SpMV through the seam (cuSPARSE bsrmv; a Thrust
// SpMV in the OpenMP test build), dot products as Thrust reductions, the constraint filter S
// applied vertex by vertex (only constrained vertices), and the filtered preconditioner
// P_i = S_i M_i^-1 S_i with M_i the (projected) block diagonal (block_jacobi, default), the
// diagonal (jacobi) or I (none), as on the CPU. Stopping rule: the true relative residual
// |S(b - A dv)| <= tolerance |S(b - A z)| (loom/filtered_pcg.hpp).
//
// Mixed precision: DevicePcg<T, M> keeps the matrix and the filter in M and the vectors, the
// preconditioner and every reduction in T. The device baraff_witkin with `precision: float`
// solves with DevicePcg<double, float>: CG in double on the float system, so it reaches the
// tolerance that float vectors cannot (their rounding floor; docs/plugins/cuda.md).
#pragma once

#include <string>
#include <utility>

#include "device_model.hpp"
#include "loom/bsr.hpp"
#include "loom/linear_solver.hpp"
#include "loom/param_spec.hpp"
#include "loom/params.hpp"

namespace loom::cuda {

struct PcgOptions {
  double tolerance = 1e-5;     ///< true relative residual |S(b - A dv)| / |S(b - A z)| (as on the CPU)
  int max_iterations = 1000;
  enum class Preconditioner { None, Jacobi, BlockJacobi } preconditioner = Preconditioner::BlockJacobi;
};
/// The keys of filtered_pcg on backend cuda: tolerance, max_iterations, preconditioner (none |
/// jacobi | block_jacobi), declared as in the cpu plugin (same defaults and meaning).
const ParamSpec& filtered_pcg_cuda_spec();
/// The same keys under the deprecated name cusparse_pcg.
const ParamSpec& cusparse_pcg_spec();
PcgOptions parse_pcg_options(const Params& p, const ParamSpec& spec = filtered_pcg_cuda_spec());

/// The constraint filter on the device: free DOF count and projector per vertex, and the
/// list of constrained vertices.
template <class T>
struct DeviceFilter {
  Index n = 0, num_constrained = 0;
  DVec<unsigned char> free;
  DVec<T> proj;
  DVec<Index> constrained;
  void upload(const Filter& S);
  /// Size the arrays for n vertices, all free (free and proj are then written on the device).
  void resize(Index n);
  /// Rebuild the list of constrained vertices (free < 3, increasing) from `free` on the device.
  void rebuild_constrained();
};

/// T: vectors, preconditioner, reductions; M: the matrix A and the filter S (M = T, or T =
/// double with M = float: the SpMV then reads float blocks into double sums, one thread per row).
template <class T, class M = T>
class DevicePcg {
 public:
  explicit DevicePcg(PcgOptions o = {}) : opt_(o) {}
  const PcgOptions& options() const { return opt_; }
  /// Allocate work vectors for n block rows.
  void analyze(Index n);
  /// Build the filtered preconditioner S_i M_i^-1 S_i from A's diagonal blocks; false (with a
  /// message) when a diagonal (block) is not positive definite.
  bool factorize(const DeviceBsr<M>& A, const DeviceFilter<M>& S, SolveReport& report);
  /// Solve on range(S) with (I - S) dv = z; dv holds the warm start on entry.
  SolveReport solve(const DeviceBsr<M>& A, const DeviceFilter<M>& S, const DVec<T>& b, const DVec<T>& z,
                    DVec<T>& dv);
  /// Prefix of the messages (the plugin's name).
  void set_name(std::string name) { name_ = std::move(name); }
  /// The next solves run at s times the tolerance (1 restores it), as LinearSolver::set_tolerance_scale.
  void set_tolerance_scale(double s) { tolerance_scale_ = s; }

 private:
  PcgOptions opt_;
  double tolerance_scale_ = 1.0;
  std::string name_ = "filtered_pcg";
  Index n_ = 0;
  DVec<T> pinv_, r_, c_, q_, s_;
};

/// filtered_pcg on backend cuda as a LinearSolver (host interface: uploads A, S, b, z, dv per
/// call); the CUDA baraff_witkin uses its DevicePcg directly on device data. `name` is
/// filtered_pcg or the deprecated cusparse_pcg.
class CusparsePcg final : public LinearSolver {
 public:
  explicit CusparsePcg(const Params& p = Params(), std::string name = "filtered_pcg")
      : pcg_(parse_pcg_options(p, name == "cusparse_pcg" ? cusparse_pcg_spec() : filtered_pcg_cuda_spec())),
        name_(std::move(name)) {
    pcg_.set_name(name_);
  }
  explicit CusparsePcg(PcgOptions o, std::string name = "filtered_pcg") : pcg_(o), name_(std::move(name)) {
    pcg_.set_name(name_);
  }
  std::string name() const override { return name_; }
  void analyze_pattern(const BsrMatrix& A, const Filter& S) override;
  bool factorize(const BsrMatrix& A, const Filter& S, SolveReport& report) override;
  SolveReport solve(const BsrMatrix& A, const Filter& S, std::span<const double> b, std::span<const double> z,
                    std::span<double> dv) override;
  const PcgOptions& options() const { return pcg_.options(); }

 private:
  DevicePcg<double> pcg_;
  std::string name_;
  DeviceBsr<double> A_;
  DeviceFilter<double> S_;
  DVec<double> b_, z_, dv_;
  std::vector<double> host_;
};

}  // namespace loom::cuda

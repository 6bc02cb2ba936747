#include "eigen_ldlt.hpp"
#include "loom/clock.hpp"
#include "loom/factor_pcg.hpp"

#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstdio>

namespace loom {

namespace {
}  // namespace

const ParamSpec& ldlt_spec() {
  static const ParamSpec spec = [] {
    const LdltOptions d;
    ParamSpec s("eigen_ldlt", "Eigen SimplicialLDLT of the projected system");
    s.number("pivot_tolerance", d.pivot_tolerance).range(ParamRange::closed(0, 1e-2)).help(
        "a pivot d_k <= pivot_tolerance max|d| counts as non-positive (A not SPD: the solve fails)");
    s.choice("contact_springs", d.contact_springs, {factor_pcg::kAssembled, factor_pcg::kFactorPreconditionedPcg})
        .help("assembled: self-contact springs assembled into A (the pattern grows, each solve refactors); "
              "factor_preconditioned_pcg: A alone factored, A + springs solved by PCG with that factor "
              "(docs/CONTACT.md)");
    s.number("contact_tolerance", d.contact_tolerance).range(ParamRange::closed(1e-15, 1e-2)).help(
        "factor_preconditioned_pcg: true relative residual |S(b - (A + E) dv)| / |S(b - (A + E) z)| to reach");
    s.integer("contact_max_iterations", d.contact_max_iterations).range(ParamRange::closed(1, 100000)).help(
        "factor_preconditioned_pcg: PCG iterations before the solve fails (then reduce dt or use assembled)");
    return s;
  }();
  return spec;
}

LdltOptions parse_ldlt_options(const Params& p) {
  LdltOptions o;
  if (!p.valid()) return o;
  const ParamReader r(p, ldlt_spec());
  o.pivot_tolerance = r.number("pivot_tolerance");
  o.contact_springs = r.text("contact_springs");
  o.contact_tolerance = r.number("contact_tolerance");
  o.contact_max_iterations = r.int32("contact_max_iterations");
  return o;
}

EigenLdlt::EigenLdlt(LdltOptions options)
    : options_(options), factor_pcg_(options_.contact_springs == factor_pcg::kFactorPreconditionedPcg) {}

void EigenLdlt::analyze_pattern(const BsrMatrix& A, const Filter& S) {
  const auto t0 = Clock::now();
  pattern_ = &A.pattern();
  n_ = A.rows();
  sp_ = solver::make_scalar_pattern(*pattern_);
  const int N = sp_.rows;
  const int nnz = sp_.outer[N];
  mat_ = Eigen::SparseMatrix<double>(N, N);
  mat_.resizeNonZeros(nnz);
  std::copy(sp_.outer.begin(), sp_.outer.end(), mat_.outerIndexPtr());
  std::copy(sp_.inner.begin(), sp_.inner.end(), mat_.innerIndexPtr());
  solver::fill_projected_csc(A, S, sp_, mat_.valuePtr());
  ldlt_.analyzePattern(mat_);
  rhs_.resize(N);
  sol_.resize(N);
  work_.assign(N, 0.0);
  if (factor_pcg_) {
    for (auto* v : {&r_, &c_, &q_, &s_}) v->assign(N, 0.0);
    factored_values_.assign(nnz, 0.0);
  }
  factorized_ = false;
  analyze_seconds_ = seconds_since(t0);
}

bool EigenLdlt::factorize(const BsrMatrix& A, const Filter& S, SolveReport& report) {
  if (&A.pattern() != pattern_ || A.rows() != n_) analyze_pattern(A, S);
  report.analyze_seconds = analyze_seconds_;
  analyze_seconds_ = 0;
  const auto t0 = Clock::now();
  solver::fill_projected_csc(A, S, sp_, mat_.valuePtr());
  if (factor_pcg_ && factorized_) {
    // The solves of one step that only add or release springs (E): same A, same S, so the
    // factor of A~ stands.
    const double* v = mat_.valuePtr();
    if (std::equal(v, v + factored_values_.size(), factored_values_.begin())) {
      report.factorize_seconds = seconds_since(t0);
      return true;
    }
  }
  ldlt_.factorize(mat_);
  ++numeric_count_;
  factorized_ = false;
  report.factorize_seconds = seconds_since(t0);
  if (ldlt_.info() != Eigen::Success) {
    report.converged = false;
    report.message =
        "eigen_ldlt: the factorization failed (zero pivot or NaN): the system matrix is singular or not finite "
        "on the free DOFs; reduce integrator.dt or check the material";
    return false;
  }
  const Eigen::VectorXd& D = ldlt_.vectorD();
  const double dmax = D.cwiseAbs().maxCoeff();
  Eigen::Index kmin = 0;
  const double dmin = D.minCoeff(&kmin);
  if (!std::isfinite(dmax) || !(dmin > options_.pivot_tolerance * dmax)) {
    char buf[160];
    std::snprintf(buf, sizeof buf, "pivot %.3g (largest %.3g)", dmin, dmax);
    report.converged = false;
    report.message = std::string("eigen_ldlt: non-positive ") + buf +
                     " in the LDL^T factorization: the system matrix is not positive definite on the free "
                     "DOFs (compressed elements without the Jacobian clamp, or a step too large for the "
                     "material); reduce integrator.dt, enable the material's Jacobian clamp, or set "
                     "integrator.on_solver_failure: halve_step";
    return false;
  }
  factorized_ = true;
  if (factor_pcg_) std::copy_n(mat_.valuePtr(), factored_values_.size(), factored_values_.begin());
  return true;
}

SolveReport EigenLdlt::solve(const BsrMatrix& A, const Filter& S, std::span<const double> b,
                             std::span<const double> z, std::span<double> dv) {
  const auto t0 = Clock::now();
  SolveReport rep;
  const std::size_t N = 3 * static_cast<std::size_t>(A.rows());
  if (b.size() != N || z.size() != N || dv.size() != N)
    throw std::invalid_argument("eigen_ldlt: vector sizes do not match the matrix");
  if (!factorized_ || &A.pattern() != pattern_) {
    rep.message = "eigen_ldlt: solve() called without a successful factorize()";
    return rep;
  }
  if (extra_) {  // A + E by PCG with A~'s factor as preconditioner
    auto factor = [this, N](const double* r, double* s) {
      std::copy_n(r, N, rhs_.data());
      sol_.noalias() = ldlt_.solve(rhs_);
      std::copy_n(sol_.data(), N, s);
      return ldlt_.info() == Eigen::Success;
    };
    rep = factor_pcg::solve(name(), A, S, b, z, extra_, factor, options_.contact_tolerance,
                            options_.contact_max_iterations, dv, r_, c_, q_, s_);
    rep.solve_seconds = seconds_since(t0);
    return rep;
  }
  std::span<double> rhs(rhs_.data(), N);
  const double bh = std::sqrt(solver::projected_rhs(A, S, b, z, rhs));
  sol_.noalias() = ldlt_.solve(rhs_);
  for (std::size_t k = 0; k < N; ++k) dv[k] = sol_[static_cast<Eigen::Index>(k)];
  // Exact on the constrained DOFs: (I - S) dv = z bit for bit.
  solver::apply_prescribed(S, z, dv);
  rep.iterations = 1;
  rep.residual = solver::relative_residual(A, S, b, dv, bh, work_);
  rep.converged = std::isfinite(rep.residual);
  if (!rep.converged) rep.message = "eigen_ldlt: the solution is not finite";
  rep.solve_seconds = seconds_since(t0);
  return rep;
}

}  // namespace loom

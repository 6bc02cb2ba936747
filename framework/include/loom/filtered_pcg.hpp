// The modified (filtered) preconditioned conjugate gradient of Baraff & Witkin (NUMERICS.md
// 3.3), written once for every backend. A backend supplies the vector operations (Ops, below);
// filtered_pcg_solve() runs the same iteration, the same start and the same stopping rule
// whatever the backend: the CPU plugin filtered_pcg (plugins/solvers/eigen, OpenMP loops)
// and the CUDA plugin filtered_pcg (plugins/backends/cuda, Thrust/cuSPARSE) both instantiate it.
//
// The problem: find dv with (I - S) dv = z and S (A dv - b) = 0, S the constraint filter.
//
//   Start (Ascher-Boxerman):  bh = S(b - A z);  dv <- S dv + z  (the warm start on the free
//     DOFs); r <- S(b - A dv), kept only if |r| < |bh|, else dv <- z, r <- bh.
//   Iteration:  s = P r, c = s, delta = r.s;  repeat
//     q = S A c;  alpha = delta / c.q;  dv += alpha c;  r -= alpha q;
//     s = P r;  delta' = r.s;  c = s + (delta'/delta) c
//   with P = S M^-1 S the filtered preconditioner (block Jacobi, Jacobi, none, or a
//   multigrid V-cycle followed by the filter).
//
// Stopping rule (one for every backend): the TRUE relative residual of the filtered system,
//     |S(b - A dv)| <= tolerance * |S(b - A z)|.
// The loop stops when the recursive residual |r| meets it; the true residual is then
// recomputed, and if rounding let the two drift apart the iteration restarts from the true
// residual (at most twice more). The reported residual is always the true one.
// Failures: the iteration cap; c.q <= 0 (A not positive definite on range(S)); r.s <= 0
// (the preconditioner not positive definite).
#pragma once

#include <cmath>
#include <concepts>
#include <cstdio>
#include <limits>
#include <string>
#include <utility>

#include "loom/linear_solver.hpp"

namespace loom::pcg {

/// The operations a backend provides, on vectors of type Ops::Vec (3n entries) with scalar
/// Ops::Real. A, S, b, z and the preconditioner are bound into the Ops object.
template <class Ops>
concept FilteredPcgOps = requires(Ops& o, typename Ops::Vec& v, const typename Ops::Vec& cv,
                                  typename Ops::Real a) {
  typename Ops::Real;
  /// out = S(b - A x); returns |out|^2.
  { o.residual(cv, v) } -> std::convertible_to<typename Ops::Real>;
  /// q = S A c (SpMV and filter); returns c.q.
  { o.apply_operator(cv, v) } -> std::convertible_to<typename Ops::Real>;
  /// s = P r (the preconditioner's apply, filtered); returns r.s.
  { o.precondition(cv, v) } -> std::convertible_to<typename Ops::Real>;
  /// x += alpha c; r -= alpha q (two axpy); returns r.r.
  { o.update(a, cv, cv, v, v) } -> std::convertible_to<typename Ops::Real>;
  /// c = s + beta c (axpby).
  o.xpby(cv, a, v);
  /// dv = S dv + z (keep the guess on the free DOFs) / dv = z.
  o.start(v);
  o.assign_prescribed(v);
  /// c = s.
  o.copy(cv, v);
};

struct Settings {
  double tolerance = 1e-5;   ///< on the true relative residual |S(b - A dv)| / |S(b - A z)|
  int max_iterations = 1000;
  bool warm_start = true;    ///< use dv on entry as the guess on the free DOFs
  const char* name = "filtered_pcg";  ///< prefix of the messages
};

/// The default tolerance of every backend.
inline constexpr double kDefaultTolerance = 1e-5;

/// The status of one run of the iteration.
/// RoundingFloor: the preconditioned residual norm r^T P^-1 r came out <= 0 but within rounding
/// of zero (|r^T P^-1 r| <= 64 eps of its starting value), or r^T P^-1 r or the curvature c^T A c
/// came out <= 0 once the residual was already within 64 eps of the right-hand side's (|r| <= 64
/// eps |S(b - A z)|): the iteration has reached what the precision can resolve, not an indefinite
/// preconditioner or system.
enum class Status { Converged = 0, IterationCap = 1, NonPositiveCurvature = 2, NonPositivePreconditioner = 3, RoundingFloor = 4 };

namespace detail {
inline std::string format(const char* fmt, double a, double b = 0, double c = 0) {
  char buf[512];
  std::snprintf(buf, sizeof buf, fmt, a, b, c);
  return buf;
}
}  // namespace detail

/// Iterates from dv with r = S(b - A dv) (|r|^2 = rr) until |r|^2 <= threshold2 or a failure.
/// r, c, q, s are work vectors; returns the iterations taken. floor2: |r|^2 at which a breakdown
/// counts as rounding (Status::RoundingFloor; 0: never by this rule).
template <FilteredPcgOps Ops>
int iterate(Ops& ops, typename Ops::Vec& dv, typename Ops::Vec& r, typename Ops::Vec& c, typename Ops::Vec& q,
            typename Ops::Vec& s, typename Ops::Real& rr, typename Ops::Real threshold2, int max_iterations,
            Status& status, double& curvature, double floor2 = 0) {
  using Real = typename Ops::Real;
  Real delta = ops.precondition(r, s);
  const double delta0 = std::fabs(static_cast<double>(delta));
  ops.copy(s, c);
  int it = 0;
  status = Status::IterationCap;
  curvature = 0;
  for (;;) {
    if (rr <= threshold2) { status = Status::Converged; break; }
    if (it >= max_iterations) { status = Status::IterationCap; break; }
    if (!(delta > Real(0)) || !std::isfinite(static_cast<double>(delta))) {
      const bool rounding = std::isfinite(static_cast<double>(delta)) && it > 0 &&
                            (std::fabs(static_cast<double>(delta)) <=
                                 64.0 * std::numeric_limits<Real>::epsilon() * delta0 ||
                             static_cast<double>(rr) <= floor2);
      status = rounding ? Status::RoundingFloor : Status::NonPositivePreconditioner;
      curvature = static_cast<double>(delta);
      break;
    }
    const Real cq = ops.apply_operator(c, q);
    if (!(cq > Real(0)) || !std::isfinite(static_cast<double>(cq))) {
      status = std::isfinite(static_cast<double>(cq)) && it > 0 && static_cast<double>(rr) <= floor2
                   ? Status::RoundingFloor
                   : Status::NonPositiveCurvature;
      curvature = static_cast<double>(cq);
      break;
    }
    const Real alpha = delta / cq;
    rr = ops.update(alpha, c, q, dv, r);
    const Real dnew = ops.precondition(r, s);
    const Real beta = dnew / delta;
    delta = dnew;
    ops.xpby(s, beta, c);
    ++it;
  }
  return it;
}

/// The whole solve (start, iteration, true-residual check and restarts, report). dv holds the
/// warm start on entry (used when settings.warm_start) and the answer on exit; r, c, q, s are
/// work vectors of the same size (their contents are overwritten).
template <FilteredPcgOps Ops>
SolveReport solve(Ops& ops, const Settings& settings, typename Ops::Vec& dv, typename Ops::Vec& r,
                  typename Ops::Vec& c, typename Ops::Vec& q, typename Ops::Vec& s) {
  using Real = typename Ops::Real;
  using Vec = typename Ops::Vec;
  SolveReport rep;
  Vec* pr = &r;  // the current residual; swapped with q on a restart
  Vec* pq = &q;
  // bh = S(b - A z): what is left to solve once the prescribed part is in place.
  ops.assign_prescribed(*pq);  // q = z
  const Real bh2r = ops.residual(*pq, *pr);
  const double bhat2 = static_cast<double>(bh2r);
  const double bh = std::sqrt(bhat2);
  if (!std::isfinite(bh)) {
    rep.message = std::string(settings.name) +
                  ": the right-hand side is not finite (NaN or Inf in the forces or the matrix)";
    return rep;
  }
  if (bhat2 == 0) {
    ops.assign_prescribed(dv);
    rep.converged = true;
    return rep;
  }
  Real rr = bh2r;
  if (settings.warm_start) {
    ops.start(dv);
    const Real rw = ops.residual(dv, *pq);
    if (rw < bh2r && std::isfinite(static_cast<double>(rw))) {
      std::swap(pr, pq);
      rr = rw;
    } else {  // the warm start is no better than none: start from z
      ops.assign_prescribed(dv);
    }
  } else {
    ops.assign_prescribed(dv);
  }
  const double tol = settings.tolerance;
  const Real threshold2 = static_cast<Real>(tol * tol * bhat2);
  // A breakdown with the residual already within 64 eps of |bh| is rounding (Status::RoundingFloor).
  const double eps64 = 64.0 * std::numeric_limits<Real>::epsilon();
  const double floor2 = eps64 * eps64 * bhat2;
  int total = 0;
  Status status = Status::IterationCap;
  double curvature = 0, rel = 0;
  for (int attempt = 0; attempt < 3; ++attempt) {
    total += iterate(ops, dv, *pr, c, *pq, s, rr, threshold2, settings.max_iterations - total, status, curvature,
                     floor2);
    if (status != Status::Converged) break;
    // The recursive residual has converged; check the true one (and restart from it if
    // rounding let the two drift apart).
    const Real tr2 = ops.residual(dv, *pq);
    rel = std::sqrt(static_cast<double>(tr2)) / bh;
    if (rel <= tol) break;
    std::swap(pr, pq);
    rr = tr2;
    status = Status::IterationCap;
  }
  if (status != Status::Converged) rel = std::sqrt(static_cast<double>(ops.residual(dv, *pq))) / bh;
  rep.iterations = total;
  rep.residual = rel;
  rep.converged = status == Status::Converged && rel <= tol;
  const std::string nm = settings.name;
  if (!rep.converged) {
    if (status == Status::NonPositiveCurvature)
      rep.message = nm + detail::format(
          ": non-positive curvature c^T A c = %.3g at iteration %.0f (relative residual %.3g): the "
          "system matrix is not positive definite on the free DOFs (compressed elements without the Jacobian "
          "clamp, or a step too large for the material); reduce integrator.dt, enable the material's Jacobian "
          "clamp, or set integrator.on_solver_failure: halve_step",
          curvature, total, rel);
    else if (status == Status::NonPositivePreconditioner)
      rep.message = nm + detail::format(
          ": the preconditioned residual norm r^T P^-1 r = %.3g is not positive at iteration %.0f "
          "(relative residual %.3g): the preconditioner or the system is not positive definite",
          curvature, total, rel);
    else if (status == Status::Converged || status == Status::RoundingFloor) {
      // The recursive residual got there three times (the true one did not), or r^T P^-1 r fell
      // to rounding level: either way the precision, not the iteration count, is the limit.
      const std::string fmt = std::string(
          ": the true relative residual stays at %.3g > tolerance %.3g after %.0f iterations, at the "
          "rounding floor of this solve: rounding limits what it can reach (") +
          (sizeof(Real) < sizeof(double) ? "float vectors); use precision: double, or raise the tolerance above it"
                                         : "double vectors); raise the tolerance above it");
      rep.message = nm + detail::format(fmt.c_str(), rel, tol, total);
    }
    else
      rep.message = nm + detail::format(
          ": not converged in %.0f iterations (relative residual %.3g > tolerance %.3g); raise "
          "max_iterations, reduce integrator.dt, or use a direct solver (eigen_ldlt, cholmod)",
          total, rel, tol);
  }
  return rep;
}

}  // namespace loom::pcg

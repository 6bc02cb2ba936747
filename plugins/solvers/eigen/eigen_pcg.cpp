#include "eigen_pcg.hpp"

#include <omp.h>
#if defined(__AVX2__) && defined(__FMA__)
#include <immintrin.h>
#endif

#include <algorithm>
#include <chrono>
#include <climits>
#include <cmath>
#include <cstdio>
#include <utility>

#include "block_row.hpp"
#include "loom/clock.hpp"
#include "loom/kernels/bsr_ops.hpp"
#include "loom/solver_common.hpp"

namespace loom {

namespace {
std::string format(const char* fmt, double a, double b = 0, double c = 0) {
  char buf[512];
  std::snprintf(buf, sizeof buf, fmt, a, b, c);
  return buf;
}
const char* precond_name(PcgPreconditioner p) {
  switch (p) {
    case PcgPreconditioner::None: return "none";
    case PcgPreconditioner::Jacobi: return "jacobi";
    case PcgPreconditioner::SaAmg: return "sa_amg";
    default: return "block_jacobi";
  }
}

}  // namespace

const ParamSpec& pcg_spec() {
  static const ParamSpec spec = [] {
    const PcgOptions d;
    const amg::SaAmgOptions m;
    ParamSpec s("eigen_pcg", "modified (filtered) PCG of Baraff-Witkin on the 3x3 block matrix");
    s.number("tolerance", d.tolerance).range(ParamRange::closed(1e-16, 0.5)).help(
        "relative residual: |S(b - A dv)| <= tolerance |S(b - A z)|");
    s.integer("max_iterations", d.max_iterations).range(ParamRange::closed(1, 1e8)).help(
        "iterations before the solve counts as failed");
    s.choice("preconditioner", precond_name(d.preconditioner), {"none", "jacobi", "block_jacobi", "sa_amg"}).help(
        "sa_amg: smoothed-aggregation multigrid V-cycle (options under sa_amg)");
    s.integer("parallel_min_rows", d.parallel_min_rows).range(ParamRange::closed(0, 1e9)).units("vertices").help(
        "loops run on all OpenMP threads from this many block rows on");
    ParamSpec a("sa_amg");
    a.choice("near_null_space", m.near_null_modes == 6 ? "rigid" : "translations", {"rigid", "translations"}).help(
        "rigid: translations and rotations (needs coordinates); translations: 3 modes");
    a.number("strength_threshold", m.strength_threshold).range(ParamRange::closed(0, 1)).help(
        "block (i,j) strong if |A_ij| > theta sqrt(|A_ii| |A_jj|)");
    a.integer("smoothing_sweeps", m.smoothing_sweeps).range(ParamRange::closed(1, 10)).help(
        "Gauss-Seidel sweeps before and after the coarse correction");
    a.integer("coarse_dofs", m.coarse_dofs).range(ParamRange::closed(6, 4000)).units("DOFs").help(
        "levels are added until one has at most this many DOFs (dense Cholesky)");
    a.integer("max_levels", m.max_levels).range(ParamRange::closed(1, 30)).help("most levels of the hierarchy");
    a.integer("prolongator_refresh_steps", m.prolongator_refresh_steps).range(ParamRange::closed(1, 1e6))
        .units("refreshes").help("rebuild the prolongator every k refreshes (1 = every step)");
    a.integer("hierarchy_refresh_steps", m.hierarchy_refresh_steps).range(ParamRange::closed(1, 1e6))
        .units("refreshes").help("recompute the coarse levels every k refreshes (1 = every step)");
    a.integer("aggressive_levels", m.aggressive_levels).range(ParamRange::closed(0, 30)).help(
        "levels (from the finest) aggregated on the distance-2 strength graph: bigger aggregates");
    a.choice("storage", m.float_storage ? "float" : "double", {"double", "float"}).help(
        "precision of the hierarchy's matrices read by the V-cycle (set-up and sums stay double)");
    a.number("prolongator_damping", m.prolongator_damping).range(ParamRange::closed(0, 1.9)).help(
        "omega = damping / lambda_max(D^-1 A)");
    s.map("sa_amg", std::move(a)).help("options of preconditioner: sa_amg");
    return s;
  }();
  return spec;
}

PcgOptions parse_pcg_options(const Params& p) {
  PcgOptions o;
  if (!p.valid()) return o;
  const ParamReader r(p, pcg_spec());
  o.tolerance = r.number("tolerance");
  o.max_iterations = r.int32("max_iterations");
  const std::string pc = r.text("preconditioner");
  o.parallel_min_rows = static_cast<Index>(r.integer("parallel_min_rows"));
  o.preconditioner = pc == "none"     ? PcgPreconditioner::None
                     : pc == "jacobi" ? PcgPreconditioner::Jacobi
                     : pc == "sa_amg" ? PcgPreconditioner::SaAmg
                                      : PcgPreconditioner::BlockJacobi;
  if (p.has("sa_amg")) {
    const ParamReader a = r.section("sa_amg");
    if (o.preconditioner != PcgPreconditioner::SaAmg)
      a.params().fail("the sa_amg: options apply only with preconditioner: sa_amg");
    if (!a.params().is_map()) a.params().fail("sa_amg: must be a map, e.g. sa_amg: {near_null_space: rigid}");
    amg::SaAmgOptions& m = o.amg;
    m.near_null_modes = a.text("near_null_space") == "rigid" ? 6 : 3;
    m.strength_threshold = a.number("strength_threshold");
    m.smoothing_sweeps = a.int32("smoothing_sweeps");
    m.coarse_dofs = static_cast<Index>(a.integer("coarse_dofs"));
    m.max_levels = a.int32("max_levels");
    m.prolongator_refresh_steps = a.int32("prolongator_refresh_steps");
    m.hierarchy_refresh_steps = a.int32("hierarchy_refresh_steps");
    m.aggressive_levels = a.int32("aggressive_levels");
    m.float_storage = a.text("storage") == "float";
    m.prolongator_damping = a.number("prolongator_damping");
    a.params().check_unused();
  }
  return o;
}

EigenPcg::EigenPcg(PcgOptions options) : options_(options) {}

void EigenPcg::set_coordinates(std::span<const double> x) { coords_.assign(x.begin(), x.end()); }

void EigenPcg::analyze_pattern(const BsrMatrix& A, const Filter& S) {
  (void)S;
  if (amg_) amg_->invalidate();
  n_ = A.rows();
  const std::size_t N = 3 * static_cast<std::size_t>(n_);
  pinv_.assign(9 * static_cast<std::size_t>(n_), 0.0);
  r_.assign(N, 0.0);
  c_.assign(N, 0.0);
  q_.assign(N, 0.0);
  s_.assign(N, 0.0);
  partial_.assign(static_cast<std::size_t>(std::max(1, omp_get_max_threads())) + 1, Partial{});
}

bool EigenPcg::factorize(const BsrMatrix& A, const Filter& S, SolveReport& report) {
  const auto t0 = Clock::now();
  if (A.rows() != n_) analyze_pattern(A, S);
  const BsrPattern& P = A.pattern();
  const Index n = n_;
  const PcgPreconditioner pc = options_.preconditioner;
  if (pc == PcgPreconditioner::SaAmg) {
    if (!amg_) amg_ = std::make_unique<amg::SaAmg>(options_.amg);
    std::span<const double> x;
    if (coords_.size() == 3 * static_cast<std::size_t>(n)) x = coords_;
    std::string msg;
    const bool ok = amg_->setup(A, S, x, msg);
    report.factorize_seconds = seconds_since(t0);
    if (!ok) {
      report.converged = false;
      report.message = "eigen_pcg: " + msg;
    }
    return ok;
  }
  Index bad = INT_MAX;
#pragma omp parallel for schedule(static) reduction(min : bad) if (n >= solver::kParallelMinRows)
  for (Index i = 0; i < n; ++i) {
    double* Pi = pinv_.data() + 9 * static_cast<std::size_t>(i);
    const int f = S.free_dofs(i);
    if (f == 0) {
      for (int e = 0; e < 9; ++e) Pi[e] = 0.0;
      continue;
    }
    const double* D = A.block(P.diag[i]);
    double M[9] = {0, 0, 0, 0, 0, 0, 0, 0, 0};
    switch (pc) {
      case PcgPreconditioner::None:
        M[0] = M[4] = M[8] = 1.0;
        break;
      case PcgPreconditioner::Jacobi:
        for (int a = 0; a < 3; ++a) {
          const double d = D[4 * a];
          if (!(d > 0.0) || !std::isfinite(d)) bad = std::min(bad, i);
          M[4 * a] = 1.0 / d;
        }
        break;
      case PcgPreconditioner::SaAmg:  // handled above
      case PcgPreconditioner::BlockJacobi: {
        double B[9];
        solver::projected_block(S, i, i, D, B);
        if (!kernels::mat3_spd_inverse(B, M) || !std::isfinite(M[0] + M[4] + M[8])) bad = std::min(bad, i);
        break;
      }
    }
    if (f == 3) {
      for (int e = 0; e < 9; ++e) Pi[e] = M[e];
    } else {
      kernels::mat3_project(S.projector(i).data(), M, S.projector(i).data(), Pi);
    }
  }
  report.factorize_seconds = seconds_since(t0);
  if (bad != INT_MAX) {
    report.converged = false;
    report.message = "eigen_pcg: the " + std::string(precond_name(pc)) + " preconditioner's diagonal " +
                     (pc == PcgPreconditioner::BlockJacobi ? "block" : "entry") + " of vertex " +
                     std::to_string(bad) +
                     " is not positive (definite), so the system matrix is not positive definite on the free "
                     "DOFs (compressed elements without the Jacobian clamp, or a step too large for the "
                     "material); reduce integrator.dt, enable the material's Jacobian clamp, or set "
                     "integrator.on_solver_failure: halve_step";
    return false;
  }
  return true;
}

int EigenPcg::iterate(const BsrMatrix& A, const Filter& S, std::span<double> dv, double threshold2,
                      int max_iterations, int& status, double& curvature) {
  const BsrPattern& P = A.pattern();
  const Index n = n_;
  const Index* rp = P.row_ptr.data();
  const Index* col = P.col.data();
  const double* val = A.values().data();
  const double* pinv = pinv_.data();
  double* r = r_.data();
  double* c = c_.data();
  double* q = q_.data();
  double* s = s_.data();
  double* x = dv.data();
  Partial* part = partial_.data();
  const double rr0 = rr_;
  int it_out = 0, status_out = 1;
  double rr_out = rr0, curv_out = 0;

#pragma omp parallel if (n >= options_.parallel_min_rows)
  {
    const int t = omp_get_thread_num();
    const int nt = omp_get_num_threads();
    // s = P r, c = s, delta = r . s
    double loc = 0;
#pragma omp for schedule(static) nowait
    for (Index i = 0; i < n; ++i) {
      const std::size_t o = 3 * static_cast<std::size_t>(i);
      kernels::mat3_mul(pinv + 3 * o, r + o, s + o);
      c[o] = s[o];
      c[o + 1] = s[o + 1];
      c[o + 2] = s[o + 2];
      loc += kernels::dot3(r + o, s + o);
    }
    part[t].v[0] = loc;
#pragma omp barrier
    double delta = 0;
    for (int k = 0; k < nt; ++k) delta += part[k].v[0];
    double rr = rr0;
    int it = 0, st = 1;
    double curv = 0;
    for (;;) {
      if (rr <= threshold2) { st = 0; break; }
      if (it >= max_iterations) { st = 1; break; }
      if (!(delta > 0) || !std::isfinite(delta)) { st = 3; curv = delta; break; }
      // q = S (A c), cq = c . q
      loc = 0;
#pragma omp for schedule(static) nowait
      for (Index i = 0; i < n; ++i) {
        const std::size_t o = 3 * static_cast<std::size_t>(i);
        block_row_multiply3(rp, col, val, c, i, q + o);
        const int f = S.free_dofs(i);
        if (f != 3) kernels::filter_vec3(f, S.projector(i).data(), q + o);
        loc += kernels::dot3(c + o, q + o);
      }
      part[t].v[1] = loc;
#pragma omp barrier
      double cq = 0;
      for (int k = 0; k < nt; ++k) cq += part[k].v[1];
      if (!(cq > 0) || !std::isfinite(cq)) { st = 2; curv = cq; break; }
      const double alpha = delta / cq;
      double ld = 0, lr = 0;
#pragma omp for schedule(static) nowait
      for (Index i = 0; i < n; ++i) {
        const std::size_t o = 3 * static_cast<std::size_t>(i);
        for (int a = 0; a < 3; ++a) {
          x[o + a] += alpha * c[o + a];
          r[o + a] -= alpha * q[o + a];
        }
        kernels::mat3_mul(pinv + 3 * o, r + o, s + o);
        ld += kernels::dot3(r + o, s + o);
        lr += kernels::dot3(r + o, r + o);
      }
      part[t].v[2] = ld;
      part[t].v[3] = lr;
#pragma omp barrier
      double dnew = 0;
      rr = 0;
      for (int k = 0; k < nt; ++k) {
        dnew += part[k].v[2];
        rr += part[k].v[3];
      }
      const double beta = dnew / delta;
      delta = dnew;
#pragma omp for schedule(static)
      for (Index i = 0; i < n; ++i) {
        const std::size_t o = 3 * static_cast<std::size_t>(i);
        c[o] = s[o] + beta * c[o];
        c[o + 1] = s[o + 1] + beta * c[o + 1];
        c[o + 2] = s[o + 2] + beta * c[o + 2];
      }
      ++it;
    }
    if (t == 0) {
      it_out = it;
      status_out = st;
      rr_out = rr;
      curv_out = curv;
    }
  }
  rr_ = rr_out;
  status = status_out;
  curvature = curv_out;
  return it_out;
}

int EigenPcg::iterate_amg(const BsrMatrix& A, const Filter& S, std::span<double> dv, double threshold2,
                          int max_iterations, int& status, double& curvature) {
  const BsrPattern& P = A.pattern();
  const Index n = n_;
  const Index* rp = P.row_ptr.data();
  const Index* col = P.col.data();
  const double* val = A.values().data();
  double* r = r_.data();
  double* c = c_.data();
  double* q = q_.data();
  double* s = s_.data();
  double* x = dv.data();
  const bool par = n >= options_.parallel_min_rows;
  // s = S M r, returns r . s
  auto precondition = [&]() {
    amg_->apply(r, s);
    solver::filter(S, s_);
    double d = 0;
#pragma omp parallel for schedule(static) reduction(+ : d) if (par)
    for (Index i = 0; i < n; ++i) d += kernels::dot3(r + 3 * static_cast<std::size_t>(i), s + 3 * static_cast<std::size_t>(i));
    return d;
  };
  double delta = precondition();
  const std::size_t N = 3 * static_cast<std::size_t>(n);
  std::copy(s, s + N, c);
  double rr = rr_;
  int it = 0;
  status = 1;
  curvature = 0;
  for (;;) {
    if (rr <= threshold2) { status = 0; break; }
    if (it >= max_iterations) { status = 1; break; }
    if (!(delta > 0) || !std::isfinite(delta)) { status = 3; curvature = delta; break; }
    double cq = 0;
#pragma omp parallel for schedule(static) reduction(+ : cq) if (par)
    for (Index i = 0; i < n; ++i) {
      const std::size_t o = 3 * static_cast<std::size_t>(i);
      block_row_multiply3(rp, col, val, c, i, q + o);
      const int f = S.free_dofs(i);
      if (f != 3) kernels::filter_vec3(f, S.projector(i).data(), q + o);
      cq += kernels::dot3(c + o, q + o);
    }
    if (!(cq > 0) || !std::isfinite(cq)) { status = 2; curvature = cq; break; }
    const double alpha = delta / cq;
    double lr = 0;
#pragma omp parallel for schedule(static) reduction(+ : lr) if (par)
    for (Index i = 0; i < n; ++i) {
      const std::size_t o = 3 * static_cast<std::size_t>(i);
      for (int a = 0; a < 3; ++a) {
        x[o + a] += alpha * c[o + a];
        r[o + a] -= alpha * q[o + a];
      }
      lr += kernels::dot3(r + o, r + o);
    }
    rr = lr;
    const double dnew = precondition();
    const double beta = dnew / delta;
    delta = dnew;
#pragma omp parallel for schedule(static) if (par)
    for (std::size_t k = 0; k < N; ++k) c[k] = s[k] + beta * c[k];
    ++it;
  }
  rr_ = rr;
  return it;
}

SolveReport EigenPcg::solve(const BsrMatrix& A, const Filter& S, std::span<const double> b,
                            std::span<const double> z, std::span<double> dv) {
  const auto t0 = Clock::now();
  SolveReport rep;
  if (A.rows() != n_) analyze_pattern(A, S);
  const std::size_t N = 3 * static_cast<std::size_t>(n_);
  if (b.size() != N || z.size() != N || dv.size() != N)
    throw std::invalid_argument("eigen_pcg: vector sizes do not match the matrix");

  // b-hat = S (b - A z): what is left to solve once the prescribed part is in place.
  double bh2;
  if (solver::prescribed_is_zero(S, z)) {
    bh2 = 0;
    for (std::size_t k = 0; k < N; ++k) r_[k] = b[k];
    solver::filter(S, r_);
    for (std::size_t k = 0; k < N; ++k) bh2 += r_[k] * r_[k];
  } else {
    bh2 = solver::filtered_residual(A, S, b, z, r_);
  }
  const double bh = std::sqrt(bh2);
  if (!std::isfinite(bh)) {
    rep.message = "eigen_pcg: the right-hand side is not finite (NaN or Inf in the forces or the matrix)";
    rep.solve_seconds = seconds_since(t0);
    return rep;
  }

  // Ascher-Boxerman start: dv = S dv_guess + z.
  solver::apply_prescribed(S, z, dv);
  bool guess_nonzero = false;
  for (std::size_t k = 0; k < N && !guess_nonzero; ++k) guess_nonzero = dv[k] != z[k];
  if (bh2 == 0) {
    std::fill(dv.begin(), dv.end(), 0.0);
    solver::apply_prescribed(S, z, dv);
    rep.converged = true;
    rep.solve_seconds = seconds_since(t0);
    return rep;
  }
  rr_ = bh2;
  if (guess_nonzero) {
    const double rw = solver::filtered_residual(A, S, b, dv, q_);
    if (rw < bh2 && std::isfinite(rw)) {
      std::swap(r_, q_);
      rr_ = rw;
    } else {  // the warm start is worse than none: start from z
      std::fill(dv.begin(), dv.end(), 0.0);
      solver::apply_prescribed(S, z, dv);
    }
  }

  const double tol = options_.tolerance;
  const double threshold2 = tol * tol * bh2;
  int total = 0, status = 1;
  double curvature = 0, rel = 0;
  for (int attempt = 0; attempt < 3; ++attempt) {
    total += options_.preconditioner == PcgPreconditioner::SaAmg
                 ? iterate_amg(A, S, dv, threshold2, options_.max_iterations - total, status, curvature)
                 : iterate(A, S, dv, threshold2, options_.max_iterations - total, status, curvature);
    if (status != 0) break;
    // The recursive residual has converged; check the true one (and restart from it if
    // rounding let the two drift apart).
    const double tr2 = solver::filtered_residual(A, S, b, dv, q_);
    rel = std::sqrt(tr2) / bh;
    if (rel <= tol) break;
    std::swap(r_, q_);
    rr_ = tr2;
    status = 1;
  }
  if (status != 0) rel = std::sqrt(solver::filtered_residual(A, S, b, dv, q_)) / bh;
  rep.iterations = total;
  rep.residual = rel;
  rep.converged = status == 0 && rel <= tol;
  if (!rep.converged) {
    if (status == 2)
      rep.message = format(
          "eigen_pcg: non-positive curvature c^T A c = %.3g at iteration %.0f (relative residual %.3g): the "
          "system matrix is not positive definite on the free DOFs (compressed elements without the Jacobian "
          "clamp, or a step too large for the material); reduce integrator.dt, enable the material's Jacobian "
          "clamp, or set integrator.on_solver_failure: halve_step",
          curvature, total, rel);
    else if (status == 3)
      rep.message = format(
          "eigen_pcg: the preconditioned residual norm r^T P^-1 r = %.3g is not positive at iteration %.0f "
          "(relative residual %.3g): the preconditioner or the system is not positive definite",
          curvature, total, rel);
    else
      rep.message = format(
          "eigen_pcg: not converged in %.0f iterations (relative residual %.3g > tolerance %.3g); raise "
          "max_iterations, reduce integrator.dt, or use eigen_ldlt",
          total, rel, tol);
  }
  rep.solve_seconds = seconds_since(t0);
  return rep;
}

}  // namespace loom

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
#include "loom/filtered_pcg.hpp"
#include "loom/kernels/bsr_ops.hpp"
#include "loom/solver_common.hpp"

namespace loom {

namespace {
const char* precond_name(PcgPreconditioner p) {
  switch (p) {
    case PcgPreconditioner::None: return "none";
    case PcgPreconditioner::Jacobi: return "jacobi";
    case PcgPreconditioner::SaAmg: return "sa_amg";
    default: return "block_jacobi";
  }
}

}  // namespace

namespace {
ParamSpec make_pcg_spec(const char* name, const char* summary) {
    const PcgOptions d;
    const amg::SaAmgOptions m;
    ParamSpec s(name, summary);
    s.number("tolerance", d.tolerance).range(ParamRange::closed(1e-16, 0.5)).help(
        "true relative residual of the filtered system: |S(b - A dv)| <= tolerance |S(b - A z)|");
    s.integer("max_iterations", d.max_iterations).range(ParamRange::closed(1, 1e8)).help(
        "iterations before the solve counts as failed");
    s.choice("preconditioner", precond_name(d.preconditioner), {"none", "jacobi", "block_jacobi", "sa_amg"}).help(
        "sa_amg: smoothed-aggregation multigrid V-cycle (options under sa_amg)");
    s.choice("spmv_storage", d.float_spmv ? "float" : "double", {"double", "float"}).backends({"cpu"}).help(
        "precision of the copy of A read by the iteration's SpMV (vectors, sums, start and stopping rule stay double)");
    s.integer("parallel_min_rows", d.parallel_min_rows).range(ParamRange::closed(0, 1e9)).units("vertices").backends({"cpu"}).help(
        "loops run on all OpenMP threads from this many block rows on");
    ParamSpec a("sa_amg");
    a.choice("near_null_space", m.near_null_modes == 6 ? "rigid" : "translations", {"rigid", "translations"}).help(
        "rigid: translations and rotations (needs coordinates); translations: 3 modes");
    a.number("strength_threshold", m.strength_threshold).range(ParamRange::closed(0, 1)).help(
        "block (i,j) strong if |A_ij| > theta sqrt(|A_ii| |A_jj|)");
    a.integer("smoothing_sweeps", m.smoothing_sweeps).range(ParamRange::closed(1, 10)).help(
        "Gauss-Seidel sweeps before and after the coarse correction");
    a.integer("coarse_smoothing_sweeps", m.coarse_smoothing_sweeps).range(ParamRange::closed(0, 10)).help(
        "Gauss-Seidel sweeps on the levels below the finest (0 = smoothing_sweeps)");
    a.number("smoothing_relaxation", m.smoothing_relaxation).range(ParamRange{0.0, 2.0, true, true}).help(
        "SOR weight w of the Gauss-Seidel smoother, x_i += w D_i^-1 r_i (1: Gauss-Seidel; SPD for 0 < w < 2)");
    a.number("coarse_smoothing_relaxation", m.coarse_smoothing_relaxation).range(ParamRange{0.0, 2.0, false, true}).help(
        "SOR weight on the levels below the finest (0 = smoothing_relaxation)");
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
    a.number("coarse_drop_tolerance", m.coarse_drop_tolerance).range(ParamRange::closed(0, 10)).help(
        "drop coarse-level blocks with |L_I^-1 A_IJ L_J^-T|_F below this, scaling the diagonal blocks to stay SPD (0: off)");
    a.flag("huge_pages", m.huge_pages).help(
        "2 MiB-aligned hierarchy arrays advised as transparent huge pages (Linux madvise; same results, fewer TLB misses)");
    s.map("sa_amg", std::move(a)).backends({"cpu"}).help("options of preconditioner: sa_amg");
    return s;
}
}  // namespace

const ParamSpec& filtered_pcg_spec() {
  static const ParamSpec spec = make_pcg_spec(
      "filtered_pcg", "modified (filtered) PCG of Baraff-Witkin on the 3x3 block matrix, one loop for every backend");
  return spec;
}

const ParamSpec& pcg_spec() {
  static const ParamSpec spec = make_pcg_spec("eigen_pcg", "deprecated name of filtered_pcg (same keys and behaviour)");
  return spec;
}

PcgOptions parse_pcg_options(const Params& p, const ParamSpec& spec, const std::string& backend) {
  PcgOptions o;
  if (!p.valid()) return o;
  const ParamReader r(p, spec);
  o.tolerance = r.number("tolerance");
  o.max_iterations = r.int32("max_iterations");
  const std::string pc = r.text("preconditioner");
  // cpu only: a device backend leaves these keys unread, so check_unused names the backend
  // that honours them.
  if (backend != "cpu") {
    if (pc == "sa_amg")
      r.params().child("preconditioner").fail("preconditioner sa_amg runs on backend cpu only; on backend " + backend +
                                              " use none, jacobi or block_jacobi");
    o.preconditioner = pc == "none" ? PcgPreconditioner::None
                       : pc == "jacobi" ? PcgPreconditioner::Jacobi : PcgPreconditioner::BlockJacobi;
    return o;
  }
  o.parallel_min_rows = static_cast<Index>(r.integer("parallel_min_rows"));
  o.float_spmv = r.text("spmv_storage") == "float";
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
    m.coarse_smoothing_sweeps = a.int32("coarse_smoothing_sweeps");
    m.smoothing_relaxation = a.number("smoothing_relaxation");
    m.coarse_smoothing_relaxation = a.number("coarse_smoothing_relaxation");
    m.coarse_dofs = static_cast<Index>(a.integer("coarse_dofs"));
    m.max_levels = a.int32("max_levels");
    m.prolongator_refresh_steps = a.int32("prolongator_refresh_steps");
    m.hierarchy_refresh_steps = a.int32("hierarchy_refresh_steps");
    m.aggressive_levels = a.int32("aggressive_levels");
    m.float_storage = a.text("storage") == "float";
    m.prolongator_damping = a.number("prolongator_damping");
    m.coarse_drop_tolerance = a.number("coarse_drop_tolerance");
    m.huge_pages = a.flag("huge_pages");
    a.params().check_unused();
  }
  return o;
}

EigenPcg::EigenPcg(PcgOptions options, std::string name) : options_(options), name_(std::move(name)) {}

void EigenPcg::set_coordinates(std::span<const double> x) { coords_.assign(x.begin(), x.end()); }

void EigenPcg::set_extra_operator(const ExtraOperator* E) {
  extra_ = E;
  if (E) extra_seen_ = true;
}

void EigenPcg::analyze_pattern(const BsrMatrix& A, const Filter& S) {
  (void)S;
  if (amg_) amg_->invalidate();
  n_ = A.rows();
  const std::size_t N = 3 * static_cast<std::size_t>(n_);
  pinv_.assign(9 * static_cast<std::size_t>(n_), 0.0);
  diag_.assign(9 * static_cast<std::size_t>(n_), 0.0);
  r_.assign(N, 0.0);
  c_.assign(N, 0.0);
  q_.assign(N, 0.0);
  s_.assign(N, 0.0);
}

bool EigenPcg::factorize(const BsrMatrix& A, const Filter& S, SolveReport& report) {
  const auto t0 = Clock::now();
  if (A.rows() != n_) analyze_pattern(A, S);
  const BsrPattern& P = A.pattern();
  const Index n = n_;
  const PcgPreconditioner pc = options_.preconditioner;
  use_upper_ = false;
  if (options_.float_spmv) {
    float_copy_values(A.values(), af_, n >= options_.parallel_min_rows);
  } else if (options_.upper_triangle_spmv) {
    if (upper_pattern_ != &P || upper_nnz_ != P.nnz_blocks()) {  // a new pattern: allocates, once
      upper_.analyze(P);
      upper_pattern_ = &P;
      upper_nnz_ = P.nnz_blocks();
    }
    use_upper_ = upper_.symmetric_values(A, 1e-12, n >= options_.parallel_min_rows);
  }
  if (pc == PcgPreconditioner::SaAmg) {
    if (!amg_) amg_ = std::make_unique<amg::SaAmg>(options_.amg);
    std::span<const double> x;
    if (coords_.size() == 3 * static_cast<std::size_t>(n)) x = coords_;
    // With a matrix-free term E, its diagonal blocks join the hierarchy's level 0.
    std::span<const double> ed;
    if (extra_) {
      diag_.assign(9 * static_cast<std::size_t>(n), 0.0);
      extra_->add_diagonal(diag_.data());
      ed = diag_;
    }
    std::string msg;
    // Only E changed since the last set-up (the solves of one step that add and release
    // springs: same A, same S): level 0's diagonal follows E, the rest of the hierarchy stays.
    const std::vector<double>& av = A.values();
    const bool only_e = extra_ && amg_values_.size() == av.size() && amg_->set_up_for(A, S) &&
                        std::equal(av.begin(), av.end(), amg_values_.begin());
    bool ok;
    if (only_e) {
      ok = amg_->refresh_level0_diagonal(A, S, ed, msg);
    } else {
      ok = amg_->setup(A, S, x, msg, ed);
      if (ok && extra_seen_) amg_values_.assign(av.begin(), av.end());
      else amg_values_.clear();
    }
    report.factorize_seconds = seconds_since(t0);
    if (!ok) {
      report.converged = false;
      report.message = name_ + ": " + msg;
    }
    return ok;
  }
  // With a matrix-free term E, the preconditioner's diagonal blocks are those of A + E.
  const bool with_extra = extra_ && pc != PcgPreconditioner::None;
  if (with_extra) {
    if (diag_.size() != 9 * static_cast<std::size_t>(n)) diag_.assign(9 * static_cast<std::size_t>(n), 0.0);
#pragma omp parallel for schedule(static) if (n >= solver::kParallelMinRows)
    for (Index i = 0; i < n; ++i) std::copy_n(A.block(P.diag[i]), 9, diag_.data() + 9 * static_cast<std::size_t>(i));
    extra_->add_diagonal(diag_.data());
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
    const double* D = with_extra ? diag_.data() + 9 * static_cast<std::size_t>(i) : A.block(P.diag[i]);
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
    report.message = name_ + ": the " + std::string(precond_name(pc)) + " preconditioner's diagonal " +
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

namespace {

// The CPU operations of the filtered PCG (loom/filtered_pcg.hpp): OpenMP loops over block
// rows (serial below parallel_min_rows rows), the preconditioner either the stored blocks
// S_i M_i^-1 S_i or the multigrid V-cycle followed by the filter.
struct CpuPcgOps {
  using Real = double;
  using Vec = std::span<double>;
  const BsrMatrix& A;
  const Filter& S;
  std::span<const double> b, z;
  const double* pinv;   // 9 per vertex (null with amg)
  amg::SaAmg* amg;      // the V-cycle (null without)
  const UpperTriangleSpmv* upper;  // the SpMV from the upper triangle (null: full rows)
  const float* af;      // the SpMV from A's values in float (null: double)
  const ExtraOperator* extra;  // the matrix-free term E (null: none): the operator is A + E
  bool par;
  Index n;

  double residual(const Vec& x, Vec& out) const {
    const BsrPattern& P = A.pattern();
    const Index* rp = P.row_ptr.data();
    const Index* col = P.col.data();
    const double* val = A.values().data();
    const double* xp = x.data();
    double* o = out.data();
    const double* bp = b.data();
    double sum = 0;
    if (extra) {  // out = b - A x - E x, then the filter
#pragma omp parallel for schedule(static) if (par)
      for (Index i = 0; i < n; ++i) {
        const std::size_t k = 3 * static_cast<std::size_t>(i);
        double ax[3];
        kernels::bsr_row_multiply(rp, col, val, xp, i, ax);
        for (int a = 0; a < 3; ++a) o[k + a] = bp[k + a] - ax[a];
      }
      extra->apply_add(xp, o, -1.0);
#pragma omp parallel for schedule(static) reduction(+ : sum) if (par)
      for (Index i = 0; i < n; ++i) {
        const std::size_t k = 3 * static_cast<std::size_t>(i);
        solver::filter_vertex(S, i, o + k);
        sum += kernels::dot3(o + k, o + k);
      }
      return sum;
    }
#pragma omp parallel for schedule(static) reduction(+ : sum) if (par)
    for (Index i = 0; i < n; ++i) {
      const std::size_t k = 3 * static_cast<std::size_t>(i);
      double ax[3];  // the shared kernel, as solver::filtered_residual (b = A z gives exactly 0)
      kernels::bsr_row_multiply(rp, col, val, xp, i, ax);
      for (int a = 0; a < 3; ++a) o[k + a] = bp[k + a] - ax[a];
      solver::filter_vertex(S, i, o + k);
      sum += kernels::dot3(o + k, o + k);
    }
    return sum;
  }
  double apply_operator(const Vec& c, Vec& q) const {
    const BsrPattern& P = A.pattern();
    const Index* rp = P.row_ptr.data();
    const Index* col = P.col.data();
    const double* val = A.values().data();
    const double* cp = c.data();
    double* qp = q.data();
    double cq = 0;
    // Row i of A c (float copy, upper triangle or full rows), then filtered and dotted with c.
    auto row_product = [&](Index i, double* out) {
      if (af)
        block_row_multiply3(rp, col, af, cp, i, out);
      else if (upper)
        upper->row(A, cp, i, out);
      else
        block_row_multiply3(rp, col, val, cp, i, out);
    };
    auto filter_dot = [&](Index i, double* out) {
      const int f = S.free_dofs(i);
      if (f != 3) kernels::filter_vec3(f, S.projector(i).data(), out);
      return kernels::dot3(cp + 3 * static_cast<std::size_t>(i), out);
    };
    if (extra) {  // q = A c + E c, then the filter
#pragma omp parallel for schedule(static) if (par)
      for (Index i = 0; i < n; ++i) row_product(i, qp + 3 * static_cast<std::size_t>(i));
      extra->apply_add(cp, qp, 1.0);
#pragma omp parallel for schedule(static) reduction(+ : cq) if (par)
      for (Index i = 0; i < n; ++i) cq += filter_dot(i, qp + 3 * static_cast<std::size_t>(i));
      return cq;
    }
#pragma omp parallel for schedule(static) reduction(+ : cq) if (par)
    for (Index i = 0; i < n; ++i) {
      double* out = qp + 3 * static_cast<std::size_t>(i);
      row_product(i, out);
      cq += filter_dot(i, out);
    }
    return cq;
  }
  double precondition(const Vec& r, Vec& s) const {
    const double* rp = r.data();
    double* sp = s.data();
    double d = 0;
    if (amg) {
      amg->apply(rp, sp);
      solver::filter(S, s);
#pragma omp parallel for schedule(static) reduction(+ : d) if (par)
      for (Index i = 0; i < n; ++i) d += kernels::dot3(rp + 3 * static_cast<std::size_t>(i), sp + 3 * static_cast<std::size_t>(i));
      return d;
    }
#pragma omp parallel for schedule(static) reduction(+ : d) if (par)
    for (Index i = 0; i < n; ++i) {
      const std::size_t o = 3 * static_cast<std::size_t>(i);
      kernels::mat3_mul(pinv + 3 * o, rp + o, sp + o);
      d += kernels::dot3(rp + o, sp + o);
    }
    return d;
  }
  double update(double alpha, const Vec& c, const Vec& q, Vec& x, Vec& r) const {
    const double* cp = c.data();
    const double* qp = q.data();
    double* xp = x.data();
    double* rp = r.data();
    double rr = 0;
#pragma omp parallel for schedule(static) reduction(+ : rr) if (par)
    for (Index i = 0; i < n; ++i) {
      const std::size_t o = 3 * static_cast<std::size_t>(i);
      for (int a = 0; a < 3; ++a) {
        xp[o + a] += alpha * cp[o + a];
        rp[o + a] -= alpha * qp[o + a];
      }
      rr += kernels::dot3(rp + o, rp + o);
    }
    return rr;
  }
  void xpby(const Vec& s, double beta, Vec& c) const {
    const double* sp = s.data();
    double* cp = c.data();
    const std::size_t N = 3 * static_cast<std::size_t>(n);
#pragma omp parallel for schedule(static) if (par)
    for (std::size_t k = 0; k < N; ++k) cp[k] = sp[k] + beta * cp[k];
  }
  void start(Vec& dv) const { solver::apply_prescribed(S, z, dv); }
  void assign_prescribed(Vec& dv) const {
    std::fill(dv.begin(), dv.end(), 0.0);
    solver::apply_prescribed(S, z, dv);
  }
  void copy(const Vec& a, Vec& b2) const { std::copy(a.begin(), a.end(), b2.begin()); }
};
static_assert(pcg::FilteredPcgOps<CpuPcgOps>);

}  // namespace

SolveReport EigenPcg::solve(const BsrMatrix& A, const Filter& S, std::span<const double> b,
                            std::span<const double> z, std::span<double> dv) {
  const auto t0 = Clock::now();
  if (A.rows() != n_) analyze_pattern(A, S);
  const std::size_t N = 3 * static_cast<std::size_t>(n_);
  if (b.size() != N || z.size() != N || dv.size() != N)
    throw std::invalid_argument(name_ + ": vector sizes do not match the matrix");
  const bool use_amg = options_.preconditioner == PcgPreconditioner::SaAmg;
  const bool use_float = options_.float_spmv && af_.size() == A.values().size() + 4;
  CpuPcgOps ops{A, S, b, z, pinv_.data(), use_amg ? amg_.get() : nullptr, use_upper_ ? &upper_ : nullptr,
                use_float ? af_.data() : nullptr, extra_, n_ >= options_.parallel_min_rows, n_};
  pcg::Settings set;
  set.tolerance = std::min(0.5, options_.tolerance * tolerance_scale_);
  set.max_iterations = options_.max_iterations;
  set.name = name_.c_str();
  std::span<double> r(r_), c(c_), q(q_), s(s_);
  SolveReport rep = pcg::solve(ops, set, dv, r, c, q, s);
  rep.solve_seconds = seconds_since(t0);
  return rep;
}

}  // namespace loom

#include "cholmod_solver.hpp"

#include <dlfcn.h>
#include <omp.h>

#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <stdexcept>

#include <cholmod.h>

#include "loom/clock.hpp"
#include "loom/factor_pcg.hpp"
#include "loom/param_fields.hpp"
#include "loom/solver_common.hpp"

extern "C" {
// OpenBLAS extensions (the plugin links libopenblas directly, see CMakeLists.txt).
void openblas_set_num_threads(int);
int openblas_get_num_threads(void);
char* openblas_get_config(void);
void dgemm_(const char*, const char*, const int*, const int*, const int*, const double*, const double*,
            const int*, const double*, const int*, const double*, double*, const int*);
}

namespace loom {

namespace {


// Vector loops below this length run on one thread: a parallel region costs more than it
// saves, and far more when the machine is oversubscribed (a descheduled thread stalls the
// barrier for a time slice).
constexpr long kParallelMinDofs = 16384;

double dot(const double* a, const double* b, long n) {
  double s = 0;
#pragma omp parallel for reduction(+ : s) schedule(static) if (n >= kParallelMinDofs)
  for (long i = 0; i < n; ++i) s += a[i] * b[i];
  return s;
}

const char* ordering_name(int o) {
  switch (o) {
    case CHOLMOD_NATURAL: return "natural";
    case CHOLMOD_GIVEN: return "given";
    case CHOLMOD_AMD: return "amd";
    case CHOLMOD_METIS: return "metis";
    case CHOLMOD_NESDIS: return "nesdis";
    case CHOLMOD_COLAMD: return "colamd";
    case CHOLMOD_POSTORDERED: return "postordered";
    default: return "unknown";
  }
}

// Below this many vertices the supernodes are small and a second BLAS thread costs more in
// wake-ups than it saves (measured: the 32 x 32 wool scene, 5 frames of Baraff-Witkin with
// cholmod, took 0.22 s with 1 BLAS thread and 2.2 s with 2).
constexpr Index kBlasThreadedMinVertices = 10000;

void apply_blas_threads(int requested, Index vertices) {
  int n = requested;
  if (n <= 0) {
    if (std::getenv("OPENBLAS_NUM_THREADS") || std::getenv("GOTO_NUM_THREADS")) return;  // user's choice
    n = vertices < kBlasThreadedMinVertices ? 1 : omp_get_max_threads();
  }
  openblas_set_num_threads(n);
}

// CHOLMOD (SuiteSparse 5.x) opens OpenMP regions with num_threads(CHOLMOD_OMP_NUM_THREADS), 4
// by default, in its supernodal factorisation, whatever omp_set_num_threads says: `threads: 1`
// ran a 4-thread team per supernode (measured on ground_plane, 8 steps: 42,000 context
// switches and 0.53 s of CPU against 90 and 0.26 s with the team capped at 1). While a CHOLMOD
// call runs, its teams are capped at the run's count: on 1 thread no region is active
// (max-active-levels 0); on more, dynamic teams (libgomp then gives at most the run's count and
// the online CPUs, less the 15-minute load average, at least 1). Restored after the call.
class TeamCap {
 public:
  TeamCap() : levels_(omp_get_max_active_levels()), dynamic_(omp_get_dynamic()) {
    if (omp_get_max_threads() <= 1) omp_set_max_active_levels(0);
    else omp_set_dynamic(1);
  }
  ~TeamCap() {
    omp_set_max_active_levels(levels_);
    omp_set_dynamic(dynamic_);
  }
  TeamCap(const TeamCap&) = delete;
  TeamCap& operator=(const TeamCap&) = delete;

 private:
  int levels_, dynamic_;
};

}  // namespace

namespace {

// The keys of cholmod, each bound to its CholmodOptions member (loom/param_fields.hpp).
const ParamFields<CholmodOptions>& cholmod_fields() {
  static const ParamFields<CholmodOptions> fields = [] {
    using O = CholmodOptions;
    ParamFields<O> f("cholmod", "SuiteSparse CHOLMOD Cholesky of the projected system");
    f.number("tolerance", &O::tolerance).range(ParamRange::positive()).help(
        "relative residual |S(b - A dv)| / |S(b - A z)| a solve with a reused factor must reach");
    f.integer("reuse_factorization_steps", &O::reuse_factorization_steps).range(ParamRange::closed(1, 1e6))
        .units("steps").help("refactor every N steps (1 = every step); in between PCG with the old factor");
    f.integer("max_iterations", &O::max_iterations).range(ParamRange::closed(0, 100000)).help(
        "PCG iterations with a stale factor before refactoring");
    f.choice("ordering", &O::ordering, {"auto", "amd", "metis", "nesdis", "natural"}).help("fill-reducing ordering");
    f.choice("factorization", &O::factorization, {"supernodal", "simplicial", "auto"}).help("CHOLMOD factorization kind");
    f.integer("blas_threads", &O::blas_threads).range(ParamRange::closed(0, 1024)).units("threads").help(
        "OpenBLAS threads (0: $OPENBLAS_NUM_THREADS if set, else 1 below 10000 vertices and the OpenMP count above)");
    f.choice("contact_springs", &O::contact_springs, {factor_pcg::kAssembled, factor_pcg::kFactorPreconditionedPcg})
        .help("assembled: self-contact springs assembled into A (the pattern grows, each solve refactors); "
              "factor_preconditioned_pcg: A alone factored, A + springs solved by PCG with that factor "
              "(docs/CONTACT.md)");
    f.number("contact_tolerance", &O::contact_tolerance).range(ParamRange::closed(1e-15, 1e-2)).help(
        "factor_preconditioned_pcg: true relative residual |S(b - (A + E) dv)| / |S(b - (A + E) z)| to reach");
    f.integer("contact_max_iterations", &O::contact_max_iterations).range(ParamRange::closed(1, 100000)).help(
        "factor_preconditioned_pcg: PCG iterations before the solve fails (then reduce dt or use assembled)");
    return f;
  }();
  return fields;
}

}  // namespace

const ParamSpec& CholmodOptions::spec() { return cholmod_fields().spec(); }

CholmodOptions CholmodOptions::from_params(const Params& p) { return cholmod_fields().read(p); }

struct CholmodSolver::Impl {
  CholmodOptions opt;
  cholmod_common c{};
  cholmod_sparse* Acsc = nullptr;    // upper triangle of A~ (stype = 1), scalar 3n x 3n
  cholmod_factor* L = nullptr;
  cholmod_dense* X = nullptr;        // solve2 workspaces, reused
  cholmod_dense* Y = nullptr;
  cholmod_dense* E = nullptr;

  const BsrPattern* pattern = nullptr;
  Index n = 0;
  long N = 0;
  std::vector<long> src;             // CSC entry -> index into proj.values()
  BsrMatrix proj;                    // A~ (full, both triangles) for residuals
  std::vector<Index> cons_list;      // constrained vertices of the last factorize
  std::vector<double> cons_S;        // their projectors (9 each), to detect a change of S
  std::vector<double> bhat, y, r, p, q, s;

  bool have_factor = false;
  bool have_values = false;
  bool factor_pcg = false;              // contact_springs: factor_preconditioned_pcg
  const ExtraOperator* extra = nullptr;
  std::vector<double> factored;         // Acsc's values of the factor (factor_pcg: skip a refactor)
  std::vector<double> c2;               // the PCG's fourth work vector
  int since_factor = 0;
  int numeric_count = 0;
  double analyze_seconds = 0;
  bool analyze_reported = false;

  explicit Impl(const CholmodOptions& o) : opt(o) {
    factor_pcg = opt.contact_springs == factor_pcg::kFactorPreconditionedPcg;
    cholmod_l_start(&c);
    c.print = 0;                 // no printing; statuses are turned into messages here
    c.error_handler = nullptr;
    c.quick_return_if_not_posdef = 1;
    if (opt.factorization == "supernodal") c.supernodal = CHOLMOD_SUPERNODAL;
    else if (opt.factorization == "simplicial") c.supernodal = CHOLMOD_SIMPLICIAL;
    else c.supernodal = CHOLMOD_AUTO;
    if (opt.ordering != "auto") {
      c.nmethods = 1;
      c.method[0].ordering = opt.ordering == "amd"      ? CHOLMOD_AMD
                             : opt.ordering == "metis"  ? CHOLMOD_METIS
                             : opt.ordering == "nesdis" ? CHOLMOD_NESDIS
                                                        : CHOLMOD_NATURAL;
      c.postorder = opt.ordering != "natural";
    }
    apply_blas_threads(opt.blas_threads, kBlasThreadedMinVertices);
  }
  ~Impl() {
    free_numeric();
    cholmod_l_finish(&c);
  }
  void free_numeric() {
    if (L) cholmod_l_free_factor(&L, &c);
    if (Acsc) cholmod_l_free_sparse(&Acsc, &c);
    if (X) cholmod_l_free_dense(&X, &c);
    if (Y) cholmod_l_free_dense(&Y, &c);
    if (E) cholmod_l_free_dense(&E, &c);
    have_factor = false;
    have_values = false;
  }

  /// x <- L^{-1} rhs (the factor's solve), using reusable workspaces.
  bool factor_solve(const double* rhs, double* x) {
    cholmod_dense B{};
    B.nrow = static_cast<size_t>(N);
    B.ncol = 1;
    B.nzmax = static_cast<size_t>(N);
    B.d = static_cast<size_t>(N);
    B.x = const_cast<double*>(rhs);
    B.z = nullptr;
    B.xtype = CHOLMOD_REAL;
    B.dtype = CHOLMOD_DOUBLE;
    {
      const TeamCap cap;
      if (!cholmod_l_solve2(CHOLMOD_A, L, &B, nullptr, &X, nullptr, &Y, &E, &c)) return false;
    }
    const double* xs = static_cast<const double*>(X->x);
    const long NN = N;
#pragma omp parallel for schedule(static) if (NN >= kParallelMinDofs)
    for (long i = 0; i < NN; ++i) x[i] = xs[i];
    return true;
  }

  /// Numeric factorisation of the current Acsc. On failure fills msg.
  bool numeric(std::string& msg) {
    {
      const TeamCap cap;
      cholmod_l_factorize(Acsc, L, &c);
    }
    ++numeric_count;
    since_factor = 0;
    if (c.status == CHOLMOD_NOT_POSDEF || (L->minor < L->n)) {
      have_factor = false;
      const long k = static_cast<long>(L->minor);
      long orig = k;
      if (L->Perm && k < static_cast<long>(L->n)) orig = static_cast<const SuiteSparse_long*>(L->Perm)[k];
      char buf[512];
      std::snprintf(buf, sizeof buf,
                    "cholmod: the matrix is not positive definite on range(S): the Cholesky pivot failed "
                    "at column %ld of %ld (vertex %ld, component %ld; CHOLMOD status %d, minor %ld). "
                    "Clamp compressed springs in the Jacobian (NUMERICS.md 3.5) or reduce dt.",
                    k, static_cast<long>(L->n), orig / 3, orig % 3, c.status, k);
      msg = buf;
      return false;
    }
    if (c.status < CHOLMOD_OK) {
      have_factor = false;
      msg = "cholmod: numeric factorisation failed (CHOLMOD status " + std::to_string(c.status) +
            (c.status == CHOLMOD_OUT_OF_MEMORY ? ", out of memory)" : ")");
      return false;
    }
    have_factor = true;
    if (!X) {  // the first solve2 allocates its workspaces: do it now, so that solve() never does
      std::fill(s.begin(), s.end(), 0.0);
      factor_solve(s.data(), q.data());
    }
    return true;
  }
};

CholmodSolver::CholmodSolver(const CholmodOptions& options) : impl_(std::make_unique<Impl>(options)) {}
CholmodSolver::~CholmodSolver() = default;

bool CholmodSolver::supports_extra_operator() const { return impl_->factor_pcg; }
void CholmodSolver::set_extra_operator(const ExtraOperator* E) { impl_->extra = impl_->factor_pcg ? E : nullptr; }

int CholmodSolver::numeric_factorizations() const { return impl_->numeric_count; }
std::string CholmodSolver::ordering_used() const {
  return impl_->L ? ordering_name(impl_->L->ordering) : "none";
}
bool CholmodSolver::is_supernodal() const { return impl_->L && impl_->L->is_super; }
double CholmodSolver::factor_nnz() const { return impl_->c.lnz; }
double CholmodSolver::factor_flops() const { return impl_->c.fl; }

void CholmodSolver::analyze_pattern(const BsrMatrix& A, const Filter& S) {
  (void)S;
  Impl& m = *impl_;
  const auto t0 = Clock::now();
  m.free_numeric();
  apply_blas_threads(m.opt.blas_threads, A.rows());
  const BsrPattern& P = A.pattern();
  m.pattern = &P;
  m.n = P.n;
  m.N = 3L * P.n;
  const long N = m.N;

  // Upper triangle of the scalar matrix, column by column: scalar column J = 3 bj + c holds
  // rows I = 3 bi + r <= J of the blocks (bi, bj), bi <= bj, i.e. the lower part of block row bj.
  std::vector<long> colptr(N + 1, 0);
  for (Index bj = 0; bj < P.n; ++bj) {
    for (Index k = P.row_ptr[bj]; k < P.row_ptr[bj + 1]; ++k) {
      const Index bi = P.col[k];
      if (bi > bj) break;
      for (int cc = 0; cc < 3; ++cc) colptr[3L * bj + cc + 1] += (bi < bj) ? 3 : cc + 1;
    }
  }
  for (long J = 0; J < N; ++J) colptr[J + 1] += colptr[J];
  const long nnz = colptr[N];
  m.Acsc = cholmod_l_allocate_sparse(N, N, nnz, /*sorted*/ 1, /*packed*/ 1, /*stype*/ 1, CHOLMOD_REAL, &m.c);
  if (!m.Acsc) throw SolverError("cholmod: out of memory allocating the " + std::to_string(N) + "^2 matrix");
  auto* Ap = static_cast<SuiteSparse_long*>(m.Acsc->p);
  auto* Ai = static_cast<SuiteSparse_long*>(m.Acsc->i);
  auto* Ax = static_cast<double*>(m.Acsc->x);
  m.src.assign(nnz, 0);
  for (long J = 0; J <= N; ++J) Ap[J] = colptr[J];
  for (Index bj = 0; bj < P.n; ++bj) {
    long pos[3] = {colptr[3L * bj], colptr[3L * bj + 1], colptr[3L * bj + 2]};
    for (Index k = P.row_ptr[bj]; k < P.row_ptr[bj + 1]; ++k) {
      const Index bi = P.col[k];
      if (bi > bj) break;
      const Index kt = P.find(bi, bj);  // block (bi, bj)
      if (kt < 0) throw SolverError("cholmod: the block pattern is not symmetric (block (" + std::to_string(bj) + ", " +
                                    std::to_string(bi) + ") has no transpose)");
      for (int cc = 0; cc < 3; ++cc)
        for (int r = 0; r < 3; ++r) {
          if (bi == bj && r > cc) continue;
          Ai[pos[cc]] = 3L * bi + r;
          Ax[pos[cc]] = 0.0;
          m.src[pos[cc]] = 9L * kt + 3 * r + cc;
          ++pos[cc];
        }
    }
  }
  {
    const TeamCap cap;
    m.L = cholmod_l_analyze(m.Acsc, &m.c);
  }
  if (!m.L) throw SolverError("cholmod: symbolic analysis failed (CHOLMOD status " + std::to_string(m.c.status) + ")");

  m.proj = BsrMatrix(&P);
  m.cons_list.clear();
  m.cons_S.clear();
  for (auto* v : {&m.bhat, &m.y, &m.r, &m.p, &m.q, &m.s}) v->assign(N, 0.0);
  if (m.factor_pcg) {
    m.c2.assign(N, 0.0);
    m.factored.assign(nnz, 0.0);
  }
  m.since_factor = 0;
  m.have_factor = false;
  m.analyze_seconds = seconds_since(t0);
  m.analyze_reported = false;
}

bool CholmodSolver::factorize(const BsrMatrix& A, const Filter& S, SolveReport& report) {
  Impl& m = *impl_;
  const auto t0 = Clock::now();
  if (!A.has_pattern()) throw SolverError("cholmod: factorize called with a matrix without pattern");
  if (m.pattern != &A.pattern() || m.n != A.rows() || !m.Acsc) analyze_pattern(A, S);
  if (S.size() != m.n)
    throw SolverError("cholmod: the filter has " + std::to_string(S.size()) + " vertices, the matrix " +
                      std::to_string(m.n));
  const BsrPattern& P = *m.pattern;
  if (!m.analyze_reported) {
    report.analyze_seconds = m.analyze_seconds;
    m.analyze_reported = true;
  }

  // Constrained flags; detect a change of S (forces a refactorisation).
  bool s_changed = S.constrained() != m.cons_list;
  if (!s_changed) {
    for (std::size_t t = 0; t < m.cons_list.size() && !s_changed; ++t) {
      const auto& Si = S.projector(m.cons_list[t]);
      for (int e = 0; e < 9; ++e)
        if (Si[e] != m.cons_S[9 * t + e]) { s_changed = true; break; }
    }
  }
  if (s_changed) {
    m.cons_list = S.constrained();
    m.cons_S.resize(9 * m.cons_list.size());
    for (std::size_t t = 0; t < m.cons_list.size(); ++t) {
      const auto& Si = S.projector(m.cons_list[t]);
      for (int e = 0; e < 9; ++e) m.cons_S[9 * t + e] = Si[e];
    }
  }

  // A~ = S A S + (I - S), checking that every value is finite and the diagonal positive.
  const Index n = m.n;
  const Index* rp = P.row_ptr.data();
  const Index* cl = P.col.data();
  const Index* dg = P.diag.data();
  const double* Av = A.values().data();
  double* Pv = m.proj.values().data();
  long bad = -1;  // first DOF with a non-positive or non-finite diagonal entry
  bool nonfinite = false;
#pragma omp parallel for schedule(static) reduction(max : bad) reduction(|| : nonfinite) if (n >= solver::kParallelMinRows)
  for (Index i = 0; i < n; ++i) {
    for (Index k = rp[i]; k < rp[i + 1]; ++k) solver::projected_block(S, i, cl[k], Av + 9L * k, Pv + 9L * k);
    for (long e = 9L * rp[i]; e < 9L * rp[i + 1]; ++e)
      if (!std::isfinite(Pv[e])) nonfinite = true;
    const double* D = Pv + 9L * dg[i];
    for (int r = 0; r < 3; ++r)
      if (!(D[4 * r] > 0.0)) bad = std::max(bad, 3L * i + r);
  }
  m.have_values = false;
  if (nonfinite || bad >= 0) {
    m.have_factor = false;
    if (nonfinite) {
      report.message = "cholmod: the matrix has NaN or Inf entries (the Jacobian or the step blew up)";
    } else {
      char buf[400];
      std::snprintf(buf, sizeof buf,
                    "cholmod: the matrix is not positive definite on range(S): diagonal entry %.6g at "
                    "vertex %ld, component %ld is not positive. Clamp compressed springs in the Jacobian "
                    "(NUMERICS.md 3.5) or reduce dt.",
                    Pv[9L * dg[bad / 3] + 4 * (bad % 3)], bad / 3, bad % 3);
      report.message = buf;
    }
    report.factorize_seconds = seconds_since(t0);
    return false;
  }

  // Scatter into the CSC upper triangle.
  auto* Ax = static_cast<double*>(m.Acsc->x);
  const long* src = m.src.data();
  const long nnz = static_cast<long>(m.src.size());
#pragma omp parallel for schedule(static) if (nnz >= kParallelMinDofs)
  for (long e = 0; e < nnz; ++e) Ax[e] = Pv[src[e]];
  m.have_values = true;

  if (m.factor_pcg && m.have_factor && !s_changed &&
      std::equal(Ax, Ax + nnz, m.factored.begin())) {  // only E changed: the factor of A~ stands
    report.factorize_seconds = seconds_since(t0);
    return true;
  }
  bool ok = true;
  const bool refactor = !m.have_factor || s_changed || m.since_factor + 1 >= m.opt.reuse_factorization_steps ||
                        m.opt.reuse_factorization_steps <= 1;
  if (refactor) {
    ok = m.numeric(report.message);
    if (ok && m.factor_pcg) std::copy_n(Ax, nnz, m.factored.begin());
  } else {
    ++m.since_factor;
  }
  report.factorize_seconds = seconds_since(t0);
  return ok;
}

SolveReport CholmodSolver::solve(const BsrMatrix& A, const Filter& S, std::span<const double> b,
                                 std::span<const double> z, std::span<double> dv) {
  Impl& m = *impl_;
  SolveReport rep;
  const auto t0 = Clock::now();
  const long N = m.N;
  if (!m.have_values || !m.have_factor) {
    rep.message = "cholmod: solve() without a successful factorize()";
    return rep;
  }
  if (static_cast<long>(b.size()) != N || static_cast<long>(z.size()) != N || static_cast<long>(dv.size()) != N)
    throw SolverError("cholmod: vector sizes differ from 3 x " + std::to_string(m.n));
  if (m.extra) {  // A + E by PCG with A~'s factor as preconditioner
    auto factor = [&m](const double* r, double* s) { return m.factor_solve(r, s); };
    rep = factor_pcg::solve(name(), A, S, b, z, m.extra, factor, m.opt.contact_tolerance,
                            m.opt.contact_max_iterations, dv, m.r, m.c2, m.q, m.s);
    rep.solve_seconds = seconds_since(t0);
    return rep;
  }
  // b^ = S (b - A z)  (z = (I - S) z by the interface's contract)
  double* bh = m.bhat.data();
  double norm0;
  if (solver::prescribed_is_zero(S, z)) {
    const double* bp = b.data();
#pragma omp parallel for schedule(static) if (N >= kParallelMinDofs)
    for (long i = 0; i < N; ++i) bh[i] = bp[i];
    solver::filter(S, m.bhat);
    norm0 = std::sqrt(dot(bh, bh, N));
  } else {
    norm0 = std::sqrt(solver::filtered_residual(A, S, b, z, m.bhat));
  }

  double* y = m.y.data();
  double* r = m.r.data();
  double rel = 0.0;
  int iterations = 0;
  if (norm0 == 0.0) {
#pragma omp parallel for schedule(static) if (N >= kParallelMinDofs)
    for (long i = 0; i < N; ++i) y[i] = 0.0;
    rep.converged = true;
  } else {
    auto residual = [&]() {  // r = b^ - A~ y, returns |r| / |b^|
      solver::multiply(m.proj, m.y, m.r);
#pragma omp parallel for schedule(static) if (N >= kParallelMinDofs)
      for (long i = 0; i < N; ++i) r[i] = bh[i] - r[i];
      return std::sqrt(dot(r, r, N)) / norm0;
    };
    for (int attempt = 0; attempt < 2; ++attempt) {
      if (!m.factor_solve(bh, y)) {
        rep.message = "cholmod: triangular solve failed (CHOLMOD status " + std::to_string(m.c.status) + ")";
        rep.solve_seconds = seconds_since(t0);
        return rep;
      }
      iterations += 1;
      rel = residual();
      // PCG on A~ preconditioned by the (possibly stale) factor, from the direct solution.
      double* p = m.p.data();
      double* q = m.q.data();
      double* s = m.s.data();
      int it = 0;
      bool indefinite = false;
      if (rel > m.opt.tolerance && m.opt.max_iterations > 0) {
        m.factor_solve(r, s);
        double rs = dot(r, s, N);
#pragma omp parallel for schedule(static) if (N >= kParallelMinDofs)
        for (long i = 0; i < N; ++i) p[i] = s[i];
        while (it < m.opt.max_iterations) {
          solver::multiply(m.proj, m.p, m.q);
          const double pq = dot(p, q, N);
          if (!(pq > 0.0)) { indefinite = true; break; }
          const double alpha = rs / pq;
#pragma omp parallel for schedule(static) if (N >= kParallelMinDofs)
          for (long i = 0; i < N; ++i) {
            y[i] += alpha * p[i];
            r[i] -= alpha * q[i];
          }
          ++it;
          rel = std::sqrt(dot(r, r, N)) / norm0;
          if (rel <= m.opt.tolerance) break;
          m.factor_solve(r, s);
          const double rs_new = dot(r, s, N);
          const double beta = rs_new / rs;
          rs = rs_new;
#pragma omp parallel for schedule(static) if (N >= kParallelMinDofs)
          for (long i = 0; i < N; ++i) p[i] = s[i] + beta * p[i];
        }
        iterations += it;
        rel = residual();  // the true residual, not the recurrence
      }
      if (rel <= m.opt.tolerance) {
        rep.converged = true;
        break;
      }
      if (m.since_factor > 0 && attempt == 0) {  // stale factor not good enough: refactor, retry
        if (!m.numeric(rep.message)) {
          rep.solve_seconds = seconds_since(t0);
          return rep;
        }
        continue;
      }
      char buf[400];
      std::snprintf(buf, sizeof buf,
                    "cholmod: relative residual %.3g exceeds the tolerance %.3g after %d refinement "
                    "iterations%s (cholmod factors the upper triangle: is A symmetric?)",
                    rel, m.opt.tolerance, it, indefinite ? " (negative curvature: A~ is not SPD)" : "");
      rep.message = buf;
      break;
    }
  }

  // dv = S y + z: exact on the constrained vertices.
  double* d = dv.data();
#pragma omp parallel for schedule(static) if (N >= kParallelMinDofs)
  for (long i = 0; i < N; ++i) d[i] = y[i];
  solver::apply_prescribed(S, z, dv);
  rep.iterations = iterations;
  rep.residual = rel;
  rep.solve_seconds = seconds_since(t0);
  return rep;
}

std::string cholmod_blas_library() {
  Dl_info info{};
  void* addr = reinterpret_cast<void*>(&dgemm_);
  if (dladdr(addr, &info) && info.dli_fname) return info.dli_fname;
  return "unknown";
}

std::string cholmod_openblas_config() {
  const char* cfg = openblas_get_config();
  return cfg ? cfg : "";
}

int cholmod_blas_threads() { return openblas_get_num_threads(); }

}  // namespace loom

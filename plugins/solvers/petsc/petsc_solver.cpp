#include "petsc_solver.hpp"

#include <dlfcn.h>
#include <petscksp.h>

#include <algorithm>
#include <atomic>
#include <cctype>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <mutex>
#include <sstream>
#include <vector>

#include "loom/clock.hpp"
#include "loom/kernels/bsr_ops.hpp"
#include "loom/param_fields.hpp"
#include "loom/solver_common.hpp"

namespace loom {

namespace {


std::string petsc_error_text(PetscErrorCode ierr) {
  const char* generic = nullptr;
  char* specific = nullptr;
  PetscErrorMessage(ierr, &generic, &specific);
  std::string s = generic ? generic : "unknown PETSc error";
  if (specific && *specific) s += std::string(": ") + specific;
  return s;
}

// Call a PETSc function; throw SolverError naming the call and PETSc's message on failure.
#define LOOM_PETSC(call)                                                                   \
  do {                                                                                     \
    PetscErrorCode loom_ierr_ = (call);                                                    \
    if (loom_ierr_) throw SolverError("petsc: " #call " failed: " + petsc_error_text(loom_ierr_)); \
  } while (0)

bool g_we_initialized = false;

void finalize_petsc_at_exit() {
  PetscBool init = PETSC_FALSE, fin = PETSC_FALSE;
  PetscInitialized(&init);
  PetscFinalized(&fin);
  if (g_we_initialized && init && !fin) PetscFinalize();
}

/// Open MPI (< 5) loads its components with dlopen and needs libmpi's symbols in the global
/// scope; a plugin module is loaded RTLD_LOCAL, so promote libmpi to RTLD_GLOBAL first.
void promote_libmpi_to_global() {
  Dl_info info{};
  if (dladdr(reinterpret_cast<void*>(&MPI_Init), &info) && info.dli_fname)
    dlopen(info.dli_fname, RTLD_NOW | RTLD_GLOBAL | RTLD_NOLOAD);
}

std::atomic<int> g_instance_counter{0};

/// Prefix every option name ("-ksp_type" -> "-<prefix>ksp_type") of a PETSc options string.
std::string prefix_options(const std::string& opts, const std::string& prefix, std::vector<std::string>& names) {
  std::istringstream in(opts);
  std::string tok, out;
  while (in >> tok) {
    if (tok.size() > 1 && tok[0] == '-' && (std::isalpha(static_cast<unsigned char>(tok[1])) || tok[1] == '_')) {
      const std::string name = tok.substr(1);
      names.push_back("-" + prefix + name);
      out += " -" + prefix + name;
    } else {
      out += " " + tok;
    }
  }
  return out;
}

std::string reason_hint(KSPConvergedReason r) {
  switch (r) {
    case KSP_DIVERGED_INDEFINITE_PC:
    case KSP_DIVERGED_INDEFINITE_MAT:
      return "the matrix (or the preconditioner) is not positive definite on range(S); clamp compressed "
             "springs in the Jacobian (NUMERICS.md 3.5) or reduce dt";
    case KSP_DIVERGED_ITS:
      return "raise max_iterations, or use a stronger preconditioner (pc: gamg)";
    case KSP_DIVERGED_PC_FAILED:
      return "the preconditioner failed to set up (zero pivot?); try pc: jacobi";
    case KSP_DIVERGED_NANORINF:
      return "NaN or Inf in the system: the step blew up";
    case KSP_DIVERGED_BREAKDOWN:
      return "Krylov breakdown; the matrix may be singular or not symmetric";
    default:
      return "see the PETSc manual for this reason";
  }
}

}  // namespace

void petsc_ensure_initialized() {
  static std::mutex m;
  std::lock_guard<std::mutex> lock(m);
  PetscBool init = PETSC_FALSE;
  PetscInitialized(&init);
  if (init) return;
  PetscBool fin = PETSC_FALSE;
  PetscFinalized(&fin);
  if (fin) throw SolverError("petsc: PETSc was already finalised in this process and cannot restart");
  promote_libmpi_to_global();
  // Loom owns the process's signals; PETSc's options still come from $PETSC_OPTIONS.
  PetscOptionsSetValue(nullptr, "-no_signal_handler", nullptr);
  PetscErrorCode ierr = PetscInitializeNoArguments();
  if (ierr) throw SolverError("petsc: PetscInitialize failed (error " + std::to_string(ierr) + ")");
  // Errors come back as codes (turned into SolverError messages), without PETSc printing traces.
  PetscPushErrorHandler(PetscReturnErrorHandler, nullptr);
  g_we_initialized = true;
  std::atexit(finalize_petsc_at_exit);
}

namespace {

// The keys of petsc, each bound to its PetscSolverOptions member (loom/param_fields.hpp).
const ParamFields<PetscSolverOptions>& petsc_fields() {
  static const ParamFields<PetscSolverOptions> fields = [] {
    using O = PetscSolverOptions;
    ParamFields<O> f("petsc", "PETSc KSP on the bs=3 projected system, distributed under mpirun");
    f.choice("ksp", &O::ksp, {"cg", "cr", "minres", "gmres", "fgmres", "bcgs", "pipecg", "preonly"}).help("KSP type");
    f.choice("pc", &O::pc, {"jacobi", "bjacobi", "gamg", "none", "sor", "ilu", "icc", "hypre", "boomeramg", "cholesky", "lu"})
        .help("PC type");
    f.choice("near_null_space", &O::near_null_space, {"auto", "rigid", "none"}).help(
        "rigid-body modes for gamg/hypre (auto: when the integrator passes positions)");
    f.number("tolerance", &O::tolerance).range(ParamRange::positive()).help(
        "relative residual |S(b - A dv)| / |S(b - A z)|");
    f.integer("max_iterations", &O::max_iterations).range(ParamRange::closed(1, 1e8)).help(
        "iterations before the solve counts as failed");
    f.integer("reuse_preconditioner_steps", &O::reuse_preconditioner_steps).range(ParamRange::closed(1, 1e6))
        .units("steps").help("rebuild the preconditioner every N steps (1 = every step)");
    f.text("options", &O::options).help("PETSc options, e.g. \"-ksp_monitor -pc_gamg_threshold 0.01\"");
    f.choice("matrix", &O::matrix, {"auto", "baij", "aij"}).help("matrix format (auto: BAIJ, AIJ for gamg/hypre)");
    return f;
  }();
  return fields;
}

}  // namespace

const ParamSpec& PetscSolverOptions::spec() { return petsc_fields().spec(); }

PetscSolverOptions PetscSolverOptions::from_params(const Params& p) { return petsc_fields().read(p); }

struct PetscSolver::Impl {
  PetscSolverOptions opt;
  MPI_Comm comm = MPI_COMM_WORLD;
  int rank = 0, size = 1;
  std::string prefix;
  std::vector<std::string> option_names;
  bool options_checked = false;
  bool aij = false;  // AIJ with block size 3 instead of BAIJ
  bool amg_pc = false;  // gamg / hypre / ml: takes a near-null space

  Mat M = nullptr;
  Vec x = nullptr, rhs = nullptr, res = nullptr, xall = nullptr;
  VecScatter scatter = nullptr;
  KSP ksp = nullptr;

  const BsrPattern* pattern = nullptr;
  Index n = 0, rb = 0, re = 0;
  std::vector<double> proj;          // projected blocks of the owned rows
  std::vector<PetscScalar> rowvals;  // one block row in PETSc's row-oriented layout
  std::vector<PetscInt> rowcols;
  std::vector<Index> cons_list;
  bool have_values = false;
  bool have_pc = false;
  std::vector<double> coords;        // vertex positions from set_coordinates (3n)
  bool nullspace_attached = false;
  int since_setup = 0;
  int setups = 0;
  double t_assemble = 0, t_setup = 0;

  ~Impl() { destroy(); }
  void destroy() {
    PetscBool fin = PETSC_FALSE;
    PetscFinalized(&fin);
    if (!fin) {  // after PetscFinalize the objects are gone with it
      if (ksp) KSPDestroy(&ksp);
      if (scatter) VecScatterDestroy(&scatter);
      if (xall) VecDestroy(&xall);
      if (x) VecDestroy(&x);
      if (rhs) VecDestroy(&rhs);
      if (res) VecDestroy(&res);
      if (M) MatDestroy(&M);
    }
    ksp = nullptr;
    scatter = nullptr;
    xall = x = rhs = res = nullptr;
    M = nullptr;
    have_values = have_pc = false;
  }

  void set_rows(bool zero) {
    const BsrPattern& P = *pattern;
    for (Index i = rb; i < re; ++i) {
      const Index k0 = P.row_ptr[i], nc = P.row_ptr[i + 1] - k0;
      for (Index jj = 0; jj < nc; ++jj) {
        rowcols[jj] = P.col[k0 + jj];
        const double* B = proj.data() + 9L * (k0 - P.row_ptr[rb] + jj);
        for (int r = 0; r < 3; ++r)
          for (int c = 0; c < 3; ++c) rowvals[r * 3L * nc + 3L * jj + c] = zero ? 0.0 : B[3 * r + c];
      }
      const PetscInt row = i;
      LOOM_PETSC(MatSetValuesBlocked(M, 1, &row, nc, rowcols.data(), rowvals.data(), INSERT_VALUES));
    }
    LOOM_PETSC(MatAssemblyBegin(M, MAT_FINAL_ASSEMBLY));
    LOOM_PETSC(MatAssemblyEnd(M, MAT_FINAL_ASSEMBLY));
  }
};

PetscSolver::PetscSolver(const PetscSolverOptions& options, MPI_Comm comm) : impl_(std::make_unique<Impl>()) {
  petsc_ensure_initialized();
  Impl& m = *impl_;
  m.opt = options;
  m.comm = comm;
  MPI_Comm_rank(comm, &m.rank);
  MPI_Comm_size(comm, &m.size);
  m.prefix = "loom_petsc" + std::to_string(g_instance_counter++) + "_";
  if (!m.opt.options.empty()) {
    const std::string prefixed = prefix_options(m.opt.options, m.prefix, m.option_names);
    LOOM_PETSC(PetscOptionsInsertString(nullptr, prefixed.c_str()));
  }
}

PetscSolver::~PetscSolver() = default;

int PetscSolver::rank() const { return impl_->rank; }
bool PetscSolver::has_near_null_space() const { return impl_->nullspace_attached; }
void PetscSolver::set_coordinates(std::span<const double> x) { impl_->coords.assign(x.begin(), x.end()); }
int PetscSolver::ranks() const { return impl_->size; }
Index PetscSolver::row_begin() const { return impl_->rb; }
Index PetscSolver::row_end() const { return impl_->re; }
double PetscSolver::assemble_seconds() const { return impl_->t_assemble; }
double PetscSolver::setup_seconds() const { return impl_->t_setup; }
int PetscSolver::preconditioner_setups() const { return impl_->setups; }
std::string PetscSolver::matrix_type() const {
  MatType t = nullptr;
  if (impl_->M) MatGetType(impl_->M, &t);
  return t ? t : "none";
}
std::string PetscSolver::ksp_type() const {
  KSPType t = nullptr;
  if (impl_->ksp) KSPGetType(impl_->ksp, &t);
  return t ? t : impl_->opt.ksp;
}
std::string PetscSolver::pc_type() const {
  if (!impl_->ksp) return impl_->opt.pc;
  PC pc;
  PCType t = nullptr;
  KSPGetPC(impl_->ksp, &pc);
  PCGetType(pc, &t);
  return t ? t : impl_->opt.pc;
}

void PetscSolver::analyze_pattern(const BsrMatrix& A, const Filter& S) {
  (void)S;
  Impl& m = *impl_;
  m.destroy();
  const BsrPattern& P = A.pattern();
  m.pattern = &P;
  m.n = P.n;
  m.rb = static_cast<Index>(static_cast<long long>(P.n) * m.rank / m.size);
  m.re = static_cast<Index>(static_cast<long long>(P.n) * (m.rank + 1) / m.size);
  const Index nloc = m.re - m.rb;

  std::vector<PetscInt> d_nnz(nloc), o_nnz(nloc);
  Index maxrow = 1;
  for (Index i = m.rb; i < m.re; ++i) {
    PetscInt d = 0, o = 0;
    for (Index k = P.row_ptr[i]; k < P.row_ptr[i + 1]; ++k) (P.col[k] >= m.rb && P.col[k] < m.re) ? ++d : ++o;
    d_nnz[i - m.rb] = d;
    o_nnz[i - m.rb] = o;
    maxrow = std::max(maxrow, P.row_ptr[i + 1] - P.row_ptr[i]);
  }
  LOOM_PETSC(KSPCreate(m.comm, &m.ksp));
  LOOM_PETSC(KSPSetOptionsPrefix(m.ksp, m.prefix.c_str()));
  LOOM_PETSC(KSPSetType(m.ksp, m.opt.ksp.c_str()));
  PC pc;
  LOOM_PETSC(KSPGetPC(m.ksp, &pc));
  if (m.opt.pc == "boomeramg") {
    // hypre BoomerAMG for a block-3 system: nodal coarsening on the 3x3 blocks (Frobenius
    // norms). Interpolation that also fits the rigid modes attached in factorize
    // (-pc_hypre_boomeramg_vec_interp_variant 2) is available through `options`; it cost
    // 9x more here (docs/plugins/solvers.md). The scene's `options` override these defaults.
    LOOM_PETSC(PCSetType(pc, PCHYPRE));
    LOOM_PETSC(PCHYPRESetType(pc, "boomeramg"));
    for (auto [key, value] : {std::pair{"pc_hypre_boomeramg_nodal_coarsen", "6"}}) {
      const std::string name = "-" + m.prefix + key;
      PetscBool set = PETSC_FALSE;
      LOOM_PETSC(PetscOptionsHasName(nullptr, nullptr, name.c_str(), &set));
      if (!set) LOOM_PETSC(PetscOptionsSetValue(nullptr, name.c_str(), value));
    }
  } else {
    LOOM_PETSC(PCSetType(pc, m.opt.pc.c_str()));
  }
  LOOM_PETSC(KSPSetTolerances(m.ksp, m.opt.tolerance, 0.0, PETSC_DEFAULT, m.opt.max_iterations));
  // The relative residual Loom reports is unpreconditioned: |b^ - A~ y| / |b^|.
  if (m.opt.ksp == "cg" || m.opt.ksp == "pipecg" || m.opt.ksp == "cr")
    LOOM_PETSC(KSPSetNormType(m.ksp, KSP_NORM_UNPRECONDITIONED));
  LOOM_PETSC(KSPSetInitialGuessNonzero(m.ksp, PETSC_TRUE));
  LOOM_PETSC(KSPSetFromOptions(m.ksp));  // the scene's `options` override the defaults above
  // GAMG (and hypre) coarsen AIJ matrices only: use AIJ with block size 3 for them, BAIJ
  // (3x3 blocks, fewer indices, faster SpMV) for the others, unless `matrix` says otherwise.
  PC pc_now;
  PCType pc_type_now = nullptr;
  LOOM_PETSC(KSPGetPC(m.ksp, &pc_now));
  LOOM_PETSC(PCGetType(pc_now, &pc_type_now));
  const std::string pct = pc_type_now ? pc_type_now : "";
  m.aij = m.opt.matrix == "aij" || (m.opt.matrix == "auto" && (pct == "gamg" || pct == "hypre" || pct == "ml"));
  m.amg_pc = pct == "gamg" || pct == "hypre" || pct == "ml";
  const PetscInt nl = 3 * static_cast<PetscInt>(nloc), N = 3 * static_cast<PetscInt>(P.n);
  LOOM_PETSC(MatCreate(m.comm, &m.M));
  LOOM_PETSC(MatSetSizes(m.M, nl, nl, N, N));
  LOOM_PETSC(MatSetBlockSize(m.M, 3));
  if (m.aij) {
    LOOM_PETSC(MatSetType(m.M, m.size > 1 ? MATMPIAIJ : MATSEQAIJ));
    std::vector<PetscInt> dn(3 * nloc), on(3 * nloc);  // scalar rows: 3 x the block counts
    for (Index i = 0; i < 3 * nloc; ++i) {
      dn[i] = 3 * d_nnz[i / 3];
      on[i] = 3 * o_nnz[i / 3];
    }
    if (m.size > 1) LOOM_PETSC(MatMPIAIJSetPreallocation(m.M, 0, dn.data(), 0, on.data()));
    else LOOM_PETSC(MatSeqAIJSetPreallocation(m.M, 0, dn.data()));
  } else {
    LOOM_PETSC(MatSetType(m.M, m.size > 1 ? MATMPIBAIJ : MATSEQBAIJ));
    if (m.size > 1) LOOM_PETSC(MatMPIBAIJSetPreallocation(m.M, 3, 0, d_nnz.data(), 0, o_nnz.data()));
    else LOOM_PETSC(MatSeqBAIJSetPreallocation(m.M, 3, 0, d_nnz.data()));
  }
  LOOM_PETSC(MatSetOption(m.M, MAT_NEW_NONZERO_ALLOCATION_ERR, PETSC_TRUE));
  LOOM_PETSC(MatSetOption(m.M, MAT_NO_OFF_PROC_ENTRIES, PETSC_TRUE));
  LOOM_PETSC(MatSetOption(m.M, MAT_SYMMETRIC, PETSC_TRUE));
  LOOM_PETSC(MatSetOption(m.M, MAT_SYMMETRY_ETERNAL, PETSC_TRUE));

  m.proj.assign(9L * (P.row_ptr[m.re] - P.row_ptr[m.rb]), 0.0);
  m.rowvals.assign(9L * maxrow, 0.0);
  m.rowcols.assign(maxrow, 0);
  m.set_rows(/*zero*/ true);  // fixes the nonzero structure
  LOOM_PETSC(MatSetOption(m.M, MAT_NEW_NONZERO_LOCATION_ERR, PETSC_TRUE));

  LOOM_PETSC(MatCreateVecs(m.M, &m.x, &m.rhs));
  LOOM_PETSC(VecDuplicate(m.rhs, &m.res));
  LOOM_PETSC(VecScatterCreateToAll(m.x, &m.scatter, &m.xall));


  m.cons_list.clear();
  m.since_setup = 0;
}

bool PetscSolver::factorize(const BsrMatrix& A, const Filter& S, SolveReport& report) {
  Impl& m = *impl_;
  const auto t0 = Clock::now();
  if (!A.has_pattern()) throw SolverError("petsc: factorize called with a matrix without pattern");
  if (m.pattern != &A.pattern() || !m.M) analyze_pattern(A, S);
  if (S.size() != m.n)
    throw SolverError("petsc: the filter has " + std::to_string(S.size()) + " vertices, the matrix " +
                      std::to_string(m.n));
  const BsrPattern& P = *m.pattern;
  bool s_changed = S.constrained() != m.cons_list;
  if (s_changed) m.cons_list = S.constrained();

  // Projected owned rows; every value finite, diagonal positive (checked on all ranks).
  const Index* rp = P.row_ptr.data();
  const Index* cl = P.col.data();
  const Index* dg = P.diag.data();
  const double* Av = A.values().data();
  const long off = 9L * rp[m.rb];
  double* Pv = m.proj.data() - off;  // indexed by global block position
  long bad = -1;
  int nonfinite = 0;
  const Index rb = m.rb, re = m.re;
#pragma omp parallel for schedule(static) reduction(max : bad) reduction(max : nonfinite) if (re - rb >= solver::kParallelMinRows)
  for (Index i = rb; i < re; ++i) {
    for (Index k = rp[i]; k < rp[i + 1]; ++k) solver::projected_block(S, i, cl[k], Av + 9L * k, Pv + 9L * k);
    for (long e = 9L * rp[i]; e < 9L * rp[i + 1]; ++e)
      if (!std::isfinite(Pv[e])) nonfinite = 1;
    const double* D = Pv + 9L * dg[i];
    for (int r = 0; r < 3; ++r)
      if (!(D[4 * r] > 0.0)) bad = std::max(bad, 3L * i + r);
  }
  long gbad = bad;
  int gnonfinite = nonfinite;
  if (m.size > 1) {
    MPI_Allreduce(&bad, &gbad, 1, MPI_LONG, MPI_MAX, m.comm);
    MPI_Allreduce(&nonfinite, &gnonfinite, 1, MPI_INT, MPI_MAX, m.comm);
  }
  if (gnonfinite || gbad >= 0) {
    m.have_values = false;
    if (gnonfinite) {
      report.message = "petsc: the matrix has NaN or Inf entries (the Jacobian or the step blew up)";
    } else {
      char buf[400];
      std::snprintf(buf, sizeof buf,
                    "petsc: the matrix is not positive definite on range(S): a diagonal entry at vertex %ld, "
                    "component %ld is not positive. Clamp compressed springs in the Jacobian (NUMERICS.md 3.5) "
                    "or reduce dt.",
                    gbad / 3, gbad % 3);
      report.message = buf;
    }
    report.factorize_seconds = seconds_since(t0);
    return false;
  }
  m.set_rows(false);
  m.have_values = true;
  m.t_assemble = seconds_since(t0);

  // Preconditioner: rebuilt now, or kept for up to reuse_preconditioner_steps calls.
  const auto t1 = Clock::now();
  const bool rebuild = !m.have_pc || s_changed || m.opt.reuse_preconditioner_steps <= 1 ||
                       m.since_setup + 1 >= m.opt.reuse_preconditioner_steps;
  LOOM_PETSC(KSPSetOperators(m.ksp, m.M, m.M));
  LOOM_PETSC(KSPSetReusePreconditioner(m.ksp, rebuild ? PETSC_FALSE : PETSC_TRUE));
  if (rebuild) {
    // Rigid-body near-null space from the current positions (6 modes per vertex; the
    // projected matrix's constrained rows are identity rows, decoupled from the rest).
    const bool want = m.opt.near_null_space == "rigid" || (m.opt.near_null_space == "auto" && m.amg_pc);
    m.nullspace_attached = false;
    if (want && m.coords.size() == 3 * static_cast<std::size_t>(m.n)) {
      Vec c;
      LOOM_PETSC(VecDuplicate(m.x, &c));
      LOOM_PETSC(VecSetBlockSize(c, 3));
      PetscScalar* cv;
      LOOM_PETSC(VecGetArray(c, &cv));
      for (long k = 3L * m.rb; k < 3L * m.re; ++k) cv[k - 3L * m.rb] = m.coords[k];
      LOOM_PETSC(VecRestoreArray(c, &cv));
      MatNullSpace nsp;
      LOOM_PETSC(MatNullSpaceCreateRigidBody(c, &nsp));
      LOOM_PETSC(MatSetNearNullSpace(m.M, nsp));
      LOOM_PETSC(MatNullSpaceDestroy(&nsp));
      LOOM_PETSC(VecDestroy(&c));
      m.nullspace_attached = true;
    } else if (m.opt.near_null_space == "rigid") {
      report.message = "petsc: near_null_space: rigid needs the vertex positions, but the integrator passed none "
                       "(use near_null_space: auto or none)";
      report.factorize_seconds = seconds_since(t0);
      return false;
    }
    PetscErrorCode ierr = KSPSetUp(m.ksp);
    if (ierr) {
      m.have_pc = false;
      report.message = "petsc: preconditioner set-up failed: " + petsc_error_text(ierr);
      report.factorize_seconds = seconds_since(t0);
      return false;
    }
    m.since_setup = 0;
    ++m.setups;
    m.have_pc = true;
  } else {
    ++m.since_setup;
  }
  m.t_setup = seconds_since(t1);
  report.factorize_seconds = seconds_since(t0);
  return true;
}

SolveReport PetscSolver::solve(const BsrMatrix& A, const Filter& S, std::span<const double> b,
                               std::span<const double> z, std::span<double> dv) {
  Impl& m = *impl_;
  SolveReport rep;
  const auto t0 = Clock::now();
  if (!m.have_values) {
    rep.message = "petsc: solve() without a successful factorize()";
    return rep;
  }
  const long N = 3L * m.n;
  if (static_cast<long>(b.size()) != N || static_cast<long>(z.size()) != N || static_cast<long>(dv.size()) != N)
    throw SolverError("petsc: vector sizes differ from 3 x " + std::to_string(m.n));
  const BsrPattern& P = *m.pattern;

  const bool z_zero = solver::prescribed_is_zero(S, z);

  // b^ = S (b - A z) and the initial guess y0 = S dv on the owned rows.
  PetscScalar* bl = nullptr;
  PetscScalar* xl = nullptr;
  LOOM_PETSC(VecGetArray(m.rhs, &bl));
  LOOM_PETSC(VecGetArray(m.x, &xl));
  const Index* rp = P.row_ptr.data();
  const Index* cl = P.col.data();
  const double* Av = A.values().data();
  const double* bp = b.data();
  const double* zp = z.data();
  const double* dvp = dv.data();
  const Index rb = m.rb, re = m.re;
  double* bh = bl - 3L * rb;  // indexed by global DOF
  double* y0 = xl - 3L * rb;
#pragma omp parallel for schedule(static) if (re - rb >= solver::kParallelMinRows)
  for (Index i = rb; i < re; ++i) {
    double* bi = bh + 3L * i;
    double az[3] = {0.0, 0.0, 0.0};
    if (!z_zero) kernels::bsr_row_multiply(rp, cl, Av, zp, i, az);
    for (int r = 0; r < 3; ++r) {
      bi[r] = bp[3L * i + r] - az[r];
      y0[3L * i + r] = std::isfinite(dvp[3L * i + r]) ? dvp[3L * i + r] : 0.0;
    }
    solver::filter_vertex(S, i, bi);
    solver::filter_vertex(S, i, y0 + 3L * i);
  }
  LOOM_PETSC(VecRestoreArray(m.x, &xl));
  LOOM_PETSC(VecRestoreArray(m.rhs, &bl));

  PetscReal norm0 = 0;
  LOOM_PETSC(VecNorm(m.rhs, NORM_2, &norm0));
  double rel = 0.0;
  if (norm0 == 0.0) {
    LOOM_PETSC(VecSet(m.x, 0.0));
    rep.converged = true;
  } else {
    PetscErrorCode ierr = KSPSolve(m.ksp, m.rhs, m.x);
    if (ierr) {
      rep.message = "petsc: KSPSolve failed: " + petsc_error_text(ierr);
      rep.solve_seconds = seconds_since(t0);
      return rep;
    }
    KSPConvergedReason reason;
    PetscInt its = 0;
    LOOM_PETSC(KSPGetConvergedReason(m.ksp, &reason));
    LOOM_PETSC(KSPGetIterationNumber(m.ksp, &its));
    // True residual |b^ - A~ y| / |b^| (not the Krylov recurrence's).
    LOOM_PETSC(MatMult(m.M, m.x, m.res));
    LOOM_PETSC(VecAYPX(m.res, -1.0, m.rhs));
    PetscReal rn = 0;
    LOOM_PETSC(VecNorm(m.res, NORM_2, &rn));
    rel = rn / norm0;
    rep.iterations = static_cast<int>(its);
    rep.converged = reason > 0;
    if (reason <= 0) {
      char buf[600];
      std::snprintf(buf, sizeof buf,
                    "petsc: KSP %s with PC %s did not converge: %s after %d iterations (relative residual "
                    "%.3g, tolerance %.3g): %s",
                    ksp_type().c_str(), pc_type().c_str(), KSPConvergedReasons[reason], static_cast<int>(its), rel,
                    m.opt.tolerance, reason_hint(reason).c_str());
      rep.message = buf;
    }
    if (!m.options_checked) {  // options given in the scene that PETSc never read: probably misspelt
      m.options_checked = true;
      for (const auto& name : m.option_names) {
        PetscBool used = PETSC_FALSE;
        PetscOptionsUsed(nullptr, name.c_str(), &used);
        if (!used && m.rank == 0)
          std::fprintf(stderr, "loom: warning: petsc option -%s was not used (misspelt?)\n",
                       name.substr(1 + m.prefix.size()).c_str());
      }
    }
  }

  // Gather the full solution to every rank, then dv = S y + (I - S) z.
  LOOM_PETSC(VecScatterBegin(m.scatter, m.x, m.xall, INSERT_VALUES, SCATTER_FORWARD));
  LOOM_PETSC(VecScatterEnd(m.scatter, m.x, m.xall, INSERT_VALUES, SCATTER_FORWARD));
  const PetscScalar* ya = nullptr;
  LOOM_PETSC(VecGetArrayRead(m.xall, &ya));
  double* d = dv.data();
#pragma omp parallel for schedule(static) if (N >= 16384)
  for (long i = 0; i < N; ++i) d[i] = ya[i];
  LOOM_PETSC(VecRestoreArrayRead(m.xall, &ya));
  solver::apply_prescribed(S, z, dv);
  rep.residual = rel;
  rep.solve_seconds = seconds_since(t0);
  return rep;
}

}  // namespace loom

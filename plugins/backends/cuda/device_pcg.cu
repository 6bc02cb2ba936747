#include "device_pcg.hpp"

#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <type_traits>

#include "loom/filtered_pcg.hpp"
#include "loom/clock.hpp"
#include "loom/kernels/bsr_ops.hpp"

namespace loom::cuda {

namespace {
// The keys filtered_pcg declares on the cpu (plugins/solvers/eigen/eigen_pcg.cpp), with the
// same defaults and meaning; sa_amg and parallel_min_rows are cpu only.
ParamSpec make_device_pcg_spec(const char* name, const char* summary) {
  const PcgOptions d;
  ParamSpec s(name, summary);
  s.number("tolerance", d.tolerance).range(ParamRange::closed(1e-16, 0.5)).help(
      "true relative residual of the filtered system: |S(b - A dv)| <= tolerance |S(b - A z)|");
  s.integer("max_iterations", d.max_iterations).range(ParamRange::closed(1, 1e8)).help(
      "iterations before the solve counts as failed");
  s.choice("preconditioner", "block_jacobi", {"none", "jacobi", "block_jacobi"}).help(
      "filtered (block) diagonal preconditioner S M^-1 S");
  return s;
}
}  // namespace

const ParamSpec& filtered_pcg_cuda_spec() {
  static const ParamSpec spec =
      make_device_pcg_spec("filtered_pcg", "modified (filtered) PCG of Baraff-Witkin on the GPU, one loop for every backend");
  return spec;
}

const ParamSpec& cusparse_pcg_spec() {
  static const ParamSpec spec = make_device_pcg_spec("cusparse_pcg", "deprecated name of filtered_pcg on backend cuda");
  return spec;
}

PcgOptions parse_pcg_options(const Params& p, const ParamSpec& spec) {
  PcgOptions o;
  if (!p.valid()) return o;
  const ParamReader r(p, spec);
  o.tolerance = r.number("tolerance");
  o.max_iterations = r.int32("max_iterations");
  const std::string pc = r.text("preconditioner");
  o.preconditioner = pc == "none"     ? PcgOptions::Preconditioner::None
                     : pc == "jacobi" ? PcgOptions::Preconditioner::Jacobi
                                      : PcgOptions::Preconditioner::BlockJacobi;
  return o;
}

template <class T>
void DeviceFilter<T>::upload(const Filter& S) {
  n = S.size();
  std::vector<unsigned char> fr(n);
  std::vector<T> pr(9 * static_cast<std::size_t>(n));
  for (Index i = 0; i < n; ++i) {
    fr[i] = static_cast<unsigned char>(S.free_dofs(i));
    for (int e = 0; e < 9; ++e) pr[9 * i + e] = static_cast<T>(S.projector(i)[e]);
  }
  cuda::upload(fr, free);
  cuda::upload(pr, proj);
  cuda::upload(S.constrained(), constrained);
  num_constrained = static_cast<Index>(S.constrained().size());
}

namespace {
struct IsConstrained {
  LOOM_HD bool operator()(unsigned char f) const { return f < 3; }
};
}  // namespace

template <class T>
void DeviceFilter<T>::resize(Index nv) {
  n = nv;
  free.assign(static_cast<std::size_t>(nv), static_cast<unsigned char>(3));
  proj.assign(9 * static_cast<std::size_t>(nv), T(0));
  constrained.assign(static_cast<std::size_t>(nv), Index(0));
  num_constrained = 0;
}

template <class T>
void DeviceFilter<T>::rebuild_constrained() {
  if (n == 0) return;
  if (constrained.size() != static_cast<std::size_t>(n)) constrained.resize(static_cast<std::size_t>(n));
  const auto end = thrust::copy_if(thrust::device, thrust::counting_iterator<Index>(0), thrust::counting_iterator<Index>(n),
                                   free.begin(), constrained.begin(), IsConstrained{});
  num_constrained = static_cast<Index>(end - constrained.begin());
}

namespace {

// The 9 values of a block (or projector) in M, as T (exact when M = T or M = float, T = double).
template <class T, class M>
LOOM_HD inline void load_block(const M* in, T* out) {
  for (int e = 0; e < 9; ++e) out[e] = static_cast<T>(in[e]);
}

// y <- S_i y with S_i stored in M (kernels::filter_vec3 on the projector converted to T).
template <class T, class M>
LOOM_HD inline void filter_vec3_from(int free_dofs, const M* proj, T* y) {
  if (free_dofs == 3) return;
  T P[9];
  load_block(proj, P);
  kernels::filter_vec3(free_dofs, P, y);
}

template <class T, class M>
struct AddPrescribed {  // dv <- S dv + z on the constrained vertices (free ones keep their guess)
  const Index* cons;
  const unsigned char* free;
  const M* proj;
  const T* z;
  T* dv;
  LOOM_HD void operator()(Index k) const {
    const Index i = cons[k];
    T* d = dv + 3LL * i;
    filter_vec3_from(static_cast<int>(free[i]), proj + 9LL * i, d);
    d[0] += z[3LL * i];
    d[1] += z[3LL * i + 1];
    d[2] += z[3LL * i + 2];
  }
};

template <class T, class Mat>
struct Preconditioner {  // P_i = S_i M_i^-1 S_i as on the CPU; returns 1 for a vertex whose (block) diagonal is not SPD
  const Index* diag;
  const Mat* A;
  const unsigned char* free;
  const Mat* proj;
  int kind;  // 0 none, 1 jacobi, 2 block
  T* pinv;
  LOOM_HD int operator()(Index i) const {
    T D[9], Si[9];   // the diagonal block and the projector in T
    load_block(A + 9LL * diag[i], D);
    load_block(proj + 9LL * i, Si);
    const int f = static_cast<int>(free[i]);
    T* P = pinv + 9LL * i;
    for (int e = 0; e < 9; ++e) P[e] = T(0);
    if (f == 0) return 0;
    T M[9] = {T(0), T(0), T(0), T(0), T(0), T(0), T(0), T(0), T(0)};
    int bad = 0;
    if (kind == 0) {
      M[0] = M[4] = M[8] = T(1);
    } else if (kind == 1) {
      for (int a = 0; a < 3; ++a) {
        if (!(D[4 * a] > T(0))) bad = 1;
        M[4 * a] = T(1) / D[4 * a];
      }
    } else {
      // The projected diagonal block S_i D S_i + (I - S_i), as solver::projected_block.
      T B[9];
      if (f == 3) {
        for (int e = 0; e < 9; ++e) B[e] = D[e];
      } else {
        T tmp[9];
        kernels::mat3_mul_mat(Si, D, tmp);
        kernels::mat3_mul_mat(tmp, Si, B);
        for (int a = 0; a < 3; ++a)
          for (int b = 0; b < 3; ++b) B[3 * a + b] += (a == b ? T(1) : T(0)) - Si[3 * a + b];
      }
      if (!kernels::mat3_spd_inverse(B, M)) bad = 1;
    }
    if (f == 3) {
      for (int e = 0; e < 9; ++e) P[e] = M[e];
    } else {
      kernels::mat3_project(Si, M, Si, P);
    }
    return bad;
  }
};

template <class T>
struct PrecondDot {  // s_i = Pinv_i r_i; returns r_i . s_i
  const T* pinv;
  const T* r;
  T* s;
  LOOM_HD T operator()(Index i) const {
    kernels::mat3_mul(pinv + 9LL * i, r + 3LL * i, s + 3LL * i);
    return kernels::dot3(r + 3LL * i, s + 3LL * i);
  }
};

template <class T>
struct Update {  // dv += alpha c; r -= alpha q; returns r . r
  const T* c;
  const T* q;
  T alpha;
  T* dv;
  T* r;
  LOOM_HD T operator()(Index i) const {
    const long long o = 3LL * i;
    for (int a = 0; a < 3; ++a) {
      dv[o + a] += alpha * c[o + a];
      r[o + a] -= alpha * q[o + a];
    }
    return kernels::dot3(r + o, r + o);
  }
};

template <class T>
struct Xpby {  // c <- s + beta c (s is in range(S), so c stays there)
  const T* s;
  T beta;
  T* c;
  LOOM_HD void operator()(Index d) const { c[d] = s[d] + beta * c[d]; }
};

template <class T, class M>
struct RowResidual {  // out_i = S_i (b_i - out_i) with out = A x on entry; returns |out_i|^2
  const unsigned char* free;
  const M* proj;
  const T* b;
  T* out;
  LOOM_HD T operator()(Index i) const {
    const long long o = 3LL * i;
    for (int a = 0; a < 3; ++a) out[o + a] = b[o + a] - out[o + a];
    filter_vec3_from(static_cast<int>(free[i]), proj + 9LL * i, out + o);
    return kernels::dot3(out + o, out + o);
  }
};

template <class T, class M>
struct FilteredDot {  // q_i <- S_i q_i; returns c_i . q_i
  const unsigned char* free;
  const M* proj;
  const T* c;
  T* q;
  LOOM_HD T operator()(Index i) const {
    const long long o = 3LL * i;
    filter_vec3_from(static_cast<int>(free[i]), proj + 9LL * i, q + o);
    return kernels::dot3(c + o, q + o);
  }
};

// out = A x: cuSPARSE (through the seam) when the matrix and the vectors share a type, else the
// mixed row product (the SpMV of the mixed-precision PCG: float blocks, double sums).
template <class T, class M>
void multiply(const DeviceBsr<M>& A, const T* x, T* out) {
  if constexpr (std::is_same_v<T, M>)
    A.multiply(x, out);
  else
    parallel_for(A.n, kernels::BsrRowProduct<T, Index, M>{raw(A.row_ptr), raw(A.col), raw(A.values), x, out});
}

template <class T>
struct Copy {
  const T* a;
  T* b;
  LOOM_HD void operator()(Index d) const { b[d] = a[d]; }
};

/// The device operations of the filtered PCG (loom/filtered_pcg.hpp): vectors in T, A and S in M.
template <class T, class M>
struct DevicePcgOps {
  using Real = T;
  using Vec = DVec<T>;
  const DeviceBsr<M>& A;
  const DeviceFilter<M>& S;
  const DVec<T>& b;
  const DVec<T>& z;
  const DVec<T>& pinv;
  Index n;

  T residual(const Vec& x, Vec& out) const {
    multiply(A, raw(x), raw(out));
    return reduce_sum<T>(n, RowResidual<T, M>{raw(S.free), raw(S.proj), raw(b), raw(out)});
  }
  T apply_operator(const Vec& c, Vec& q) const {
    multiply(A, raw(c), raw(q));
    return reduce_sum<T>(n, FilteredDot<T, M>{raw(S.free), raw(S.proj), raw(c), raw(q)});
  }
  T precondition(const Vec& r, Vec& s) const { return reduce_sum<T>(n, PrecondDot<T>{raw(pinv), raw(r), raw(s)}); }
  T update(T alpha, const Vec& c, const Vec& q, Vec& x, Vec& r) const {
    return reduce_sum<T>(n, Update<T>{raw(c), raw(q), alpha, raw(x), raw(r)});
  }
  void xpby(const Vec& s, T beta, Vec& c) const { parallel_for(3 * n, Xpby<T>{raw(s), beta, raw(c)}); }
  void start(Vec& dv) const {
    parallel_for(S.num_constrained, AddPrescribed<T, M>{raw(S.constrained), raw(S.free), raw(S.proj), raw(z), raw(dv)});
  }
  void assign_prescribed(Vec& dv) const {
    fill(dv, T(0));
    start(dv);
  }
  void copy(const Vec& a, Vec& c) const { parallel_for(3 * n, Copy<T>{raw(a), raw(c)}); }
};

}  // namespace

template <class T, class M>
void DevicePcg<T, M>::analyze(Index n) {
  n_ = n;
  const std::size_t N = 3 * static_cast<std::size_t>(n);
  pinv_.assign(9 * static_cast<std::size_t>(n), T(0));
  r_.assign(N, T(0));
  c_.assign(N, T(0));
  q_.assign(N, T(0));
  s_.assign(N, T(0));
}

template <class T, class M>
bool DevicePcg<T, M>::factorize(const DeviceBsr<M>& A, const DeviceFilter<M>& S, SolveReport& report) {
  const auto t0 = Clock::now();
  if (A.n != n_) analyze(A.n);
  const int kind = opt_.preconditioner == PcgOptions::Preconditioner::None     ? 0
                   : opt_.preconditioner == PcgOptions::Preconditioner::Jacobi ? 1
                                                                               : 2;
  const int bad = reduce_sum<int>(
      n_, Preconditioner<T, M>{raw(A.diag), raw(A.values), raw(S.free), raw(S.proj), kind, raw(pinv_)});
  report.factorize_seconds = seconds_since(t0);
  if (bad > 0) {
    report.converged = false;
    report.message = name_ + ": " + std::to_string(bad) +
                     " diagonal blocks of the system are not positive definite, so the system matrix is not positive "
                     "definite on the free DOFs (compressed elements without the Jacobian clamp, or a step too large "
                     "for the material); reduce integrator.dt, enable the material's Jacobian clamp, or set "
                     "integrator.on_solver_failure: halve_step";
    return false;
  }
  return true;
}

template <class T, class M>
SolveReport DevicePcg<T, M>::solve(const DeviceBsr<M>& A, const DeviceFilter<M>& S, const DVec<T>& b,
                                   const DVec<T>& z, DVec<T>& dv) {
  const auto t0 = Clock::now();
  if (A.n != n_) analyze(A.n);
  DevicePcgOps<T, M> ops{A, S, b, z, pinv_, n_};
  static_assert(pcg::FilteredPcgOps<DevicePcgOps<T, M>>);
  pcg::Settings set;
  set.tolerance = std::min(0.5, opt_.tolerance * tolerance_scale_);  // as the CPU filtered_pcg
  set.max_iterations = opt_.max_iterations;
  set.name = name_.c_str();
  SolveReport rep = pcg::solve(ops, set, dv, r_, c_, q_, s_);
  rep.solve_seconds = seconds_since(t0);
  return rep;
}

template class DevicePcg<double>;
template class DevicePcg<float>;
template class DevicePcg<double, float>;
template struct DeviceFilter<double>;
template struct DeviceFilter<float>;

// ---- host interface ----
void CusparsePcg::analyze_pattern(const BsrMatrix& A, const Filter&) {
  A_.set_pattern(A.pattern());
  pcg_.analyze(A.rows());
}

bool CusparsePcg::factorize(const BsrMatrix& A, const Filter& S, SolveReport& report) {
  if (A_.n != A.rows() || A_.nnzb != A.pattern().nnz_blocks()) analyze_pattern(A, S);
  cuda::upload(A.values(), A_.values);
  S_.upload(S);
  return pcg_.factorize(A_, S_, report);
}

SolveReport CusparsePcg::solve(const BsrMatrix&, const Filter&, std::span<const double> b, std::span<const double> z,
                               std::span<double> dv) {
  b_.assign(b.begin(), b.end());
  z_.assign(z.begin(), z.end());
  dv_.assign(dv.begin(), dv.end());
  SolveReport rep = pcg_.solve(A_, S_, b_, z_, dv_);
  thrust::copy(dv_.begin(), dv_.end(), dv.begin());
  return rep;
}

}  // namespace loom::cuda

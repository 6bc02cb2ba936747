#include "device_pcg.hpp"

#include <chrono>
#include <cmath>
#include <cstdio>

#include "loom/kernels/bsr_ops.hpp"

namespace loom::cuda {

const ParamSpec& cusparse_pcg_spec() {
  static const ParamSpec spec = [] {
    const PcgOptions d;
    ParamSpec s("cusparse_pcg", "modified (filtered) PCG on the GPU");
    s.number("tolerance", d.tolerance).range(ParamRange::closed(1e-16, 0.5)).help(
        "on sqrt(r.P^-1 r / b.P^-1 b) of the filtered residual");
    s.integer("max_iterations", d.max_iterations).range(ParamRange::at_least(1)).help(
        "iterations before the solve counts as failed");
    s.choice("preconditioner", "block_jacobi", {"none", "jacobi", "block_jacobi"}).help("diagonal preconditioner");
    return s;
  }();
  return spec;
}

PcgOptions parse_pcg_options(const Params& p) {
  PcgOptions o;
  if (!p.valid()) return o;
  const ParamReader r(p, cusparse_pcg_spec());
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

using Clock = std::chrono::steady_clock;

template <class T>
struct FilterConstrained {  // y <- S y on the constrained vertices
  const Index* cons;
  const unsigned char* free;
  const T* proj;
  T* y;
  LOOM_HD void operator()(Index k) const {
    const Index i = cons[k];
    kernels::filter_vec3(static_cast<int>(free[i]), proj + 9LL * i, y + 3LL * i);
  }
};

template <class T>
struct AddPrescribed {  // dv <- S dv + z on the constrained vertices (free ones keep their guess)
  const Index* cons;
  const unsigned char* free;
  const T* proj;
  const T* z;
  T* dv;
  LOOM_HD void operator()(Index k) const {
    const Index i = cons[k];
    T* d = dv + 3LL * i;
    kernels::filter_vec3(static_cast<int>(free[i]), proj + 9LL * i, d);
    d[0] += z[3LL * i];
    d[1] += z[3LL * i + 1];
    d[2] += z[3LL * i + 2];
  }
};

template <class T>
struct Preconditioner {  // Pm^-1 blocks; returns 1 for a vertex whose (block) diagonal is not SPD
  const Index* diag;
  const T* A;
  int kind;  // 0 none, 1 jacobi, 2 block
  T* pinv;
  LOOM_HD int operator()(Index i) const {
    const T* D = A + 9LL * diag[i];
    T* P = pinv + 9LL * i;
    for (int e = 0; e < 9; ++e) P[e] = T(0);
    if (kind == 0) {
      P[0] = P[4] = P[8] = T(1);
      return 0;
    }
    if (kind == 1) {
      if (!(D[0] > T(0)) || !(D[4] > T(0)) || !(D[8] > T(0))) return 1;
      P[0] = T(1) / D[0];
      P[4] = T(1) / D[4];
      P[8] = T(1) / D[8];
      return 0;
    }
    return kernels::mat3_spd_inverse(D, P) ? 0 : 1;
  }
};

template <class T>
struct Residual {  // r <- b - t (filter applied separately)
  const T* b;
  const T* t;
  T* r;
  LOOM_HD void operator()(Index d) const { r[d] = b[d] - t[d]; }
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
struct Update {  // dv += alpha c; r -= alpha q; s = Pinv r; returns r . s
  const T* pinv;
  const T* c;
  const T* q;
  T alpha;
  T* dv;
  T* r;
  T* s;
  LOOM_HD T operator()(Index i) const {
    const long long o = 3LL * i;
    for (int a = 0; a < 3; ++a) {
      dv[o + a] += alpha * c[o + a];
      r[o + a] -= alpha * q[o + a];
    }
    kernels::mat3_mul(pinv + 9LL * i, r + o, s + o);
    return kernels::dot3(r + o, s + o);
  }
};

template <class T>
struct Direction {  // c <- S (s + beta c)
  const unsigned char* free;
  const T* proj;
  const T* s;
  T beta;
  T* c;
  LOOM_HD void operator()(Index i) const {
    const long long o = 3LL * i;
    for (int a = 0; a < 3; ++a) c[o + a] = s[o + a] + beta * c[o + a];
    kernels::filter_vec3(static_cast<int>(free[i]), proj + 9LL * i, c + o);
  }
};

template <class T>
struct Copy {
  const T* a;
  T* b;
  LOOM_HD void operator()(Index d) const { b[d] = a[d]; }
};

template <class T>
void filter(const DeviceFilter<T>& S, DVec<T>& y) {
  parallel_for(S.num_constrained, FilterConstrained<T>{raw(S.constrained), raw(S.free), raw(S.proj), raw(y)});
}

/// out = S (b - A x); returns |out|^2.
template <class T>
T filtered_residual(const DeviceBsr<T>& A, const DeviceFilter<T>& S, const DVec<T>& b, const DVec<T>& x, DVec<T>& tmp,
                    DVec<T>& out) {
  A.multiply(raw(x), raw(tmp));
  parallel_for(static_cast<Index>(out.size()), Residual<T>{raw(b), raw(tmp), raw(out)});
  filter(S, out);
  return dot(out, out);
}

}  // namespace

template <class T>
void DevicePcg<T>::analyze(Index n) {
  n_ = n;
  const std::size_t N = 3 * static_cast<std::size_t>(n);
  pinv_.assign(9 * static_cast<std::size_t>(n), T(0));
  r_.assign(N, T(0));
  c_.assign(N, T(0));
  q_.assign(N, T(0));
  s_.assign(N, T(0));
  t_.assign(N, T(0));
}

template <class T>
bool DevicePcg<T>::factorize(const DeviceBsr<T>& A, SolveReport& report) {
  const auto t0 = Clock::now();
  if (A.n != n_) analyze(A.n);
  const int kind = opt_.preconditioner == PcgOptions::Preconditioner::None     ? 0
                   : opt_.preconditioner == PcgOptions::Preconditioner::Jacobi ? 1
                                                                               : 2;
  const int bad = reduce_sum<int>(n_, Preconditioner<T>{raw(A.diag), raw(A.values), kind, raw(pinv_)});
  report.factorize_seconds = std::chrono::duration<double>(Clock::now() - t0).count();
  if (bad > 0) {
    report.converged = false;
    report.message = "cusparse_pcg: " + std::to_string(bad) +
                     " diagonal blocks of the system are not positive definite, so A is not SPD (the "
                     "preconditioner needs them). Fix: clamp compressed springs / project the Jacobian to PSD, or "
                     "reduce dt.";
    return false;
  }
  return true;
}

template <class T>
SolveReport DevicePcg<T>::solve(const DeviceBsr<T>& A, const DeviceFilter<T>& S, const DVec<T>& b, const DVec<T>& z,
                                DVec<T>& dv) {
  const auto t0 = Clock::now();
  SolveReport rep;
  if (A.n != n_) analyze(A.n);
  const Index n = n_;
  const Index N = 3 * n;
  // dv <- S dv + z (warm start on the free DOFs, prescribed values on the constrained ones).
  parallel_for(S.num_constrained, AddPrescribed<T>{raw(S.constrained), raw(S.free), raw(S.proj), raw(z), raw(dv)});
  // bh = S (b - A z) (in c_ for now); delta0 = bh . Pm^-1 bh.
  const T bh2 = filtered_residual(A, S, b, z, t_, c_);
  const T delta0 = reduce_sum<T>(n, PrecondDot<T>{raw(pinv_), raw(c_), raw(s_)});
  filtered_residual(A, S, b, dv, t_, r_);
  T delta = reduce_sum<T>(n, PrecondDot<T>{raw(pinv_), raw(r_), raw(s_)});
  parallel_for(n, Direction<T>{raw(S.free), raw(S.proj), raw(s_), T(0), raw(c_)});
  const T eps2 = static_cast<T>(opt_.tolerance * opt_.tolerance);
  int it = 0;
  bool ok = true;
  while (delta > eps2 * delta0 && it < opt_.max_iterations) {
    A.multiply(raw(c_), raw(q_));
    filter(S, q_);
    const T cq = dot(c_, q_);
    if (!(cq > T(0))) {
      ok = false;
      char buf[200];
      std::snprintf(buf, sizeof buf,
                    "cusparse_pcg: c^T A c = %.3g is not positive at iteration %d: A is not positive definite on the "
                    "free DOFs. Fix: clamp compressed springs / PSD projection, or reduce dt.",
                    static_cast<double>(cq), it);
      rep.message = buf;
      break;
    }
    const T alpha = delta / cq;
    const T dnew = reduce_sum<T>(n, Update<T>{raw(pinv_), raw(c_), raw(q_), alpha, raw(dv), raw(r_), raw(s_)});
    const T beta = dnew / delta;
    delta = dnew;
    parallel_for(n, Direction<T>{raw(S.free), raw(S.proj), raw(s_), beta, raw(c_)});
    ++it;
  }
  rep.iterations = it;
  // True relative residual |S(b - A dv)| / |S(b - A z)|.
  const T rr = filtered_residual(A, S, b, dv, t_, q_);
  rep.residual = bh2 > T(0) ? std::sqrt(static_cast<double>(rr) / static_cast<double>(bh2))
                            : std::sqrt(static_cast<double>(rr));
  rep.converged = ok && delta <= eps2 * delta0;
  if (ok && !rep.converged) {
    char buf[200];
    std::snprintf(buf, sizeof buf,
                  "cusparse_pcg: not converged after %d iterations (relative residual %.3g, tolerance %.3g). Fix: "
                  "raise max_iterations, relax tolerance or reduce dt.",
                  it, rep.residual, opt_.tolerance);
    rep.message = buf;
  }
  (void)N;
  rep.solve_seconds = std::chrono::duration<double>(Clock::now() - t0).count();
  return rep;
}

template class DevicePcg<double>;
template class DevicePcg<float>;
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
  return pcg_.factorize(A_, report);
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

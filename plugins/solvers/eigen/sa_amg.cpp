#include "sa_amg.hpp"

#include <omp.h>
#if defined(__AVX2__) && defined(__FMA__)
#include <immintrin.h>
#endif

#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <type_traits>

#include "block_row.hpp"
#include "loom/clock.hpp"
#include "loom/solver_common.hpp"

namespace loom::amg {

namespace {

using I3 = std::integral_constant<int, 3>;
using I6 = std::integral_constant<int, 6>;

// f(integral_constant<int, a>) for a in {3, 6}.
template <class F>
void with_size(int a, F&& f) {
  if (a == 3)
    f(I3{});
  else
    f(I6{});
}
template <class F>
void with_sizes(int a, int b, F&& f) {
  with_size(a, [&](auto A) { with_size(b, [&](auto B) { f(A, B); }); });
}

// y += M x, M is R x C row-major (double or float entries, double arithmetic).
template <int R, int C, class T>
inline void gemv_add(const T* M, const double* x, double* y) {
  for (int a = 0; a < R; ++a) {
    double s = 0;
    for (int c = 0; c < C; ++c) s += M[a * C + c] * x[c];
    y[a] += s;
  }
}
// y = M x
template <int R, int C, class T>
inline void gemv_set(const T* M, const double* x, double* y) {
  for (int a = 0; a < R; ++a) {
    double s = 0;
    for (int c = 0; c < C; ++c) s += M[a * C + c] * x[c];
    y[a] = s;
  }
}
// y -= M x
template <int R, int C, class T>
inline void gemv_sub(const T* M, const double* x, double* y) {
  for (int a = 0; a < R; ++a) {
    double s = 0;
    for (int c = 0; c < C; ++c) s += M[a * C + c] * x[c];
    y[a] -= s;
  }
}
// Cm += A B, A is R x K, B is K x C (row-major; Cm must not overlap A or B). Each row of Cm
// is summed in a local accumulator over k in increasing order: the same operations in the
// same order as the plain triple loop (so the same bits), but with the row in registers and
// B loaded once per row instead of being reloaded after every store to Cm, which the
// compiler had to assume might alias it (the Galerkin products are built from these).
template <int R, int K, int C>
inline void gemm_add(const double* __restrict A, const double* __restrict B, double* __restrict Cm) {
  for (int a = 0; a < R; ++a) {
    double acc[C];
    for (int c = 0; c < C; ++c) acc[c] = Cm[a * C + c];
    for (int k = 0; k < K; ++k) {
      const double s = A[a * K + k];
      for (int c = 0; c < C; ++c) acc[c] += s * B[k * C + c];
    }
    for (int c = 0; c < C; ++c) Cm[a * C + c] = acc[c];
  }
}


// The values of M in storage T: the doubles, or their float copy (sync_float()).
template <class T>
const T* values(const BlockMatrix& M) {
  if constexpr (std::is_same_v<T, float>)
    return M.f.data();
  else
    return M.v.data();
}

// acc = b_i - (A x)_i for block row i.
template <int B, class T>
inline void row_residual(const BlockMatrix& A, const double* b, const double* x, Index i, double* acc) {
  const T* val = values<T>(A);
  double ax[B];
  if constexpr (B == 6)
    block_row_multiply6(A.rp.data(), A.ci.data(), val, x, i, ax);
  else
    block_row_multiply3(A.rp.data(), A.ci.data(), val, x, i, ax);
  for (int a = 0; a < B; ++a) acc[a] = b[static_cast<std::size_t>(B) * i + a] - ax[a];
}

// out = sum over blocks k0 <= k < k1 of A_k x_col(k) (a contiguous part of one block row).
template <int B, class T>
inline void row_partial(const BlockMatrix& A, Index k0, Index k1, const double* x, double* out) {
  const Index range[2] = {k0, k1};
  const T* val = values<T>(A);
  if constexpr (B == 6)
    block_row_multiply6(range, A.ci.data(), val, x, 0, out);
  else
    block_row_multiply3(range, A.ci.data(), val, x, 0, out);
}

// Lower Cholesky factor L (row-major, upper part zero) of a B x B SPD block; false when it is
// not (numerically) positive definite.
template <int B>
bool cholesky(const double* A, double* L) {
  for (int e = 0; e < B * B; ++e) L[e] = 0;
  for (int j = 0; j < B; ++j) {
    double d = A[j * B + j];
    for (int k = 0; k < j; ++k) d -= L[j * B + k] * L[j * B + k];
    if (!(d > 0) || !std::isfinite(d)) return false;
    const double ljj = std::sqrt(d);
    L[j * B + j] = ljj;
    for (int i = j + 1; i < B; ++i) {
      double s = 0.5 * (A[i * B + j] + A[j * B + i]);
      for (int k = 0; k < j; ++k) s -= L[i * B + k] * L[j * B + k];
      L[i * B + j] = s / ljj;
    }
  }
  return true;
}

// Inverse of a B x B SPD matrix by Cholesky; false when it is not (numerically) SPD.
template <int B>
bool spd_inverse(const double* A, double* Ainv) {
  double L[B * B];
  if (!cholesky<B>(A, L)) return false;
  // W = L^-1 (lower triangular), Ainv = W^T W.
  double W[B * B] = {};
  for (int c = 0; c < B; ++c) {
    for (int i = c; i < B; ++i) {
      double s = (i == c) ? 1.0 : 0.0;
      for (int k = c; k < i; ++k) s -= L[i * B + k] * W[k * B + c];
      W[i * B + c] = s / L[i * B + i];
    }
  }
  for (int i = 0; i < B; ++i)
    for (int j = 0; j < B; ++j) {
      double s = 0;
      for (int k = std::max(i, j); k < B; ++k) s += W[k * B + i] * W[k * B + j];
      Ainv[i * B + j] = s;
    }
  return true;
}

// |LI^-1 M LJ^-T|_F for a B x B block M and lower Cholesky factors LI, LJ.
template <int B>
double scaled_frobenius(const double* LI, const double* M, const double* LJ) {
  double X[B * B];
  for (int c = 0; c < B; ++c)  // X = LI^-1 M, column by column
    for (int a = 0; a < B; ++a) {
      double s = M[a * B + c];
      for (int k = 0; k < a; ++k) s -= LI[a * B + k] * X[k * B + c];
      X[a * B + c] = s / LI[a * B + a];
    }
  double f = 0;
  for (int a = 0; a < B; ++a) {  // row a of X LJ^-T is (LJ^-1 x_a)^T
    double y[B];
    for (int c = 0; c < B; ++c) {
      double s = X[a * B + c];
      for (int k = 0; k < c; ++k) s -= LJ[c * B + k] * y[k];
      y[c] = s / LJ[c * B + c];
      f += y[c] * y[c];
    }
  }
  return std::sqrt(f);
}

double since(Clock::time_point t0) { return seconds_since(t0); }  // the one clock (loom/clock.hpp)
// Adds the scope's duration to `total` (every return path of setup()).
struct ScopeTimer {
  double& total;
  Clock::time_point t0 = Clock::now();
  ~ScopeTimer() { total += since(t0); }
};

double frob(const double* b, std::size_t n) {
  double s = 0;
  for (std::size_t k = 0; k < n; ++k) s += b[k] * b[k];
  return std::sqrt(s);
}

}  // namespace

double SaAmg::operator_complexity() const {
  if (L_.empty()) return 0;
  double total = 0;
  for (const Level& L : L_) total += static_cast<double>(L.A.nnz()) * static_cast<double>(L.A.bsize());
  return total / (static_cast<double>(L_[0].A.nnz()) * 9.0);
}

void SaAmg::fill_level0(const BsrMatrix& A, const Filter& S) {
  Level& L = L_[0];
  const BsrPattern& P = A.pattern();
  const Index n = P.n;
#pragma omp parallel for schedule(static) if (parallel(L))
  for (Index i = 0; i < n; ++i)
    for (Index k = P.row_ptr[i]; k < P.row_ptr[i + 1]; ++k) solver::projected_block(S, i, P.col[k], A.block(k), L.A.block(k));
}

// Level 0's diagonal blocks += S_i E_ii S_i (E_ii positive semidefinite, so the blocks stay
// positive definite and A~ + blockdiag(S E S) symmetric positive definite).
void SaAmg::add_extra_diagonal(const Filter& S, std::span<const double> E) {
  Level& L = L_[0];
  const Index n = L.A.rows;
#pragma omp parallel for schedule(static) if (parallel(L))
  for (Index i = 0; i < n; ++i) {
    const int f = S.free_dofs(i);
    if (f == 0) continue;
    const double* Ei = E.data() + 9 * static_cast<std::size_t>(i);
    double* D = L.A.block(L.diag[i]);
    if (f == 3) {
      for (int e = 0; e < 9; ++e) D[e] += Ei[e];
    } else {
      double t[9];
      kernels::mat3_project(S.projector(i).data(), Ei, S.projector(i).data(), t);
      for (int e = 0; e < 9; ++e) D[e] += t[e];
    }
  }
}

bool SaAmg::refresh_level0_diagonal(const BsrMatrix& A, const Filter& S, std::span<const double> extra_diagonal,
                                    std::string& message) {
  if (!set_up_for(A, S)) throw std::logic_error("sa_amg: refresh_level0_diagonal() needs the last setup's A and S");
  if (!extra_diagonal.empty() && extra_diagonal.size() != 9 * static_cast<std::size_t>(A.rows()))
    throw std::invalid_argument("sa_amg: the extra diagonal blocks do not match the matrix");
  ++t_.setups;
  const ScopeTimer timer{t_.setup};
  Level& L = L_[0];
  const Index n = L.A.rows;
  const BsrPattern& P = A.pattern();
#pragma omp parallel for schedule(static) if (parallel(L))
  for (Index i = 0; i < n; ++i) solver::projected_block(S, i, i, A.block(P.diag[i]), L.A.block(L.diag[i]));
  if (!extra_diagonal.empty()) add_extra_diagonal(S, extra_diagonal);
  if (!invert_diagonal(0, message)) {
    built_ = false;
    return false;
  }
  sync_float(true, false);
  return true;
}

bool SaAmg::invert_diagonal(std::size_t l, std::string& message) {
  Level& L = L_[l];
  const Index n = L.A.rows;
  const int b = L.A.br;
  L.dinv.resize(static_cast<std::size_t>(n) * b * b);
  Index bad = n;
  with_size(b, [&](auto Bc) {
    constexpr int B = decltype(Bc)::value;
#pragma omp parallel for schedule(static) reduction(min : bad) if (parallel(L))
    for (Index i = 0; i < n; ++i)
      if (!spd_inverse<B>(L.A.block(L.diag[i]), L.dinv.data() + static_cast<std::size_t>(B * B) * i)) bad = std::min(bad, i);
  });
  if (bad < n) {
    char buf[256];
    std::snprintf(buf, sizeof buf, "sa_amg: diagonal block %d of level %zu is not positive definite", bad, l);
    message = std::string(buf) +
              (l == 0 ? " (that vertex's block of S A S), so the system matrix is not positive definite on the free DOFs"
                      : " (the Galerkin product of an indefinite matrix)") +
              "; reduce integrator.dt, enable the material's Jacobian clamp, or set integrator.on_solver_failure: "
              "halve_step";
    return false;
  }
  return true;
}

// Strength graph on the level's values, then the three aggregation phases of Vanek, Mandel
// & Brezina (1996): (1) a node whose strong neighbours are all free seeds an aggregate with
// them, (2) a node left over joins the phase-1 aggregate it is most strongly connected to,
// (3) what is still left forms aggregates with its free strong neighbours. Nodes without
// strong neighbours (fully constrained vertices, whose rows of A~ are the identity) stay out
// of every aggregate: the smoother alone handles them.
void SaAmg::aggregate(std::size_t l) {
  Level& L = L_[l];
  const Index n = L.A.rows;
  const std::size_t bs = L.A.bsize();
  std::vector<double> dnorm(n);
  for (Index i = 0; i < n; ++i) dnorm[i] = frob(L.A.block(L.diag[i]), bs);
  std::vector<Index> sp(n + 1, 0), sc;
  std::vector<double> sw;
  const double th = o_.strength_threshold;
  for (Index i = 0; i < n; ++i) {
    for (Index k = L.A.rp[i]; k < L.A.rp[i + 1]; ++k) {
      const Index j = L.A.ci[k];
      if (j == i) continue;
      const double s = frob(L.A.block(k), bs);
      if (s > 0 && s > th * std::sqrt(dnorm[i] * dnorm[j])) {
        sc.push_back(j);
        sw.push_back(s / std::sqrt(dnorm[i] * dnorm[j]));
      }
    }
    sp[i + 1] = static_cast<Index>(sc.size());
  }
  if (static_cast<int>(l) < o_.aggressive_levels) {
    // Distance-2 graph: j is a neighbour of i when a strong path i - k - j exists; its weight
    // is the strongest such path (the product of the two weights), a direct edge counts too.
    std::vector<Index> sp2(n + 1, 0), sc2;
    std::vector<double> sw2;
    std::vector<Index> pos(n, -1);
    for (Index i = 0; i < n; ++i) {
      const std::size_t start = sc2.size();
      auto add = [&](Index j, double w) {
        if (j == i) return;
        if (pos[j] < static_cast<Index>(start) || pos[j] >= static_cast<Index>(sc2.size()) || sc2[pos[j]] != j) {
          pos[j] = static_cast<Index>(sc2.size());
          sc2.push_back(j);
          sw2.push_back(w);
        } else {
          sw2[pos[j]] = std::max(sw2[pos[j]], w);
        }
      };
      for (Index k = sp[i]; k < sp[i + 1]; ++k) {
        add(sc[k], sw[k]);
        for (Index q = sp[sc[k]]; q < sp[sc[k] + 1]; ++q) add(sc[q], sw[k] * sw[q]);
      }
      sp2[i + 1] = static_cast<Index>(sc2.size());
    }
    sp = std::move(sp2);
    sc = std::move(sc2);
    sw = std::move(sw2);
  }
  std::vector<Index> agg(n, -1);
  Index na = 0;
  for (Index i = 0; i < n; ++i) {
    if (agg[i] >= 0 || sp[i] == sp[i + 1]) continue;
    bool free = true;
    for (Index k = sp[i]; k < sp[i + 1] && free; ++k) free = agg[sc[k]] < 0;
    if (!free) continue;
    agg[i] = na;
    for (Index k = sp[i]; k < sp[i + 1]; ++k) agg[sc[k]] = na;
    ++na;
  }
  const std::vector<Index> agg1 = agg;
  for (Index i = 0; i < n; ++i) {
    if (agg[i] >= 0) continue;
    double best = -1;
    for (Index k = sp[i]; k < sp[i + 1]; ++k)
      if (agg1[sc[k]] >= 0 && sw[k] > best) {
        best = sw[k];
        agg[i] = agg1[sc[k]];
      }
  }
  for (Index i = 0; i < n; ++i) {
    if (agg[i] >= 0 || sp[i] == sp[i + 1]) continue;
    agg[i] = na;
    for (Index k = sp[i]; k < sp[i + 1]; ++k)
      if (agg[sc[k]] < 0) agg[sc[k]] = na;
    ++na;
  }
  L.agg = std::move(agg);
}

// Gauss-Seidel schedule: the rows are cut into `parts` contiguous ranges (8 when the level
// is large enough to run threaded, else 1). A row whose neighbours all lie in its own range
// is interior: the interior rows of different ranges are never coupled, so the ranges are
// swept lexicographically in parallel (lexicographic Gauss-Seidel smooths better than a
// multicolour one: 28 vs 35 iterations on the 128^2 wool hang). The remaining boundary rows
// are greedily coloured and swept colour by colour afterwards.
void SaAmg::colour(std::size_t l) {
  Level& L = L_[l];
  const Index n = L.A.rows;
  const Index dofs = static_cast<Index>(n) * L.A.br;
  int parts = 1;
  if (dofs >= o_.parallel_min_dofs)
    parts = o_.min_part_dofs <= 0 ? 8 : static_cast<int>(std::clamp<Index>(dofs / o_.min_part_dofs, 2, 8));
  auto part = [&](Index i) { return static_cast<int>(static_cast<long long>(i) * parts / n); };
  std::vector<char> boundary(n, 0);
  for (Index i = 0; i < n; ++i)
    for (Index k = L.A.rp[i]; k < L.A.rp[i + 1]; ++k)
      if (part(L.A.ci[k]) != part(i)) boundary[i] = 1;
  L.clean.assign(n, 1);
  for (Index i = 0; i < n; ++i)
    for (Index k = L.A.rp[i]; k < L.A.rp[i + 1]; ++k)
      if (boundary[L.A.ci[k]]) L.clean[i] = 0;
  L.part_ptr.assign(static_cast<std::size_t>(parts) + 1, 0);
  L.part_rows.clear();
  for (int p = 0; p < parts; ++p) {
    for (Index i = 0; i < n; ++i)
      if (!boundary[i] && part(i) == p) L.part_rows.push_back(i);
    L.part_ptr[p + 1] = static_cast<Index>(L.part_rows.size());
  }
  std::vector<int> c(n, -1), seen;
  int nc = 0;
  for (Index i = 0; i < n; ++i) {
    if (!boundary[i]) continue;
    seen.assign(static_cast<std::size_t>(nc) + 1, 0);
    for (Index k = L.A.rp[i]; k < L.A.rp[i + 1]; ++k) {
      const int cj = c[L.A.ci[k]];
      if (cj >= 0) seen[cj] = 1;
    }
    int ci = 0;
    while (seen[ci]) ++ci;
    c[i] = ci;
    nc = std::max(nc, ci + 1);
  }
  L.colour_ptr.assign(static_cast<std::size_t>(nc) + 1, 0);
  for (Index i = 0; i < n; ++i)
    if (c[i] >= 0) ++L.colour_ptr[c[i] + 1];
  for (int k = 0; k < nc; ++k) L.colour_ptr[k + 1] += L.colour_ptr[k];
  L.colour_rows.resize(L.colour_ptr[nc]);
  std::vector<Index> fill(L.colour_ptr.begin(), L.colour_ptr.end() - 1);
  for (Index i = 0; i < n; ++i)
    if (c[i] >= 0) L.colour_rows[fill[c[i]]++] = i;
}

// Patterns of P (row i: the aggregates of i's neighbours), R = P^T, A P and P^T A P; the
// next level is appended with the Galerkin pattern.
void SaAmg::build_patterns(std::size_t l) {
  Index nc = 0;
  for (Index a : L_[l].agg) nc = std::max(nc, a + 1);
  Level& L = L_[l];
  const Index n = L.A.rows;
  const int b = L.A.br, m = m_;
  std::vector<Index> mark(nc, -1);
  auto sorted_union = [&](BlockMatrix& M, Index rows, auto&& each_row) {
    M.rp.assign(static_cast<std::size_t>(rows) + 1, 0);
    M.ci.clear();
    for (Index i = 0; i < rows; ++i) {
      const std::size_t start = M.ci.size();
      each_row(i, [&](Index j) {
        if (mark[j] != i) {
          mark[j] = i;
          M.ci.push_back(j);
        }
      });
      std::sort(M.ci.begin() + static_cast<std::ptrdiff_t>(start), M.ci.end());
      M.rp[i + 1] = static_cast<Index>(M.ci.size());
    }
  };
  // P
  L.P.rows = n;
  L.P.cols = nc;
  L.P.br = b;
  L.P.bc = m;
  sorted_union(L.P, n, [&](Index i, auto&& add) {
    for (Index k = L.A.rp[i]; k < L.A.rp[i + 1]; ++k)
      if (L.agg[L.A.ci[k]] >= 0) add(L.agg[L.A.ci[k]]);
  });
  L.P.v.assign(L.P.ci.size() * L.P.bsize(), 0.0);
  // R = P^T
  L.R.rows = nc;
  L.R.cols = n;
  L.R.br = m;
  L.R.bc = b;
  L.R.rp.assign(static_cast<std::size_t>(nc) + 1, 0);
  for (Index J : L.P.ci) ++L.R.rp[J + 1];
  for (Index J = 0; J < nc; ++J) L.R.rp[J + 1] += L.R.rp[J];
  L.R.ci.resize(L.P.ci.size());
  L.r_from_p.resize(L.P.ci.size());
  {
    std::vector<Index> fill(L.R.rp.begin(), L.R.rp.end() - 1);
    for (Index i = 0; i < n; ++i)
      for (Index k = L.P.rp[i]; k < L.P.rp[i + 1]; ++k) {
        const Index q = fill[L.P.ci[k]]++;
        L.R.ci[q] = i;
        L.r_from_p[q] = k;
      }
  }
  L.R.v.assign(L.R.ci.size() * L.R.bsize(), 0.0);
  // A P
  std::fill(mark.begin(), mark.end(), -1);
  L.AP.rows = n;
  L.AP.cols = nc;
  L.AP.br = b;
  L.AP.bc = m;
  sorted_union(L.AP, n, [&](Index i, auto&& add) {
    for (Index k = L.A.rp[i]; k < L.A.rp[i + 1]; ++k) {
      const Index j = L.A.ci[k];
      for (Index q = L.P.rp[j]; q < L.P.rp[j + 1]; ++q) add(L.P.ci[q]);
    }
  });
  L.AP.v.assign(L.AP.ci.size() * L.AP.bsize(), 0.0);
  // P^T A P
  Level C;
  std::fill(mark.begin(), mark.end(), -1);
  C.A.rows = C.A.cols = nc;
  C.A.br = C.A.bc = m;
  sorted_union(C.A, nc, [&](Index I, auto&& add) {
    for (Index k = L.R.rp[I]; k < L.R.rp[I + 1]; ++k) {
      const Index i = L.R.ci[k];
      for (Index q = L.AP.rp[i]; q < L.AP.rp[i + 1]; ++q) add(L.AP.ci[q]);
    }
  });
  C.A.v.assign(C.A.ci.size() * C.A.bsize(), 0.0);
  C.diag.resize(nc);
  for (Index I = 0; I < nc; ++I) {
    C.diag[I] = -1;
    for (Index k = C.A.rp[I]; k < C.A.rp[I + 1]; ++k)
      if (C.A.ci[k] == I) C.diag[I] = k;
  }
  // The Galerkin pattern is symmetric (A's is): position of each block's transpose.
  C.trans.assign(C.A.ci.begin(), C.A.ci.end());  // (sized like ci; overwritten below)
  for (Index I = 0; I < nc; ++I)
    for (Index k = C.A.rp[I]; k < C.A.rp[I + 1]; ++k) {
      const Index J = C.A.ci[k];
      const auto b = C.A.ci.begin() + C.A.rp[J], e = C.A.ci.begin() + C.A.rp[J + 1];
      C.trans[k] = static_cast<Index>(std::lower_bound(b, e, I) - C.A.ci.begin());
    }
  C.B.assign(static_cast<std::size_t>(nc) * m * m, 0.0);
  C.dead.assign(static_cast<std::size_t>(nc) * m, 0);
  C.x.assign(static_cast<std::size_t>(nc) * m, 0.0);
  C.b.assign(static_cast<std::size_t>(nc) * m, 0.0);
  C.r.assign(static_cast<std::size_t>(nc) * m, 0.0);
  L.T.assign(static_cast<std::size_t>(n) * b * m, 0.0);
  if (o_.coarse_drop_tolerance > 0) {
    // The Galerkin product goes to G; A gets its pattern after the first product (drop_weak).
    C.G = C.A;
    C.g_diag = C.diag;
    C.g_trans = C.trans;
    C.a_from_g.clear();
  }
  L_.push_back(std::move(C));
}

// Rigid-body modes of each aggregate about its centroid, rows filtered by S_i (constraint-
// aware near-null space: the coarse space lies in range(S)).
void SaAmg::near_null_level0(const Filter& S, std::span<const double> x) {
  Level& L = L_[0];
  const Index n = L.A.rows;
  const int m = m_;
  Index na = 0;
  for (Index a : L.agg) na = std::max(na, a + 1);
  std::vector<double>& cen = centroid_;
  cen.assign(4 * static_cast<std::size_t>(na), 0.0);
  if (m == 6)
    for (Index i = 0; i < n; ++i) {
      const Index a = L.agg[i];
      if (a < 0) continue;
      for (int c = 0; c < 3; ++c) cen[4 * a + c] += x[3 * i + c];
      cen[4 * a + 3] += 1;
    }
  L.B.assign(static_cast<std::size_t>(n) * 3 * m, 0.0);
  for (Index i = 0; i < n; ++i) {
    double* Bi = L.B.data() + static_cast<std::size_t>(3 * m) * i;
    for (int a = 0; a < 3; ++a) Bi[a * m + a] = 1.0;
    const Index g = L.agg[i];
    if (m == 6 && g >= 0) {
      const double w = 1.0 / cen[4 * g + 3];
      const double dx = x[3 * i] - w * cen[4 * g], dy = x[3 * i + 1] - w * cen[4 * g + 1],
                   dz = x[3 * i + 2] - w * cen[4 * g + 2];
      // rotations about x, y, z: omega x d
      Bi[0 * m + 3] = 0;
      Bi[1 * m + 3] = -dz;
      Bi[2 * m + 3] = dy;
      Bi[0 * m + 4] = dz;
      Bi[1 * m + 4] = 0;
      Bi[2 * m + 4] = -dx;
      Bi[0 * m + 5] = -dy;
      Bi[1 * m + 5] = dx;
      Bi[2 * m + 5] = 0;
    }
    const int f = S.free_dofs(i);
    if (f == 3) continue;
    if (f == 0) {
      std::fill(Bi, Bi + 3 * m, 0.0);
      continue;
    }
    const double* Sp = S.projector(i).data();
    for (int c = 0; c < m; ++c) {
      const double v[3] = {Bi[c], Bi[m + c], Bi[2 * m + c]};
      for (int a = 0; a < 3; ++a) Bi[a * m + c] = Sp[3 * a] * v[0] + Sp[3 * a + 1] * v[1] + Sp[3 * a + 2] * v[2];
    }
  }
}

// Tentative prolongator: per aggregate a thin QR (modified Gram-Schmidt, twice) of the rows
// of B; Q's rows become T, R becomes the next level's near-null space. A column that is
// (numerically) dependent is dropped: its column of T is zero and the coarse DOF is marked
// dead (its row and column of the coarse matrix are zero; the Galerkin step puts 1 on its
// diagonal, as the filter does for constrained DOFs).
void SaAmg::tentative(std::size_t l) {
  Level& L = L_[l];
  Level& C = L_[l + 1];
  const int b = L.A.br, m = m_;
  const Index nc = C.A.rows;
  const std::size_t tb = static_cast<std::size_t>(b) * m;
  std::copy(L.B.begin(), L.B.end(), L.T.begin());
  for (Index i = 0; i < L.A.rows; ++i)
    if (L.agg[i] < 0) std::fill(L.T.begin() + tb * i, L.T.begin() + tb * (i + 1), 0.0);
  const bool par = parallel(L);
#pragma omp parallel for schedule(dynamic, 64) if (par)
  for (Index J = 0; J < nc; ++J) {
    const Index* mem = L.members.data() + L.member_ptr[J];
    const Index cnt = L.member_ptr[J + 1] - L.member_ptr[J];
    double* Rj = C.B.data() + static_cast<std::size_t>(m) * m * J;
    std::fill(Rj, Rj + m * m, 0.0);
    auto col_dot = [&](int c, int d) {
      double s = 0;
      for (Index t = 0; t < cnt; ++t) {
        const double* Ti = L.T.data() + tb * mem[t];
        for (int a = 0; a < b; ++a) s += Ti[a * m + c] * Ti[a * m + d];
      }
      return s;
    };
    for (int c = 0; c < m; ++c) {
      const double n0 = std::sqrt(col_dot(c, c));
      for (int pass = 0; pass < 2; ++pass)
        for (int d = 0; d < c; ++d) {
          const double p = col_dot(c, d);
          if (p == 0) continue;
          Rj[d * m + c] += p;
          for (Index t = 0; t < cnt; ++t) {
            double* Ti = L.T.data() + tb * mem[t];
            for (int a = 0; a < b; ++a) Ti[a * m + c] -= p * Ti[a * m + d];
          }
        }
      const double nn = std::sqrt(col_dot(c, c));
      const bool dead = !(nn > 1e-8 * n0) || !(n0 > 0);
      C.dead[static_cast<std::size_t>(m) * J + c] = dead ? 1 : 0;
      const double s = dead ? 0.0 : 1.0 / nn;
      Rj[c * m + c] = dead ? 0.0 : nn;
      if (dead)
        for (int d = 0; d < c; ++d) Rj[d * m + c] = 0;
      for (Index t = 0; t < cnt; ++t) {
        double* Ti = L.T.data() + tb * mem[t];
        for (int a = 0; a < b; ++a) Ti[a * m + c] *= s;
      }
    }
  }
}

// Largest eigenvalue of D^-1 A by power iteration (for the prolongator smoother's weight):
// 12 iterations on the first build, then 3 from the previous build's vector (the matrix
// changes little from step to step).
double SaAmg::lambda_max(std::size_t l) {
  Level& L = L_[l];
  const Index n = L.A.rows;
  const int b = L.A.br;
  const std::size_t N = static_cast<std::size_t>(n) * b;
  HugeVector<double>& v = L.ev;
  HugeVector<double>& w = L.r;
  int iterations = 3;
  if (v.size() != N) {
    v.resize(N);
    for (std::size_t k = 0; k < N; ++k) v[k] = 1.0 + 0.5 * std::sin(0.7 * static_cast<double>(k) + 0.3);
    iterations = 12;
  }
  double lam = 0;
  with_size(b, [&](auto Bc) {
    constexpr int B = decltype(Bc)::value;
    for (int it = 0; it < iterations; ++it) {
      double nv = 0, nw = 0;
#pragma omp parallel for schedule(static) reduction(+ : nv, nw) if (parallel(L))
      for (Index i = 0; i < n; ++i) {
        double t[B] = {};
        for (Index k = L.A.rp[i]; k < L.A.rp[i + 1]; ++k)
          gemv_add<B, B>(L.A.block(k), v.data() + static_cast<std::size_t>(B) * L.A.ci[k], t);
        double* wi = w.data() + static_cast<std::size_t>(B) * i;
        std::fill(wi, wi + B, 0.0);
        gemv_add<B, B>(L.dinv.data() + static_cast<std::size_t>(B * B) * i, t, wi);
        for (int a = 0; a < B; ++a) {
          nv += v[B * i + a] * v[B * i + a];
          nw += wi[a] * wi[a];
        }
      }
      lam = nv > 0 ? std::sqrt(nw / nv) : 0;
      const double s = nw > 0 ? 1.0 / std::sqrt(nw) : 0;
      for (std::size_t k = 0; k < N; ++k) v[k] = w[k] * s;
    }
  });
  return lam;
}

// P = (I - omega D^-1 A) T, then R = P^T.
void SaAmg::smooth_prolongator(std::size_t l) {
  Level& L = L_[l];
  const Index n = L.A.rows;
  const double lam = lambda_max(l);
  const double omega = lam > 0 ? o_.prolongator_damping / lam : 0.0;
  with_sizes(L.A.br, m_, [&](auto Bc, auto Mc) {
    constexpr int B = decltype(Bc)::value, M = decltype(Mc)::value;
    constexpr std::size_t PB = static_cast<std::size_t>(B) * M;
#pragma omp parallel for schedule(static) if (parallel(L))
    for (Index i = 0; i < n; ++i) {
      const Index p0 = L.P.rp[i], p1 = L.P.rp[i + 1];
      std::fill(L.P.v.begin() + PB * p0, L.P.v.begin() + PB * p1, 0.0);
      for (Index k = L.A.rp[i]; k < L.A.rp[i + 1]; ++k) {
        const Index j = L.A.ci[k];
        const Index J = L.agg[j];
        if (J < 0) continue;
        Index q = p0;
        while (L.P.ci[q] != J) ++q;
        gemm_add<B, B, M>(L.A.block(k), L.T.data() + PB * j, L.P.v.data() + PB * q);
      }
      const double* Di = L.dinv.data() + static_cast<std::size_t>(B * B) * i;
      for (Index q = p0; q < p1; ++q) {
        double W[PB];
        double* Pq = L.P.v.data() + PB * q;
        std::copy(Pq, Pq + PB, W);
        std::fill(Pq, Pq + PB, 0.0);
        gemm_add<B, B, M>(Di, W, Pq);
        for (std::size_t e = 0; e < PB; ++e) Pq[e] *= -omega;
        if (L.P.ci[q] == L.agg[i])
          for (std::size_t e = 0; e < PB; ++e) Pq[e] += L.T[PB * i + e];
      }
    }
    const Index nr = L.R.nnz();
#pragma omp parallel for schedule(static) if (parallel(L))
    for (Index q = 0; q < nr; ++q) {
      const double* Pk = L.P.v.data() + PB * L.r_from_p[q];
      double* Rq = L.R.v.data() + PB * q;
      for (int a = 0; a < B; ++a)
        for (int c = 0; c < M; ++c) Rq[c * B + a] = Pk[a * M + c];
    }
  });
}

// A P, then the coarse matrix P^T A P (+ 1 on the diagonal of dead coarse DOFs).
void SaAmg::galerkin(std::size_t l) {
  Level& L = L_[l];
  Level& C = L_[l + 1];
  const Index n = L.A.rows, nc = C.A.rows;
  const int nt = std::max(1, omp_get_max_threads());
  if (static_cast<int>(marker_.size()) < nt) marker_.resize(nt);
  for (auto& mk : marker_)
    if (static_cast<Index>(mk.size()) < nc) mk.assign(nc, 0);
  // With coarse_drop_tolerance the product goes to C.G (drop_weak() then writes C.A).
  const bool to_g = !C.G.rp.empty();
  BlockMatrix& CA = to_g ? C.G : C.A;
  const std::vector<Index>& cdiag = to_g ? C.g_diag : C.diag;
  const std::vector<Index>& ctrans = to_g ? C.g_trans : C.trans;
  with_sizes(L.A.br, m_, [&](auto Bc, auto Mc) {
    constexpr int B = decltype(Bc)::value, M = decltype(Mc)::value;
    constexpr std::size_t PB = static_cast<std::size_t>(B) * M, CB = static_cast<std::size_t>(M) * M;
#pragma omp parallel if (parallel(L))
    {
      Index* mk = marker_[omp_get_thread_num()].data();
#pragma omp for schedule(static)
      for (Index i = 0; i < n; ++i) {
        const Index a0 = L.AP.rp[i], a1 = L.AP.rp[i + 1];
        for (Index q = a0; q < a1; ++q) mk[L.AP.ci[q]] = q;
        std::fill(L.AP.v.begin() + PB * a0, L.AP.v.begin() + PB * a1, 0.0);
        for (Index k = L.A.rp[i]; k < L.A.rp[i + 1]; ++k) {
          const Index j = L.A.ci[k];
          for (Index q = L.P.rp[j]; q < L.P.rp[j + 1]; ++q)
            gemm_add<B, B, M>(L.A.block(k), L.P.v.data() + PB * q, L.AP.v.data() + PB * mk[L.P.ci[q]]);
        }
      }
      // P^T A P is symmetric: the blocks on and above the diagonal (J >= I), then each block
      // below it as the transpose of its mirror (half the products; exactly symmetric).
#pragma omp for schedule(dynamic, 64)
      for (Index I = 0; I < nc; ++I) {
        const Index c0 = CA.rp[I], c1 = CA.rp[I + 1];
        for (Index q = c0; q < c1; ++q) mk[CA.ci[q]] = q;
        std::fill(CA.v.begin() + CB * c0, CA.v.begin() + CB * c1, 0.0);
        for (Index k = L.R.rp[I]; k < L.R.rp[I + 1]; ++k) {
          const Index i = L.R.ci[k];
          const double* Rk = L.R.v.data() + PB * k;
          for (Index q = L.AP.rp[i]; q < L.AP.rp[i + 1]; ++q)
            if (L.AP.ci[q] >= I) gemm_add<M, B, M>(Rk, L.AP.v.data() + PB * q, CA.v.data() + CB * mk[L.AP.ci[q]]);
        }
        double* D = CA.block(cdiag[I]);
        for (int c = 0; c < M; ++c)
          if (C.dead[static_cast<std::size_t>(M) * I + c]) D[c * M + c] += 1.0;
      }
#pragma omp for schedule(static)
      for (Index I = 0; I < nc; ++I)
        for (Index q = CA.rp[I]; q < CA.rp[I + 1]; ++q) {
          if (CA.ci[q] >= I) continue;
          const double* U = CA.v.data() + CB * ctrans[q];
          double* Lq = CA.v.data() + CB * q;
          for (int a = 0; a < M; ++a)
            for (int c = 0; c < M; ++c) Lq[a * M + c] = U[c * M + a];
        }
    }
  });
}

// coarse_drop_tolerance: level l's A from the full Galerkin product G. For a dropped pair
// (I, J), with s = |L_I^-1 G_IJ L_J^-T|_F >= its spectral norm,
//   [s G_II, -G_IJ; -G_JI, s G_JJ] = diag(L_I, L_J) [s I, -X; -X^T, s I] diag(L_I, L_J)^T
// (X = L_I^-1 G_IJ L_J^-T) is positive semidefinite, so A = G - (dropped blocks) + the
// diagonal blocks scaled by 1 + sum of s = G + (a sum of those PSD terms) is SPD whenever G is.
// The pattern (which blocks to drop: s below the tolerance) is decided on the first call.
void SaAmg::drop_weak(std::size_t l) {
  Level& C = L_[l];
  const BlockMatrix& G = C.G;
  const Index n = G.rows;
  const int b = G.br;
  const std::size_t bs = G.bsize();
  const bool par = static_cast<Index>(n) * b >= o_.parallel_min_dofs;
  C.chol.resize(bs * static_cast<std::size_t>(n));
  Index bad = n;
  with_size(b, [&](auto Bc) {
    constexpr int B = decltype(Bc)::value;
#pragma omp parallel for schedule(static) reduction(min : bad) if (par)
    for (Index I = 0; I < n; ++I)
      if (!cholesky<B>(G.block(C.g_diag[I]), C.chol.data() + bs * I)) bad = std::min(bad, I);
    if (C.a_from_g.empty()) {
      // The pattern: keep the diagonal and every block with s >= tolerance (or next to a
      // diagonal block that is not positive definite: set-up reports it below).
      std::vector<std::uint8_t> keep(static_cast<std::size_t>(G.nnz()), 1);
      std::vector<std::uint8_t> chol_ok(n, 1);
      for (Index I = 0; I < n; ++I) chol_ok[I] = cholesky<B>(G.block(C.g_diag[I]), C.chol.data() + bs * I);
      C.drop_g.clear();
      C.drop_i.clear();
      for (Index I = 0; I < n; ++I)
        for (Index q = G.rp[I]; q < G.rp[I + 1]; ++q) {
          const Index J = G.ci[q];
          if (J <= I || !chol_ok[I] || !chol_ok[J]) continue;
          const double sq = scaled_frobenius<B>(C.chol.data() + bs * I, G.block(q), C.chol.data() + bs * J);
          if (sq < o_.coarse_drop_tolerance) {
            keep[q] = keep[C.g_trans[q]] = 0;
            C.drop_g.push_back(q);
            C.drop_i.push_back(I);
          }
        }
      C.A.rp.assign(static_cast<std::size_t>(n) + 1, 0);
      C.A.ci.clear();
      C.a_from_g.clear();
      C.diag.assign(n, -1);
      for (Index I = 0; I < n; ++I) {
        for (Index q = G.rp[I]; q < G.rp[I + 1]; ++q)
          if (keep[q]) {
            if (G.ci[q] == I) C.diag[I] = static_cast<Index>(C.A.ci.size());
            C.A.ci.push_back(G.ci[q]);
            C.a_from_g.push_back(q);
          }
        C.A.rp[I + 1] = static_cast<Index>(C.A.ci.size());
      }
      C.A.v.assign(C.A.ci.size() * bs, 0.0);
      // Each row's dropped pairs (as row I and as row J).
      const std::size_t nd = C.drop_g.size();
      C.drop_ptr.assign(static_cast<std::size_t>(n) + 1, 0);
      for (std::size_t d = 0; d < nd; ++d) {
        ++C.drop_ptr[C.drop_i[d] + 1];
        ++C.drop_ptr[G.ci[C.drop_g[d]] + 1];
      }
      for (Index I = 0; I < n; ++I) C.drop_ptr[I + 1] += C.drop_ptr[I];
      C.drop_idx.resize(2 * nd);
      std::vector<Index> fill(C.drop_ptr.begin(), C.drop_ptr.end() - 1);
      for (std::size_t d = 0; d < nd; ++d) {
        C.drop_idx[fill[C.drop_i[d]]++] = static_cast<Index>(d);
        C.drop_idx[fill[G.ci[C.drop_g[d]]]++] = static_cast<Index>(d);
      }
      C.drop_s.assign(nd, 0.0);
    }
    const Index nd = static_cast<Index>(C.drop_g.size());
    const Index na = C.A.nnz();
#pragma omp parallel if (par)
    {
#pragma omp for schedule(static)
      for (Index d = 0; d < nd; ++d) {
        const Index I = C.drop_i[d], q = C.drop_g[d], J = G.ci[q];
        C.drop_s[d] = bad < n ? 0.0 : scaled_frobenius<B>(C.chol.data() + bs * I, G.block(q), C.chol.data() + bs * J);
      }
#pragma omp for schedule(static)
      for (Index k = 0; k < na; ++k) std::copy_n(G.block(C.a_from_g[k]), bs, C.A.block(k));
#pragma omp for schedule(static)
      for (Index I = 0; I < n; ++I) {
        double s = 1.0;
        for (Index t = C.drop_ptr[I]; t < C.drop_ptr[I + 1]; ++t) s += C.drop_s[C.drop_idx[t]];
        double* D = C.A.block(C.diag[I]);
        for (std::size_t e = 0; e < bs; ++e) D[e] *= s;
      }
    }
  });
}

bool SaAmg::factor_coarsest(std::string& message) {
  Level& C = L_.back();
  const Index N = C.A.rows * C.A.br;
  coarse_direct_ = N <= 4000;
  if (!coarse_direct_) return true;  // symmetric Gauss-Seidel sweeps instead (set up in build)
  coarse_.setZero(N, N);
  const int b = C.A.br;
  for (Index i = 0; i < C.A.rows; ++i)
    for (Index k = C.A.rp[i]; k < C.A.rp[i + 1]; ++k) {
      const double* Bk = C.A.block(k);
      for (int a = 0; a < b; ++a)
        for (int c = 0; c < b; ++c) coarse_(b * i + a, b * C.A.ci[k] + c) = Bk[a * b + c];
    }
  llt_.compute(coarse_);
  if (llt_.info() != Eigen::Success) {
    message = "sa_amg: the coarsest matrix (" + std::to_string(N) +
              " DOFs) is not positive definite, so the system matrix is not positive definite on the free DOFs; "
              "reduce integrator.dt, enable the material's Jacobian clamp, or set integrator.on_solver_failure: "
              "halve_step";
    return false;
  }
  return true;
}

void SaAmg::sync_float(bool level0_only, bool transfers) {
  if (!o_.float_storage) return;
  auto copy = [&](BlockMatrix& M, bool par) {
    const std::ptrdiff_t N = static_cast<std::ptrdiff_t>(M.v.size());
    M.f.resize(M.v.size());
#pragma omp parallel for schedule(static) if (par)
    for (std::ptrdiff_t k = 0; k < N; ++k) M.f[k] = static_cast<float>(M.v[k]);
  };
  for (std::size_t l = 0; l < L_.size(); ++l) {
    Level& L = L_[l];
    copy(L.A, parallel(L));
    // The diagonal inverses, symmetrised then rounded: the backward sweep stays the exact
    // adjoint of the forward one (NUMERICS.md 3.6).
    const int b = L.A.br;
    const Index n = o_.float_diagonal ? L.A.rows : 0;
    L.dinv_f.resize(o_.float_diagonal ? L.dinv.size() : 0);
#pragma omp parallel for schedule(static) if (parallel(L))
    for (Index i = 0; i < n; ++i) {
      const double* D = L.dinv.data() + static_cast<std::size_t>(b * b) * i;
      float* F = L.dinv_f.data() + static_cast<std::size_t>(b * b) * i;
      for (int a = 0; a < b; ++a)
        for (int c = 0; c < b; ++c) F[a * b + c] = static_cast<float>(0.5 * (D[a * b + c] + D[c * b + a]));
    }
    if (level0_only) break;
    // P and R change only when the prolongator is rebuilt (prolongator_refresh_steps): their
    // float copies are written then, not at every refresh (about 75 MB of reads and writes
    // per step at 256^2).
    if (transfers && l + 1 < L_.size()) {
      copy(L.P, parallel(L));
      copy(L.R, parallel(L));
      // Level 0's rigid-body transfers in half: R's values are the rounded values of P's
      // (r_from_p), so R stays the exact transpose of the rounded P.
      const bool half = l == 0 && o_.half_transfers && L.A.br == 3 && L.P.bc == 6;
      L.P.h.resize(half ? L.P.v.size() : 0);
      L.R.h.resize(half ? L.R.v.size() : 0);
      if (half) {
        const std::ptrdiff_t N = static_cast<std::ptrdiff_t>(L.P.v.size());
#pragma omp parallel for schedule(static) if (parallel(L))
        for (std::ptrdiff_t k = 0; k < N; ++k) L.P.h[k] = float_to_half(L.P.f[k]);
        const Index nr = L.R.nnz();
#pragma omp parallel for schedule(static) if (parallel(L))
        for (Index k = 0; k < nr; ++k) {
          const Half* src = L.P.h.data() + 18 * static_cast<std::size_t>(L.r_from_p[k]);
          Half* dst = L.R.h.data() + 18 * static_cast<std::size_t>(k);
          for (int a = 0; a < 3; ++a)
            for (int c = 0; c < 6; ++c) dst[3 * c + a] = src[6 * a + c];  // R block (6x3) = P block (3x6) transposed
        }
      }
    }
  }
}

double SaAmg::half_transfer_error() const {
  if (L_.empty() || L_[0].P.h.empty()) return 0;
  const BlockMatrix& P = L_[0].P;
  double d = 0, n = 0;
  for (std::size_t k = 0; k < P.v.size(); ++k) {
    const double e = widen(P.h[k]) - P.v[k];
    d += e * e;
    n += P.v[k] * P.v[k];
  }
  return n > 0 ? std::sqrt(d / n) : 0;
}

bool SaAmg::filter_changed(const Filter& S) const {
  if (S.constrained() != s_constrained_) return true;
  std::size_t o = 0;
  for (Index i : S.constrained()) {
    const auto& p = S.projector(i);
    for (int e = 0; e < 9; ++e)
      if (p[e] != s_proj_[o + e]) return true;
    o += 9;
  }
  return false;
}

void SaAmg::remember_filter(const Filter& S) {
  s_constrained_ = S.constrained();
  s_proj_.resize(9 * s_constrained_.size());
  std::size_t o = 0;
  for (Index i : S.constrained()) {
    const auto& p = S.projector(i);
    std::copy(p.begin(), p.end(), s_proj_.begin() + o);
    o += 9;
  }
}

bool SaAmg::setup(const BsrMatrix& A, const Filter& S, std::span<const double> x, std::string& message,
                  std::span<const double> extra_diagonal) {
  if (!extra_diagonal.empty() && extra_diagonal.size() != 9 * static_cast<std::size_t>(A.rows()))
    throw std::invalid_argument("sa_amg: the extra diagonal blocks do not match the matrix");
  const bool coords = !x.empty() && o_.near_null_modes == 6;
  if (!x.empty() && x.size() != 3 * static_cast<std::size_t>(A.rows()))
    throw std::invalid_argument("sa_amg: the coordinates do not match the matrix");
  const bool rebuild = !built_ || pattern_ != &A.pattern() || pattern_nnz_ != A.pattern().nnz_blocks() ||
                       L_.empty() || L_[0].A.rows != A.rows() || coords != had_coordinates_;
  ++refreshes_;
  ++t_.setups;
  const ScopeTimer timer{t_.setup};
  const HugePageScope pages(o_.huge_pages);  // every allocation of the hierarchy happens in setup()
  if (rebuild) {
    built_ = false;
    pattern_ = &A.pattern();
    pattern_nnz_ = A.pattern().nnz_blocks();
    had_coordinates_ = coords;
    m_ = coords ? 6 : 3;
    L_.clear();
    L_.emplace_back();
    Level& L0 = L_[0];
    const BsrPattern& P = A.pattern();
    L0.A.rows = L0.A.cols = P.n;
    L0.A.br = L0.A.bc = 3;
    L0.A.rp = P.row_ptr;
    L0.A.ci.assign(P.col.begin(), P.col.end());
    L0.A.v.assign(9 * static_cast<std::size_t>(P.nnz_blocks()), 0.0);
    L0.diag = P.diag;
    L0.x.assign(3 * static_cast<std::size_t>(P.n), 0.0);
    L0.b = L0.x;
    L0.r = L0.x;
  }
  const bool s_changed = !rebuild && filter_changed(S);
  fill_level0(A, S);
  const bool extra = !extra_diagonal.empty();
  if (!rebuild && !s_changed && since_hierarchy_ + 1 < o_.hierarchy_refresh_steps) {
    // Frozen coarse levels: only the smoother of level 0 follows the new matrix.
    ++since_hierarchy_;
    if (extra) add_extra_diagonal(S, extra_diagonal);
    if (!invert_diagonal(0, message)) {
      built_ = false;
      return false;
    }
    sync_float(true, false);
    return true;
  }
  since_hierarchy_ = 0;
  ++hierarchy_builds_;
  const bool new_p = rebuild || s_changed || since_prolongator_ + 1 >= o_.prolongator_refresh_steps;
  if (extra && o_.extra_on_coarse_levels) add_extra_diagonal(S, extra_diagonal);
  for (std::size_t l = 0;; ++l) {
    if (!invert_diagonal(l, message)) {
      built_ = false;
      return false;
    }
    if (rebuild) {
      const Level& L = L_[l];
      bool last = static_cast<Index>(L.A.rows) * L.A.br <= o_.coarse_dofs || static_cast<int>(l) + 1 >= o_.max_levels;
      if (!last) {
        aggregate(l);
        Index na = 0;
        for (Index a : L_[l].agg) na = std::max(na, a + 1);
        last = na == 0 || static_cast<double>(na) * m_ >= 0.9 * static_cast<double>(L.A.rows) * L.A.br;
        if (!last) {
          Level& Lm = L_[l];
          Lm.member_ptr.assign(static_cast<std::size_t>(na) + 1, 0);
          for (Index a : Lm.agg)
            if (a >= 0) ++Lm.member_ptr[a + 1];
          for (Index a = 0; a < na; ++a) Lm.member_ptr[a + 1] += Lm.member_ptr[a];
          Lm.members.resize(Lm.member_ptr[na]);
          std::vector<Index> fill(Lm.member_ptr.begin(), Lm.member_ptr.end() - 1);
          for (Index i = 0; i < Lm.A.rows; ++i)
            if (Lm.agg[i] >= 0) Lm.members[fill[Lm.agg[i]]++] = i;
          colour(l);
          build_patterns(l);
        }
      }
      if (last) {
        L_[l].agg.clear();
        if (static_cast<Index>(L_[l].A.rows) * L_[l].A.br > 4000) colour(l);
        break;
      }
    } else if (l + 1 == L_.size()) {
      break;
    }
    if (new_p) {
      const auto tp = Clock::now();
      if (l == 0) near_null_level0(S, x);
      tentative(l);
      smooth_prolongator(l);
      t_.setup_prolongator += since(tp);
    }
    const auto tg = Clock::now();
    galerkin(l);
    if (!L_[l + 1].G.rp.empty()) drop_weak(l + 1);
    t_.setup_galerkin += since(tg);
  }
  if (new_p) {
    since_prolongator_ = 0;
    ++prolongator_builds_;
    remember_filter(S);
  } else {
    ++since_prolongator_;
  }
  if (!factor_coarsest(message)) {
    built_ = false;
    return false;
  }
  if (extra && !o_.extra_on_coarse_levels) {  // level 0 only: the coarse levels are A's
    add_extra_diagonal(S, extra_diagonal);
    if (!invert_diagonal(0, message)) {
      built_ = false;
      return false;
    }
  }
  built_ = true;
  sync_float(false, new_p);
  info_.clear();
  for (const Level& L : L_)
    info_.push_back({L.A.rows, L.A.br, L.A.nnz(),
                     L.colour_ptr.empty() ? 0 : static_cast<int>(L.colour_ptr.size()) - 1,
                     L.part_ptr.empty() ? 0 : static_cast<int>(L.part_ptr.size()) - 1, L.P.nnz(),
                     static_cast<Index>(L.colour_rows.size()),
                     static_cast<Index>(std::count(L.clean.begin(), L.clean.end(), std::uint8_t{1}))});
  return true;
}

namespace {

// One Gauss-Seidel sweep. Forward: the interior rows of every part in increasing order (the
// parts in parallel: they are not coupled), then the boundary rows colour by colour (rows of
// one colour are not coupled). Backward: exactly the reverse order. Every update is a
// sequential Gauss-Seidel step in one fixed row order, so the backward sweep is the adjoint
// of the forward one, with no races and the same result on any number of threads.
template <int B, class T, class D>
void gs_sweep(const BlockMatrix& A, const D* dinv, const std::vector<Index>& cp,
              const std::vector<Index>& cr, const std::vector<Index>& pp, const std::vector<Index>& pr,
              const double* b, double* x, bool forward, bool par, double omega) {
  const int nc = static_cast<int>(cp.size()) - 1;
  const int np = static_cast<int>(pp.size()) - 1;
  auto update = [&](Index i) {
    double acc[B];
    row_residual<B, T>(A, b, x, i, acc);
    for (int a = 0; a < B; ++a) acc[a] *= omega;  // SOR (1: Gauss-Seidel, the same bits)
    gemv_add<B, B>(dinv + static_cast<std::size_t>(B * B) * i, acc, x + static_cast<std::size_t>(B) * i);
  };
#pragma omp parallel if (par)
  {
    if (forward) {
#pragma omp for schedule(static, 1)
      for (int p = 0; p < np; ++p)
        for (Index t = pp[p]; t < pp[p + 1]; ++t) update(pr[t]);
    }
    for (int s = 0; s < nc; ++s) {
      const int c = forward ? s : nc - 1 - s;
#pragma omp for schedule(static)
      for (Index t = cp[c]; t < cp[c + 1]; ++t) update(cr[t]);
    }
    if (!forward) {
#pragma omp for schedule(static, 1)
      for (int p = 0; p < np; ++p)
        for (Index t = pp[p + 1]; t-- > pp[p];) update(pr[t]);
    }
  }
}

// The first forward sweep from x = 0, fused with the residual that follows it. An interior
// row is swept before every boundary row and after the interior rows below it in its own
// part, so when it is updated the only nonzero x_j of its neighbours are those with j < i:
// the blocks left of the diagonal (the columns are sorted). Its partial residual
// acc_i = b_i - sum_{j<i} A_ij x_j is kept in r. After the sweep, for a `clean` row (interior,
// no boundary neighbour: no neighbour changed after it except j > i), the residual is
// r_i = acc_i - sum_{j>=i} A_ij x_j, the blocks from the diagonal on; every other row gets
// the full b_i - (A x)_i. Together one pass over A instead of two (a sweep and a residual),
// the same operator as gs_sweep + residual up to rounding.
template <int B, class T, class D>
void gs_forward_from_zero_and_residual(const BlockMatrix& A, const std::vector<Index>& diag,
                                       const D* dinv, const std::vector<std::uint8_t>& clean,
                                       const std::vector<Index>& cp, const std::vector<Index>& cr,
                                       const std::vector<Index>& pp, const std::vector<Index>& pr, const double* b,
                                       double* x, double* r, bool par, bool with_residual, double omega) {
  const int nc = static_cast<int>(cp.size()) - 1;
  const int np = static_cast<int>(pp.size()) - 1;
  const Index n = A.rows;
#pragma omp parallel if (par)
  {
    // x starts at 0: only the boundary rows are read before they are written (the interior
    // rows are assigned in order), so only they are cleared.
    for (int c = 0; c < nc; ++c) {
#pragma omp for schedule(static) nowait
      for (Index t = cp[c]; t < cp[c + 1]; ++t) std::fill_n(x + static_cast<std::size_t>(B) * cr[t], B, 0.0);
    }
#pragma omp barrier
#pragma omp for schedule(static, 1)
    for (int p = 0; p < np; ++p)
      for (Index t = pp[p]; t < pp[p + 1]; ++t) {
        const Index i = pr[t];
        double lo[B];
        row_partial<B, T>(A, A.rp[i], diag[i], x, lo);
        double* acc = r + static_cast<std::size_t>(B) * i;
        double w[B];
        for (int a = 0; a < B; ++a) {
          acc[a] = b[static_cast<std::size_t>(B) * i + a] - lo[a];
          w[a] = omega * acc[a];  // acc stays the partial residual
        }
        gemv_set<B, B>(dinv + static_cast<std::size_t>(B * B) * i, w, x + static_cast<std::size_t>(B) * i);
      }
    for (int c = 0; c < nc; ++c) {
#pragma omp for schedule(static)
      for (Index t = cp[c]; t < cp[c + 1]; ++t) {
        const Index i = cr[t];
        double acc[B];
        row_residual<B, T>(A, b, x, i, acc);
        for (int a = 0; a < B; ++a) acc[a] *= omega;
        gemv_add<B, B>(dinv + static_cast<std::size_t>(B * B) * i, acc, x + static_cast<std::size_t>(B) * i);
      }
    }
    if (with_residual) {
#pragma omp for schedule(static)
    for (Index i = 0; i < n; ++i) {
      double* ri = r + static_cast<std::size_t>(B) * i;
      if (clean[i]) {
        double up[B];
        row_partial<B, T>(A, diag[i], A.rp[i + 1], x, up);
        for (int a = 0; a < B; ++a) ri[a] -= up[a];
      } else {
        row_residual<B, T>(A, b, x, i, ri);
      }
    }
    }
  }
}

}  // namespace

template <class T, class D>
void SaAmg::cycle(std::size_t l, const double* b, double* x) {
  Level& L = L_[l];
  const Index n = L.A.rows;
  const int bs = L.A.br;
  const std::size_t N = static_cast<std::size_t>(n) * bs;
  const bool par = parallel(L);
  // SOR relaxation of the smoother (smoothing_relaxation, coarse_smoothing_relaxation).
  const double omega = l == 0 || o_.coarse_smoothing_relaxation == 0 ? o_.smoothing_relaxation
                                                                    : o_.coarse_smoothing_relaxation;
  const D* Dv;  // the smoother's diagonal inverses: double, or their symmetrised float copy
  if constexpr (std::is_same_v<D, float>)
    Dv = L.dinv_f.data();
  else
    Dv = L.dinv.data();
  if (l + 1 == L_.size()) {
    if (coarse_direct_) {
      Eigen::Map<Eigen::VectorXd> xv(x, static_cast<Eigen::Index>(N));
      xv = Eigen::Map<const Eigen::VectorXd>(b, static_cast<Eigen::Index>(N));
      llt_.matrixL().solveInPlace(xv);
      llt_.matrixU().solveInPlace(xv);
    } else {
      std::fill(x, x + N, 0.0);
      with_size(bs, [&](auto Bc) {
        constexpr int B = decltype(Bc)::value;
        for (int s = 0; s < 2; ++s) {
          gs_sweep<B, T>(L.A, Dv, L.colour_ptr, L.colour_rows, L.part_ptr, L.part_rows, b, x, true, par, omega);
          gs_sweep<B, T>(L.A, Dv, L.colour_ptr, L.colour_rows, L.part_ptr, L.part_rows, b, x, false, par, omega);
        }
      });
    }
    return;
  }
  Level& C = L_[l + 1];
  const bool timed = l == 0;
  Clock::time_point t0{};
  if (timed) t0 = Clock::now();
  auto lap = [&](double& total) {
    if (!timed) return;
    const auto t1 = Clock::now();
    total += seconds_between(t0, t1);
    t0 = t1;
  };
  // The first forward sweep starts from x = 0 and reads only the blocks left of the
  // diagonal of the interior rows; it clears x itself.
  const bool from_zero = L.clean.size() == static_cast<std::size_t>(n);
  if (!from_zero) std::fill(x, x + N, 0.0);
  with_sizes(bs, m_, [&](auto Bc, auto Mc) {
    constexpr int B = decltype(Bc)::value, M = decltype(Mc)::value;
    constexpr std::size_t PB = static_cast<std::size_t>(B) * M;
    double* r = L.r.data();
    const Index nc = C.A.rows;
    const int sweeps = l == 0 || o_.coarse_smoothing_sweeps == 0 ? o_.smoothing_sweeps : o_.coarse_smoothing_sweeps;
    // With one sweep the residual is fused into the first one as well.
    const bool fused = sweeps == 1 && from_zero;
    if (from_zero)
      gs_forward_from_zero_and_residual<B, T>(L.A, L.diag, Dv, L.clean, L.colour_ptr, L.colour_rows, L.part_ptr,
                                              L.part_rows, b, x, r, par, fused, omega);
    for (int s = from_zero ? 1 : 0; s < sweeps; ++s)
      gs_sweep<B, T>(L.A, Dv, L.colour_ptr, L.colour_rows, L.part_ptr, L.part_rows, b, x, true, par, omega);
    lap(t_.apply_fine_smooth);
#pragma omp parallel if (par)
    {
      if (!fused) {
#pragma omp for schedule(static)
        for (Index i = 0; i < n; ++i) {
          row_residual<B, T>(L.A, b, x, i, r + static_cast<std::size_t>(B) * i);
        }
      }
#pragma omp for schedule(static)
      for (Index I = 0; I < nc; ++I) {
        double* bi = C.b.data() + static_cast<std::size_t>(M) * I;
        if constexpr (B == 3 && M == 6) {  // level 0 of the rigid-body hierarchy (block_row.hpp)
          if (!L.R.h.empty())
            block_row_restrict63(L.R.rp.data(), L.R.ci.data(), L.R.h.data(), r, I, bi);
          else
            block_row_restrict63(L.R.rp.data(), L.R.ci.data(), values<T>(L.R), r, I, bi);
        } else {
          std::fill(bi, bi + M, 0.0);
          for (Index k = L.R.rp[I]; k < L.R.rp[I + 1]; ++k)
            gemv_add<M, B>(values<T>(L.R) + PB * k, r + static_cast<std::size_t>(B) * L.R.ci[k], bi);
        }
      }
    }
    lap(t_.apply_fine_transfer);
    cycle<T, D>(l + 1, C.b.data(), C.x.data());
    lap(t_.apply_coarse);
#pragma omp parallel for schedule(static) if (par)
    for (Index i = 0; i < n; ++i) {
      if constexpr (B == 3 && M == 6) {
        if (!L.P.h.empty())
          block_row_prolong36_add(L.P.rp.data(), L.P.ci.data(), L.P.h.data(), C.x.data(), i,
                                  x + static_cast<std::size_t>(B) * i);
        else
          block_row_prolong36_add(L.P.rp.data(), L.P.ci.data(), values<T>(L.P), C.x.data(), i,
                                  x + static_cast<std::size_t>(B) * i);
      } else {
        for (Index k = L.P.rp[i]; k < L.P.rp[i + 1]; ++k)
          gemv_add<B, M>(values<T>(L.P) + PB * k, C.x.data() + static_cast<std::size_t>(M) * L.P.ci[k],
                         x + static_cast<std::size_t>(B) * i);
      }
    }
    lap(t_.apply_fine_transfer);
    for (int s = 0; s < sweeps; ++s)
      gs_sweep<B, T>(L.A, Dv, L.colour_ptr, L.colour_rows, L.part_ptr, L.part_rows, b, x, false, par, omega);
    lap(t_.apply_fine_smooth);
  });
}

void SaAmg::apply(const double* r, double* z) {
  if (!built_) throw std::logic_error("sa_amg: apply() before a successful setup()");
  const auto t0 = Clock::now();
  if (o_.float_storage && o_.float_diagonal)
    cycle<float, float>(0, r, z);
  else if (o_.float_storage)
    cycle<float, double>(0, r, z);
  else
    cycle<double, double>(0, r, z);
  t_.apply += since(t0);
  ++t_.applies;
}

}  // namespace loom::amg

// Helpers shared by the linear-solver plugins (eigen_pcg, eigen_ldlt, and the other
// backends): parallel 3x3-block SpMV, the constraint filter applied vertex by vertex, the
// projected residual, and the projected system of NUMERICS.md 3.4
//     A~ = S A S + (I - S),   b~ = S (b - A z) + z,
// written into a scalar compressed (CSR or CSC) matrix whose structure is built once from
// the block pattern (every 3x3 block stored dense, so the structure does not depend on S).
//
// All loops are over block rows (vertices); each writes only its own rows, so they run in
// parallel without atomics. Nothing here allocates except the make_* functions, which are
// meant for analyze_pattern().
#pragma once

#include <cmath>
#include <span>
#include <vector>

#include "loom/bsr.hpp"
#include "loom/common.hpp"
#include "loom/kernels/bsr_ops.hpp"

namespace loom::solver {

/// Number of scalar unknowns (3 per vertex).
inline std::size_t dofs(const BsrMatrix& A) { return 3 * static_cast<std::size_t>(A.rows()); }

/// Below this many block rows the helpers run serially: the rule in common.hpp.
using loom::kParallelMinRows;

/// y <- S_i y for vertex i (exact zeros for a fully constrained vertex).
inline void filter_vertex(const Filter& S, Index i, double* y) {
  const int f = S.free_dofs(i);
  if (f == 3) return;
  kernels::filter_vec3(f, S.projector(i).data(), y);
}

/// y <- S y, touching only the constrained vertices.
inline void filter(const Filter& S, std::span<double> y) {
  for (Index i : S.constrained()) filter_vertex(S, i, y.data() + 3 * static_cast<std::size_t>(i));
}

/// dv <- S dv + z (Ascher-Boxerman start: the prescribed values on constrained DOFs, the
/// guess on the free ones). z must satisfy (I - S) z = z.
inline void apply_prescribed(const Filter& S, std::span<const double> z, std::span<double> dv) {
  for (Index i : S.constrained()) {
    double* d = dv.data() + 3 * static_cast<std::size_t>(i);
    filter_vertex(S, i, d);
    const double* zi = z.data() + 3 * static_cast<std::size_t>(i);
    d[0] += zi[0];
    d[1] += zi[1];
    d[2] += zi[2];
  }
}

/// Whether z is zero on every constrained vertex (then A z needs no product).
inline bool prescribed_is_zero(const Filter& S, std::span<const double> z) {
  for (Index i : S.constrained()) {
    const double* zi = z.data() + 3 * static_cast<std::size_t>(i);
    if (zi[0] != 0.0 || zi[1] != 0.0 || zi[2] != 0.0) return false;
  }
  return true;
}

/// y = A x (parallel over block rows).
inline void multiply(const BsrMatrix& A, std::span<const double> x, std::span<double> y) {
  const BsrPattern& P = A.pattern();
  const Index n = P.n;
  const Index* rp = P.row_ptr.data();
  const Index* col = P.col.data();
  const double* val = A.values().data();
  const double* xp = x.data();
  double* yp = y.data();
#pragma omp parallel for schedule(static) if (n >= kParallelMinRows)
  for (Index i = 0; i < n; ++i) kernels::bsr_row_multiply(rp, col, val, xp, i, yp + 3 * static_cast<std::size_t>(i));
}

/// r = S (b - A x); returns |r|^2 (parallel).
inline double filtered_residual(const BsrMatrix& A, const Filter& S, std::span<const double> b,
                                std::span<const double> x, std::span<double> r) {
  const BsrPattern& P = A.pattern();
  const Index n = P.n;
  const Index* rp = P.row_ptr.data();
  const Index* col = P.col.data();
  const double* val = A.values().data();
  double sum = 0;
#pragma omp parallel for schedule(static) reduction(+ : sum) if (n >= kParallelMinRows)
  for (Index i = 0; i < n; ++i) {
    double ax[3];
    kernels::bsr_row_multiply(rp, col, val, x.data(), i, ax);
    double* ri = r.data() + 3 * static_cast<std::size_t>(i);
    const double* bi = b.data() + 3 * static_cast<std::size_t>(i);
    ri[0] = bi[0] - ax[0];
    ri[1] = bi[1] - ax[1];
    ri[2] = bi[2] - ax[2];
    filter_vertex(S, i, ri);
    sum += kernels::dot3(ri, ri);
  }
  return sum;
}

/// |S(b - A x)| / |S(b - A z)| using the work vector (3n); 0 when S(b - A z) = 0 and the
/// residual is 0 too. `bhat_norm` is |S(b - A z)|.
inline double relative_residual(const BsrMatrix& A, const Filter& S, std::span<const double> b,
                                std::span<const double> x, double bhat_norm, std::span<double> work) {
  const double rr = std::sqrt(filtered_residual(A, S, b, x, work));
  if (bhat_norm > 0) return rr / bhat_norm;
  return rr;
}

/// Scalar structure of a BSR pattern with dense 3x3 blocks: row (or column) 3i+a holds, in
/// increasing order, the 3 entries of every block (i, j) of block row i. The same arrays
/// serve as CSR or CSC (the block pattern is symmetric).
struct ScalarPattern {
  std::vector<int> outer;       ///< 3n + 1
  std::vector<int> inner;       ///< 9 * nnz_blocks
  std::vector<Index> transpose; ///< for block k = (i, j): the position of block (j, i)
  int rows = 0;
  /// Position in the value array of entry (a, b) of block k, which lies in block row i.
  int position(const BsrPattern& P, Index i, Index k, int a, int b) const {
    return outer[3 * i + a] + 3 * (k - P.row_ptr[i]) + b;
  }
};

inline ScalarPattern make_scalar_pattern(const BsrPattern& P) {
  ScalarPattern sp;
  const Index n = P.n;
  sp.rows = 3 * n;
  sp.outer.assign(3 * static_cast<std::size_t>(n) + 1, 0);
  sp.inner.resize(9 * static_cast<std::size_t>(P.nnz_blocks()));
  sp.transpose.resize(P.nnz_blocks());
  for (Index i = 0; i < n; ++i) {
    const int len = 3 * (P.row_ptr[i + 1] - P.row_ptr[i]);
    for (int a = 0; a < 3; ++a) sp.outer[3 * i + a + 1] = sp.outer[3 * i + a] + len;
  }
  for (Index i = 0; i < n; ++i)
    for (int a = 0; a < 3; ++a) {
      int pos = sp.outer[3 * i + a];
      for (Index k = P.row_ptr[i]; k < P.row_ptr[i + 1]; ++k)
        for (int b = 0; b < 3; ++b) sp.inner[pos++] = 3 * P.col[k] + b;
    }
  for (Index i = 0; i < n; ++i)
    for (Index k = P.row_ptr[i]; k < P.row_ptr[i + 1]; ++k) {
      const Index t = P.find(P.col[k], i);
      if (t < 0) throw std::logic_error("solver_common: block pattern is not structurally symmetric");
      sp.transpose[k] = t;
    }
  return sp;
}

/// Block (i, j) of the projected matrix: out = S_i B S_j (+ (I - S_i) when i == j).
inline void projected_block(const Filter& S, Index i, Index j, const double* B, double* out) {
  const int fi = S.free_dofs(i), fj = S.free_dofs(j);
  if (fi == 0 || fj == 0) {
    for (int e = 0; e < 9; ++e) out[e] = 0.0;
  } else {
    double tmp[9];
    const double* src = B;
    if (fi != 3) {
      kernels::mat3_mul_mat(S.projector(i).data(), src, tmp);
      src = tmp;
    }
    if (fj != 3) {
      kernels::mat3_mul_mat(src, S.projector(j).data(), out);
    } else {
      for (int e = 0; e < 9; ++e) out[e] = src[e];
    }
  }
  if (i == j && fi != 3) {
    // + (I - S_i)
    const double* Si = S.projector(i).data();
    for (int a = 0; a < 3; ++a)
      for (int b = 0; b < 3; ++b) out[3 * a + b] += (a == b ? 1.0 : 0.0) - (fi == 0 ? 0.0 : Si[3 * a + b]);
  }
}

/// Values of A~ = S A S + (I - S) in row-major (CSR) order over make_scalar_pattern().
inline void fill_projected_csr(const BsrMatrix& A, const Filter& S, const ScalarPattern& sp, double* values) {
  const BsrPattern& P = A.pattern();
  const Index n = P.n;
#pragma omp parallel for schedule(static) if (n >= kParallelMinRows)
  for (Index i = 0; i < n; ++i) {
    for (Index k = P.row_ptr[i]; k < P.row_ptr[i + 1]; ++k) {
      double blk[9];
      projected_block(S, i, P.col[k], A.block(k), blk);
      for (int a = 0; a < 3; ++a) {
        double* dst = values + sp.position(P, i, k, a, 0);
        dst[0] = blk[3 * a];
        dst[1] = blk[3 * a + 1];
        dst[2] = blk[3 * a + 2];
      }
    }
  }
}

/// Values of A~ in column-major (CSC) order over make_scalar_pattern(): column 3i+a holds
/// rows 3j+b, i.e. entry (b, a) of the projected block (j, i). Exact also for a
/// non-symmetric A.
inline void fill_projected_csc(const BsrMatrix& A, const Filter& S, const ScalarPattern& sp, double* values) {
  const BsrPattern& P = A.pattern();
  const Index n = P.n;
#pragma omp parallel for schedule(static) if (n >= kParallelMinRows)
  for (Index i = 0; i < n; ++i) {
    for (Index k = P.row_ptr[i]; k < P.row_ptr[i + 1]; ++k) {
      const Index j = P.col[k];
      double blk[9];
      projected_block(S, j, i, A.block(sp.transpose[k]), blk);
      for (int a = 0; a < 3; ++a) {
        double* dst = values + sp.position(P, i, k, a, 0);
        dst[0] = blk[a];
        dst[1] = blk[3 + a];
        dst[2] = blk[6 + a];
      }
    }
  }
}

/// out = S (b - A z) + z. Returns |S(b - A z)|^2.
inline double projected_rhs(const BsrMatrix& A, const Filter& S, std::span<const double> b,
                            std::span<const double> z, std::span<double> out) {
  const double r2 = filtered_residual(A, S, b, z, out);
  for (Index i : S.constrained()) {
    double* o = out.data() + 3 * static_cast<std::size_t>(i);
    const double* zi = z.data() + 3 * static_cast<std::size_t>(i);
    o[0] += zi[0];
    o[1] += zi[1];
    o[2] += zi[2];
  }
  return r2;
}

}  // namespace loom::solver

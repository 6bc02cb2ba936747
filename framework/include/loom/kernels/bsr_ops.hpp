// 3x3 block helpers for the block-sparse (BSR) matrices of the implicit step and the
// linear solvers. Header-only, host+device (LOOM_HD), templated on the scalar so that a
// CUDA backend (plugins/backends/cuda) runs the same math. Blocks are row-major arrays of 9 scalars,
// vectors arrays of 3.
#pragma once

#include <cmath>

#include "loom/common.hpp"

namespace loom::kernels {

/// y = B x
template <class T>
LOOM_HD inline void mat3_mul(const T* B, const T* x, T* y) {
  const T x0 = x[0], x1 = x[1], x2 = x[2];
  y[0] = B[0] * x0 + B[1] * x1 + B[2] * x2;
  y[1] = B[3] * x0 + B[4] * x1 + B[5] * x2;
  y[2] = B[6] * x0 + B[7] * x1 + B[8] * x2;
}

/// y += B x
template <class T>
LOOM_HD inline void mat3_mul_add(const T* B, const T* x, T* y) {
  const T x0 = x[0], x1 = x[1], x2 = x[2];
  y[0] += B[0] * x0 + B[1] * x1 + B[2] * x2;
  y[1] += B[3] * x0 + B[4] * x1 + B[5] * x2;
  y[2] += B[6] * x0 + B[7] * x1 + B[8] * x2;
}

/// y += s B x
template <class T>
LOOM_HD inline void mat3_mul_add_scaled(T s, const T* B, const T* x, T* y) {
  const T x0 = x[0], x1 = x[1], x2 = x[2];
  y[0] += s * (B[0] * x0 + B[1] * x1 + B[2] * x2);
  y[1] += s * (B[3] * x0 + B[4] * x1 + B[5] * x2);
  y[2] += s * (B[6] * x0 + B[7] * x1 + B[8] * x2);
}

/// C = A B (C must not alias A or B)
template <class T>
LOOM_HD inline void mat3_mul_mat(const T* A, const T* B, T* C) {
  for (int r = 0; r < 3; ++r)
    for (int c = 0; c < 3; ++c)
      C[3 * r + c] = A[3 * r] * B[c] + A[3 * r + 1] * B[3 + c] + A[3 * r + 2] * B[6 + c];
}

/// out = S B S' (S, S' symmetric projectors; out must not alias B)
template <class T>
LOOM_HD inline void mat3_project(const T* S, const T* B, const T* Sp, T* out) {
  T tmp[9];
  mat3_mul_mat(S, B, tmp);
  mat3_mul_mat(tmp, Sp, out);
}

/// B = B^T in place
template <class T>
LOOM_HD inline void mat3_transpose_in_place(T* B) {
  T t = B[1]; B[1] = B[3]; B[3] = t;
  t = B[2]; B[2] = B[6]; B[6] = t;
  t = B[5]; B[5] = B[7]; B[7] = t;
}

/// Inverse of a symmetric positive definite 3x3 block through its Cholesky factor.
/// Only the symmetric part (B + B^T)/2 is used. Returns false (and leaves Binv untouched)
/// when a pivot is not positive (B is not SPD) or not finite.
template <class T>
LOOM_HD inline bool mat3_spd_inverse(const T* B, T* Binv) {
  using std::sqrt;
  const T a00 = B[0];
  const T a10 = T(0.5) * (B[3] + B[1]), a11 = B[4];
  const T a20 = T(0.5) * (B[6] + B[2]), a21 = T(0.5) * (B[7] + B[5]), a22 = B[8];
  // B = L L^T
  if (!(a00 > T(0))) return false;
  const T l00 = sqrt(a00);
  const T l10 = a10 / l00, l20 = a20 / l00;
  const T d1 = a11 - l10 * l10;
  if (!(d1 > T(0))) return false;
  const T l11 = sqrt(d1);
  const T l21 = (a21 - l20 * l10) / l11;
  const T d2 = a22 - l20 * l20 - l21 * l21;
  if (!(d2 > T(0))) return false;
  const T l22 = sqrt(d2);
  // W = L^{-1} (lower triangular)
  const T w00 = T(1) / l00, w11 = T(1) / l11, w22 = T(1) / l22;
  const T w10 = -l10 * w00 * w11;
  const T w21 = -l21 * w11 * w22;
  const T w20 = -(l20 * w00 + l21 * w10) * w22;
  // B^{-1} = W^T W
  Binv[0] = w00 * w00 + w10 * w10 + w20 * w20;
  Binv[1] = w10 * w11 + w20 * w21;
  Binv[2] = w20 * w22;
  Binv[4] = w11 * w11 + w21 * w21;
  Binv[5] = w21 * w22;
  Binv[8] = w22 * w22;
  Binv[3] = Binv[1];
  Binv[6] = Binv[2];
  Binv[7] = Binv[5];
  return true;
}

/// Dot product of two 3-vectors.
template <class T>
LOOM_HD inline T dot3(const T* a, const T* b) {
  return a[0] * b[0] + a[1] * b[1] + a[2] * b[2];
}

/// y_i = sum_k A_ik x_col(k) over block row i of a BSR matrix (row_ptr, col, 9-value blocks).
/// The blocks may be stored in another type V than the vectors and the sums (T): the CUDA
/// backend's mixed-precision PCG reads float blocks into double sums.
template <class T, class I, class V = T>
LOOM_HD inline void bsr_row_multiply(const I* row_ptr, const I* col, const V* values, const T* x,
                                     I i, T* yi) {
  T y0 = T(0), y1 = T(0), y2 = T(0);
  for (I k = row_ptr[i]; k < row_ptr[i + 1]; ++k) {
    const V* B = values + 9 * static_cast<long long>(k);
    const T* xj = x + 3 * static_cast<long long>(col[k]);
    const T x0 = xj[0], x1 = xj[1], x2 = xj[2];
    y0 += B[0] * x0 + B[1] * x1 + B[2] * x2;
    y1 += B[3] * x0 + B[4] * x1 + B[5] * x2;
    y2 += B[6] * x0 + B[7] * x1 + B[8] * x2;
  }
  yi[0] = y0;
  yi[1] = y1;
  yi[2] = y2;
}

/// y = A x one block row at a time (bsr_row_multiply), as the functor of a parallel loop over the
/// rows (Thrust's for_each, the CUDA backend's parallel_for): blocks in V, x, y and the sums in T.
template <class T, class I, class V = T>
struct BsrRowProduct {
  const I* row_ptr;
  const I* col;
  const V* values;
  const T* x;
  T* y;
  LOOM_HD void operator()(I i) const { bsr_row_multiply(row_ptr, col, values, x, i, y + 3 * static_cast<long long>(i)); }
};

/// y <- S_i y for one vertex, where free_dofs is the vertex's number of free DOF and P its
/// projector (ignored when free_dofs is 3 or 0). Exactly zero for a fully constrained vertex.
template <class T>
LOOM_HD inline void filter_vec3(int free_dofs, const T* P, T* y) {
  if (free_dofs == 3) return;
  if (free_dofs == 0) {
    y[0] = y[1] = y[2] = T(0);
    return;
  }
  T t[3];
  mat3_mul(P, y, t);
  y[0] = t[0];
  y[1] = t[1];
  y[2] = t[2];
}

}  // namespace loom::kernels

// Per-block math of the projected system of NUMERICS.md 3.4, shared by the direct and
// distributed solver backends (cholmod, petsc) and reusable by a device backend:
//   A~ = S A S + (I - S),   b^ = S (b - A z),   A~ y = b^,   dv = y + z.
// Blocks are 3x3 row-major; a null projector pointer means S_i = I (a free vertex).
#pragma once

#include "loom/common.hpp"

namespace loom::kernels {

/// out = S_i B S_j (S_i, S_j may be null for the identity; out may alias B).
template <class T>
LOOM_HD inline void project_block(const T* Si, const T* B, const T* Sj, T* out) {
  T tmp[9];
  if (Sj) {  // tmp = B S_j
    for (int r = 0; r < 3; ++r)
      for (int c = 0; c < 3; ++c)
        tmp[3 * r + c] = B[3 * r] * Sj[c] + B[3 * r + 1] * Sj[3 + c] + B[3 * r + 2] * Sj[6 + c];
  } else {
    for (int e = 0; e < 9; ++e) tmp[e] = B[e];
  }
  if (Si) {  // out = S_i tmp
    for (int r = 0; r < 3; ++r)
      for (int c = 0; c < 3; ++c)
        out[3 * r + c] = Si[3 * r] * tmp[c] + Si[3 * r + 1] * tmp[3 + c] + Si[3 * r + 2] * tmp[6 + c];
  } else {
    for (int e = 0; e < 9; ++e) out[e] = tmp[e];
  }
}

/// D += I - S_i (the diagonal block of a constrained vertex).
template <class T>
LOOM_HD inline void add_complement(const T* Si, T* D) {
  for (int r = 0; r < 3; ++r)
    for (int c = 0; c < 3; ++c) D[3 * r + c] += (r == c ? T(1) : T(0)) - Si[3 * r + c];
}

/// out = S_i y (3-vectors; out must not alias y).
template <class T>
LOOM_HD inline void apply_projector(const T* Si, const T* y, T* out) {
  for (int r = 0; r < 3; ++r) out[r] = Si[3 * r] * y[0] + Si[3 * r + 1] * y[1] + Si[3 * r + 2] * y[2];
}

/// Projected block row i of the system: writes S_i A_ij S_j (+ I - S_i on the diagonal) for
/// every block k in [begin, end) of row i. cons[j] != 0 marks constrained vertices; proj(j)
/// returns S_j's 9 values for them.
template <class T, class ProjFn>
LOOM_HD inline void project_row(Index i, Index begin, Index end, Index diag, const Index* col,
                                const unsigned char* cons, ProjFn proj, const T* A, T* out) {
  const T* Si = cons[i] ? proj(i) : nullptr;
  for (Index k = begin; k < end; ++k) {
    const Index j = col[k];
    const T* Sj = cons[j] ? proj(j) : nullptr;
    project_block(Si, A + 9 * static_cast<long>(k), Sj, out + 9 * static_cast<long>(k));
  }
  if (Si) add_complement(Si, out + 9 * static_cast<long>(diag));
}

/// One block row of b^ = S (b - A z): out_i = S_i (b_i - sum_k A_ik z_col(k)). Pass
/// z == nullptr when z is zero.
template <class T>
LOOM_HD inline void projected_rhs_row(Index i, Index begin, Index end, const Index* col, const T* Si,
                                      const T* A, const T* b, const T* z, T* out) {
  T t[3] = {b[3 * i], b[3 * i + 1], b[3 * i + 2]};
  if (z) {
    for (Index k = begin; k < end; ++k) {
      const T* B = A + 9 * static_cast<long>(k);
      const T* zj = z + 3 * static_cast<long>(col[k]);
      for (int r = 0; r < 3; ++r) t[r] -= B[3 * r] * zj[0] + B[3 * r + 1] * zj[1] + B[3 * r + 2] * zj[2];
    }
  }
  if (Si) {
    apply_projector(Si, t, out + 3 * static_cast<long>(i));
  } else {
    for (int r = 0; r < 3; ++r) out[3 * i + r] = t[r];
  }
}

}  // namespace loom::kernels

// One block row i of the Baraff-Witkin system (NUMERICS.md 3.1-3.2, with Rayleigh damping):
//   A_ij = -h df/dv_ij - (h^2 + h beta) df/dx_ij  (+ ((1 + h alpha) m_i + h c_d n_i) I on the
//   diagonal, - h c_d I off it: the Kang-Cho graph-Laplacian damper)
//   b_i  = h ( f_i + m_i g - alpha m_i v_i + (h + beta) (df/dx v)_i - c_d (L v)_i )
// Host+device: the CPU plugin (baraff_witkin) and the CUDA backend run this same function.
#pragma once

#include "loom/common.hpp"
#include "loom/kernels/bsr_ops.hpp"

namespace loom::kernels {

/// Fields: the pattern (rp, col), df/dx and df/dv values, v0, f0, masses, the Laplacian
/// degree n_i; outputs a (A's values) and b; coefficients h, cm = 1 + h alpha,
/// cx = h^2 + h beta, cbx = h + beta, hcd = h c_d, alpha, cd = c_d, gravity g0..g2.
template <class T>
struct BwAssemble {
  const Index *rp, *col;
  const T *dfx, *dfv, *v, *f, *mass, *degree;
  T* a;
  T* b;
  T h, cm, cx, cbx, hcd, alpha, cd, g0, g1, g2;
  LOOM_HD void operator()(Index i) const {
    const long long o = 3LL * i;
    T y[3] = {T(0), T(0), T(0)};
    T sv[3] = {T(0), T(0), T(0)};
    for (Index k = rp[i]; k < rp[i + 1]; ++k) {
      const long long kb = 9LL * k;
      const Index j = col[k];
      const T* vj = v + 3LL * j;
      kernels::mat3_mul_add(dfx + kb, vj, y);
      T* ak = a + kb;
      for (int e = 0; e < 9; ++e) ak[e] = -h * dfv[kb + e] - cx * dfx[kb + e];
      if (j == i) {
        const T d = cm * mass[i] + hcd * degree[i];
        ak[0] += d;
        ak[4] += d;
        ak[8] += d;
      } else {
        ak[0] -= hcd;
        ak[4] -= hcd;
        ak[8] -= hcd;
        sv[0] += vj[0];
        sv[1] += vj[1];
        sv[2] += vj[2];
      }
    }
    const T m = mass[i], deg = degree[i];
    const T g[3] = {g0, g1, g2};
    for (int c = 0; c < 3; ++c) {
      const T lv = deg * v[o + c] - sv[c];
      b[o + c] = h * (f[o + c] + m * g[c] - alpha * m * v[o + c] + cbx * y[c] - cd * lv);
    }
  }
};


}  // namespace loom::kernels

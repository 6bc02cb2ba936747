// The vertex update of symplectic Euler, one source for the CPU plugin (generic path) and the
// CUDA backend's device step (plugins/backends/cuda): host+device, header-only.
//   free vertex (w > 0):  v += h (w f + g), then x += h v
//   pinned (w = 0):       x += h v per component with v != 0 (a prescribed velocity); a fixed pin
//                         (v = 0) is not touched at all, bit for bit.
#pragma once

#include "loom/common.hpp"

namespace loom::symplectic_euler {

template <class T>
LOOM_HD inline void se_update_vertex(T* xi, T* vi, const T* fi, T wi, T h, T g0, T g1, T g2) {
  if (wi != T(0)) {
    vi[0] += h * (wi * fi[0] + g0);
    vi[1] += h * (wi * fi[1] + g1);
    vi[2] += h * (wi * fi[2] + g2);
    xi[0] += h * vi[0];
    xi[1] += h * vi[1];
    xi[2] += h * vi[2];
  } else {
    for (int c = 0; c < 3; ++c)
      if (vi[c] != T(0)) xi[c] += h * vi[c];
  }
}

}  // namespace loom::symplectic_euler

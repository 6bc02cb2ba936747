// Per-spring math (Hooke spring with optional axial damper), shared by the CPU plugins
// and the CUDA backend (plugins/backends/cuda). Header-only, host+device (LOOM_HD), templated on the scalar.
//
// Conventions (NUMERICS.md): spring (i, j), d = x_j - x_i, l = |d|, n = d / l,
// delta = l - l0, delta_dot = n . (v_j - v_i).
//   force on i:   f_i = k (l - l0) n + c (n . (v_j - v_i)) n = k (1 - l0/l) d + ...,  f_j = -f_i
//   energy:       E = k (l - l0)^2 / 2
//   d f_i / d x_j = k [ n n^T + (1 - l0/l) (I - n n^T) ]   (symmetric 3x3 block K)
//   d f_i / d x_i = d f_j / d x_j = -K,   d f_j / d x_i = K
//   d f_i / d v_j = c n n^T (block D),    d f_i / d v_i = -D
// The damper's position derivative is not included (the usual BW simplification; it is zero
// at rest and non-symmetric otherwise).
// A spring of current length 0 (coincident endpoints) gets zero force and direction n = 0
// instead of a NaN; rest lengths are validated > 0 when the material is built.
#pragma once

#include <cmath>

#include "loom/common.hpp"

namespace loom::kernels {

/// 1/|d| for d != 0, else 0. Uses one sqrt and one division (-fno-math-errno lets it vectorise).
template <class T>
LOOM_HD inline T spring_inv_length(T l2) {
  using std::sqrt;
  return l2 > T(0) ? T(1) / sqrt(l2) : T(0);
}

/// The force on i is s d. Elastic: s = k (1 - l0/l), from l2 = d . d.
/// (Scalar form for vectorised loops: the caller gathers d itself.)
template <class T>
LOOM_HD inline T spring_force_scale(T l2, T k, T l0) {
  return k * (T(1) - l0 * spring_inv_length(l2));
}

/// Elastic plus damper: s = k (1 - l0/l) + c (d . u) / l^2, u = v_j - v_i
/// (the damper force c (n . u) n = c (d . u) d / l^2).
template <class T>
LOOM_HD inline T spring_force_scale_damped(T l2, T du, T k, T l0, T c) {
  const T il = spring_inv_length(l2);
  return k * (T(1) - l0 * il) + c * du * il * il;
}

/// Elastic force on endpoint i (the force on j is -fi).
template <class T>
LOOM_HD inline void spring_force(const T* xi, const T* xj, T k, T l0, T* fi) {
  const T d0 = xj[0] - xi[0], d1 = xj[1] - xi[1], d2 = xj[2] - xi[2];
  const T s = spring_force_scale(d0 * d0 + d1 * d1 + d2 * d2, k, l0);
  fi[0] = s * d0;
  fi[1] = s * d1;
  fi[2] = s * d2;
}

/// Elastic plus axial damping force on endpoint i (the force on j is -fi).
template <class T>
LOOM_HD inline void spring_force_damped(const T* xi, const T* xj, const T* vi, const T* vj, T k,
                                        T l0, T c, T* fi) {
  const T d0 = xj[0] - xi[0], d1 = xj[1] - xi[1], d2 = xj[2] - xi[2];
  const T du = d0 * (vj[0] - vi[0]) + d1 * (vj[1] - vi[1]) + d2 * (vj[2] - vi[2]);
  const T s = spring_force_scale_damped(d0 * d0 + d1 * d1 + d2 * d2, du, k, l0, c);
  fi[0] = s * d0;
  fi[1] = s * d1;
  fi[2] = s * d2;
}

/// Current length of the spring.
template <class T>
LOOM_HD inline T spring_length(const T* xi, const T* xj) {
  using std::sqrt;
  const T d0 = xj[0] - xi[0], d1 = xj[1] - xi[1], d2 = xj[2] - xi[2];
  return sqrt(d0 * d0 + d1 * d1 + d2 * d2);
}

/// Elastic energy k (l - l0)^2 / 2.
template <class T>
LOOM_HD inline T spring_energy(const T* xi, const T* xj, T k, T l0) {
  const T e = spring_length(xi, xj) - l0;
  return T(0.5) * k * e * e;
}

/// Signed strain l/l0 - 1, given 1/l0.
template <class T>
LOOM_HD inline T spring_strain(const T* xi, const T* xj, T inv_l0) {
  return spring_length(xi, xj) * inv_l0 - T(1);
}

/// K = d f_i / d x_j = k [n n^T + g (I - n n^T)], g = 1 - l0/l, clamped to max(0, g) when
/// clamp_compressed (Choi & Ko 2002: -J stays PSD under compression). K is symmetric, row-major.
template <class T>
LOOM_HD inline void spring_stiffness_block(const T* xi, const T* xj, T k, T l0, bool clamp_compressed,
                                           T* K) {
  const T d[3] = {xj[0] - xi[0], xj[1] - xi[1], xj[2] - xi[2]};
  const T l2 = d[0] * d[0] + d[1] * d[1] + d[2] * d[2];
  const T il = spring_inv_length(l2);
  T g = T(1) - l0 * il;
  if (clamp_compressed && g < T(0)) g = T(0);
  if (l2 == T(0)) g = T(0);  // no direction: only the (zero) axial term is left
  // k [g I + (1 - g) n n^T], n n^T = d d^T / l^2
  const T a = k * (T(1) - g) * il * il;
  const T b = k * g;
  for (int r = 0; r < 3; ++r)
    for (int c = 0; c < 3; ++c) K[3 * r + c] = a * d[r] * d[c] + (r == c ? b : T(0));
}

/// D = d f_i / d v_j = c n n^T (symmetric, row-major).
template <class T>
LOOM_HD inline void spring_damping_block(const T* xi, const T* xj, T c, T* D) {
  const T d[3] = {xj[0] - xi[0], xj[1] - xi[1], xj[2] - xi[2]};
  const T l2 = d[0] * d[0] + d[1] * d[1] + d[2] * d[2];
  const T il = spring_inv_length(l2);
  const T a = c * il * il;
  for (int r = 0; r < 3; ++r)
    for (int q = 0; q < 3; ++q) D[3 * r + q] = a * d[r] * d[q];
}

}  // namespace loom::kernels

// Classical fourth-order Runge-Kutta, per degree of freedom, header-only, host+device.
//
// State y = (x, v), y' = (v, a(x, v)), a = w f + g for free vertices and a = 0 for pinned
// ones (w = 0): a pinned vertex keeps its prescribed velocity at every stage, so a fixed pin
// stays exactly where it is. The integrator calls, for every dof d:
//   stage 1 (at x0, v0):  rk4_first(...)          -> acc = k1,        (xs, vs) = y0 + h/2 k1
//   stage 2 (at xs, vs):  rk4_middle(..., h/2)    -> acc += 2 k2,     (xs, vs) = y0 + h/2 k2
//   stage 3 (at xs, vs):  rk4_middle(..., h)      -> acc += 2 k3,     (xs, vs) = y0 + h k3
//   stage 4 (at xs, vs):  rk4_last(...)           -> y0 += h/6 (acc + k4)
#pragma once

#include "loom/common.hpp"

namespace loom::kernels {

/// Acceleration of one dof: inverse mass times force, plus gravity for free vertices.
template <class T>
LOOM_HD inline T rk4_accel(T f, T w, T g) {
  return w > T(0) ? w * f + g : T(0);
}

template <class T>
LOOM_HD inline void rk4_first(T x0, T v0, T a, T& xs, T& vs, T& accx, T& accv, T half_h) {
  accx = v0;
  accv = a;
  xs = x0 + half_h * v0;
  vs = v0 + half_h * a;
}

/// Stages 2 and 3: (xs, vs) holds the current stage, a its acceleration; next is h/2 or h.
template <class T>
LOOM_HD inline void rk4_middle(T x0, T v0, T a, T& xs, T& vs, T& accx, T& accv, T next) {
  const T kx = vs;
  accx += T(2) * kx;
  accv += T(2) * a;
  xs = x0 + next * kx;
  vs = v0 + next * a;
}

template <class T>
LOOM_HD inline void rk4_last(T& x0, T& v0, T a, T vs, T accx, T accv, T h) {
  const T h6 = h / T(6);
  x0 += h6 * (accx + vs);
  v0 += h6 * (accv + a);
}

}  // namespace loom::kernels

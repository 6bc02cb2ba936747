// Dihedral-angle hinge bending (Bridson et al. 2003, Grinspun et al. 2003 "discrete shells"),
// NUMERICS.md section 5: per-hinge angle, energy, force and force Jacobian. Header-only and
// LOOM_HD so that the CPU material adapter and a CUDA backend share the math. Templated on
// the scalar T of the computation (double, float, the Dual below, or a complex-step type in
// tests, which then specialises HingeMath).
//
// A hinge is the interior edge (x0, x1) with the opposite vertices x2 (triangle A, oriented
// x0 -> x1 -> x2) and x3 (triangle B, oriented x1 -> x0 -> x3, i.e. consistently with A).
//   e = x1 - x0,  nA = e x (x2 - x0),  nB = (x3 - x0) x e          (unnormalised face normals)
//   theta = atan2( (nB x nA) . e / |e|,  nA . nB )                  (signed, 0 when flat,
//                                                                   > 0 when x2, x3 move along nA)
//   d theta / d x2 = |e| nA / |nA|^2,   d theta / d x3 = |e| nB / |nB|^2
//   d theta / d x0 = -(1 - tA) g2 - (1 - tB) g3,   d theta / d x1 = -tA g2 - tB g3,
//   tA = (x2 - x0).e / |e|^2,  tB = (x3 - x0).e / |e|^2
// Energy E = k (theta - theta0)^2 (theta - theta0 wrapped into (-pi, pi]), k from the rest
// mesh (RestHinge::k = B |e0|^2 / (2 (A0 + A1)), NUMERICS.md 5.1).
// Force F = -2 k (theta - theta0) grad theta. Jacobian dF/dx = -2 k (g g^T + (theta - theta0)
// Hess theta): exact (the Hessian of theta by forward-mode differentiation of the gradient,
// 12 directional passes with the Dual type below), or the Gauss-Newton term -2 k g g^T,
// which is negative semidefinite (so -J is PSD) and is the default for implicit solves.
#pragma once

#include <cmath>

#include "loom/common.hpp"

namespace loom::bending {

/// Scalar operations the kernel needs; specialise for other scalar types (tests do for
/// std::complex). value() gives the real value used for branching.
template <class T>
struct HingeMath {
  LOOM_HD static T atan2(const T& s, const T& c) {
    using std::atan2;
    return atan2(s, c);
  }
  LOOM_HD static T sqrt(const T& a) {
    using std::sqrt;
    return sqrt(a);
  }
  LOOM_HD static double value(const T& a) { return static_cast<double>(a); }
};

/// First-order forward-mode dual number (value, derivative): the exact Hessian of theta.
struct Dual {
  double v = 0, d = 0;
  LOOM_HD Dual() = default;
  LOOM_HD Dual(double value) : v(value), d(0) {}  // NOLINT: implicit from constants
  LOOM_HD Dual(double value, double deriv) : v(value), d(deriv) {}
};
LOOM_HD inline Dual operator+(Dual a, Dual b) { return {a.v + b.v, a.d + b.d}; }
LOOM_HD inline Dual operator-(Dual a, Dual b) { return {a.v - b.v, a.d - b.d}; }
LOOM_HD inline Dual operator-(Dual a) { return {-a.v, -a.d}; }
LOOM_HD inline Dual operator*(Dual a, Dual b) { return {a.v * b.v, a.d * b.v + a.v * b.d}; }
LOOM_HD inline Dual operator/(Dual a, Dual b) { return {a.v / b.v, (a.d * b.v - a.v * b.d) / (b.v * b.v)}; }

template <>
struct HingeMath<Dual> {
  LOOM_HD static Dual atan2(const Dual& s, const Dual& c) {
    using std::atan2;
    return {atan2(s.v, c.v), (c.v * s.d - s.v * c.d) / (s.v * s.v + c.v * c.v)};
  }
  LOOM_HD static Dual sqrt(const Dual& a) {
    using std::sqrt;
    const double r = sqrt(a.v);
    return {r, r > 0 ? a.d / (2 * r) : 0.0};
  }
  LOOM_HD static double value(const Dual& a) { return a.v; }
};

/// Rest data of one hinge: E = k (theta - theta0)^2.
template <class R = double>
struct RestHinge {
  R k;       ///< J (energy per squared radian): B |e0|^2 / (2 (A0 + A1))
  R theta0;  ///< rest dihedral angle (rad), from the input mesh
};

template <class T>
LOOM_HD inline void hinge_cross(const T a[3], const T b[3], T c[3]) {
  c[0] = a[1] * b[2] - a[2] * b[1];
  c[1] = a[2] * b[0] - a[0] * b[2];
  c[2] = a[0] * b[1] - a[1] * b[0];
}
template <class T>
LOOM_HD inline T hinge_dot(const T a[3], const T b[3]) {
  return a[0] * b[0] + a[1] * b[1] + a[2] * b[2];
}

/// Relative size below which a wing is treated as collapsed: |nA|^2 <= eps |e|^4.
constexpr double kDegenerateWing = 1e-24;

/// Dihedral angle theta of the hinge X (4 points) and its gradient g[4][3]. Returns false
/// (theta = 0, g = 0) when the edge has zero length or a wing has collapsed onto the edge
/// line, where the angle is undefined.
template <class T>
LOOM_HD inline bool angle_gradient(const T X[4][3], T& theta, T g[4][3]) {
  using M = HingeMath<T>;
  T e[3], a[3], b[3], nA[3], nB[3], c[3];
  for (int k = 0; k < 3; ++k) {
    e[k] = X[1][k] - X[0][k];
    a[k] = X[2][k] - X[0][k];
    b[k] = X[3][k] - X[0][k];
  }
  hinge_cross(e, a, nA);
  hinge_cross(b, e, nB);
  const T e2 = hinge_dot(e, e), lA2 = hinge_dot(nA, nA), lB2 = hinge_dot(nB, nB);
  const double e2v = M::value(e2);
  if (!(e2v > 0) || !(M::value(lA2) > kDegenerateWing * e2v * e2v) || !(M::value(lB2) > kDegenerateWing * e2v * e2v)) {
    theta = T(0);
    for (int j = 0; j < 4; ++j)
      for (int k = 0; k < 3; ++k) g[j][k] = T(0);
    return false;
  }
  const T le = M::sqrt(e2);
  hinge_cross(nB, nA, c);
  theta = M::atan2(hinge_dot(c, e) / le, hinge_dot(nA, nB));
  const T sA = le / lA2, sB = le / lB2;
  const T tA = hinge_dot(a, e) / e2, tB = hinge_dot(b, e) / e2;
  for (int k = 0; k < 3; ++k) {
    const T gA = sA * nA[k], gB = sB * nB[k];
    g[2][k] = gA;
    g[3][k] = gB;
    g[0][k] = -((T(1) - tA) * gA + (T(1) - tB) * gB);
    g[1][k] = -(tA * gA + tB * gB);
  }
  return true;
}

/// theta - theta0 wrapped into (-pi, pi].
template <class T, class R>
LOOM_HD inline T angle_excess(const T& theta, R theta0) {
  constexpr double pi = 3.14159265358979323846;
  T d = theta - T(theta0);
  const double dv = HingeMath<T>::value(d);
  if (dv > pi) d = d - T(2 * pi);
  else if (dv <= -pi) d = d + T(2 * pi);
  return d;
}

/// Energy k (theta - theta0)^2 of one hinge (0 for a degenerate hinge).
template <class T, class R>
LOOM_HD inline T energy(const RestHinge<R>& h, const T X[4][3]) {
  T theta, g[4][3];
  if (!angle_gradient(X, theta, g)) return T(0);
  const T d = angle_excess(theta, h.theta0);
  return T(h.k) * d * d;
}

/// Forces F[j] = -dE/dX_j = -2 k (theta - theta0) g_j. Returns the energy.
template <class T, class R>
LOOM_HD inline T forces(const RestHinge<R>& h, const T X[4][3], T F[4][3]) {
  T theta, g[4][3];
  if (!angle_gradient(X, theta, g)) {
    for (int j = 0; j < 4; ++j)
      for (int k = 0; k < 3; ++k) F[j][k] = T(0);
    return T(0);
  }
  const T d = angle_excess(theta, h.theta0);
  const T s = T(-2) * T(h.k) * d;
  for (int j = 0; j < 4; ++j)
    for (int k = 0; k < 3; ++k) F[j][k] = s * g[j][k];
  return T(h.k) * d * d;
}

/// Jacobian blocks J[a][b] = dF_a/dX_b (3x3 row-major: J[a][b][3 r + c] = dF_a[r]/dX_b[c]).
/// exact = false: the Gauss-Newton term -2 k g_a g_b^T (-J PSD). exact = true: adds
/// -2 k (theta - theta0) Hess(theta), with the Hessian by forward-mode differentiation.
/// J[b][a] = J[a][b]^T in both cases.
template <class R>
LOOM_HD inline void jacobian(const RestHinge<R>& h, const double X[4][3], bool exact, double J[4][4][9]) {
  double theta, g[4][3];
  if (!angle_gradient(X, theta, g)) {
    for (int a = 0; a < 4; ++a)
      for (int b = 0; b < 4; ++b)
        for (int q = 0; q < 9; ++q) J[a][b][q] = 0;
    return;
  }
  const double m2k = -2.0 * static_cast<double>(h.k);
  for (int a = 0; a < 4; ++a)
    for (int b = 0; b < 4; ++b)
      for (int r = 0; r < 3; ++r)
        for (int c = 0; c < 3; ++c) J[a][b][3 * r + c] = m2k * g[a][r] * g[b][c];
  if (!exact) return;
  const double d = angle_excess(theta, h.theta0);
  if (d == 0) return;
  Dual XD[4][3], th, gd[4][3];
  for (int j = 0; j < 4; ++j)
    for (int k = 0; k < 3; ++k) XD[j][k] = Dual(X[j][k]);
  for (int b = 0; b < 4; ++b)
    for (int c = 0; c < 3; ++c) {
      XD[b][c].d = 1;
      angle_gradient(XD, th, gd);  // gd[a][r].d = d^2 theta / dX_a[r] dX_b[c]
      XD[b][c].d = 0;
      for (int a = 0; a < 4; ++a)
        for (int r = 0; r < 3; ++r) J[a][b][3 * r + c] += m2k * d * gd[a][r].d;
    }
}

/// Stiffness of a hinge whose edge makes the material-space angle phi (rad) with the weft:
/// phi is folded into [0, pi/2] (an edge has no sign, and the cloth is assumed symmetric
/// about weft and warp) and interpolated linearly in angle between the rigidities for
/// edges along the weft (b_edge_weft: the curvature runs along the warp), at 45 degrees
/// (b_bias) and along the warp (b_edge_warp: the curvature runs along the weft).
LOOM_HD inline double stiffness_at_edge_angle(double phi, double b_edge_weft, double b_bias, double b_edge_warp) {
  constexpr double pi = 3.14159265358979323846;
  double f = std::fmod(std::fabs(phi), pi);  // [0, pi)
  if (f > pi / 2) f = pi - f;                // [0, pi/2]
  const double t = f / (pi / 4);             // [0, 2]
  if (t <= 1) return b_edge_weft + (b_bias - b_edge_weft) * t;
  return b_bias + (b_edge_warp - b_bias) * (t - 1);
}

}  // namespace loom::bending

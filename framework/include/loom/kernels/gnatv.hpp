// GNATV triangle element (Volino et al. 2009, corrected as in NUMERICS.md section 2):
// per-triangle rest data, strain, energy, force and force Jacobian. Header-only and
// LOOM_HD so the CPU and the CUDA backend (plugins/backends/cuda) share the math. Templated on the scalar T
// of the computation (double, float, or a complex-step/dual type in tests) and on the
// storage type R of the rest data and curves.
#pragma once

#include <cmath>

#include "loom/common.hpp"
#include "loom/curves.hpp"

namespace loom::gnatv {

/// Rest data of one triangle: r_u, r_v (gradients of the barycentric coordinates in the
/// isometric rest frame, weft = +x), and the rest area s (held constant, G2).
template <class R = double>
struct RestTriangle {
  R ru[3];
  R rv[3];
  R area;
};

/// The three stress-strain curves.
template <class R = double>
struct Curves {
  CurveView<R> uu, vv, uv;
};

/// Rest coefficients from an isometric 2D copy (a, b, c) of the rest triangle with weft
/// along +x (NUMERICS.md 2.1, signed d). Returns false when the triangle is degenerate
/// (|d| <= min_d).
template <class R>
LOOM_HD inline bool rest_from_2d(const R a[2], const R b[2], const R c[2], RestTriangle<R>& t, R min_d = R(0)) {
  const R d = (b[0] - a[0]) * (c[1] - a[1]) - (b[1] - a[1]) * (c[0] - a[0]);
  if (!(std::fabs(d) > min_d)) return false;
  t.ru[0] = (b[1] - c[1]) / d;
  t.ru[1] = (c[1] - a[1]) / d;
  t.ru[2] = (a[1] - b[1]) / d;
  t.rv[0] = (c[0] - b[0]) / d;
  t.rv[1] = (a[0] - c[0]) / d;
  t.rv[2] = (b[0] - a[0]) / d;
  t.area = std::fabs(d) / R(2);
  return true;
}

/// Deformation vectors u = sum r_uj P_j, v = sum r_vj P_j (P: 3 points of 3 coordinates).
template <class T, class R>
LOOM_HD inline void deformation(const RestTriangle<R>& t, const T P[3][3], T u[3], T v[3]) {
  for (int k = 0; k < 3; ++k) {
    u[k] = T(t.ru[0]) * P[0][k] + T(t.ru[1]) * P[1][k] + T(t.ru[2]) * P[2][k];
    v[k] = T(t.rv[0]) * P[0][k] + T(t.rv[1]) * P[1][k] + T(t.rv[2]) * P[2][k];
  }
}

template <class T>
LOOM_HD inline T dot3(const T a[3], const T b[3]) {
  return a[0] * b[0] + a[1] * b[1] + a[2] * b[2];
}

/// Green strains (eps_uu, eps_vv, eps_uv) with eps_uv = u.v.
template <class T>
LOOM_HD inline void strains(const T u[3], const T v[3], T eps[3]) {
  eps[0] = T(0.5) * (dot3(u, u) - T(1));
  eps[1] = T(0.5) * (dot3(v, v) - T(1));
  eps[2] = dot3(u, v);
}

/// Elastic energy s (W_uu + W_vv + W_uv) of one triangle.
template <class T, class R>
LOOM_HD inline T energy(const RestTriangle<R>& t, const Curves<R>& c, const T P[3][3]) {
  T u[3], v[3], e[3], W[3], s, ds;
  deformation(t, P, u, v);
  strains(u, v, e);
  curve_eval(c.uu, e[0], W[0], s, ds);
  curve_eval(c.vv, e[1], W[1], s, ds);
  curve_eval(c.uv, e[2], W[2], s, ds);
  return T(t.area) * (W[0] + W[1] + W[2]);
}

/// Forces F[j] = -d(s W)/dP_j (NUMERICS.md 2.2). Returns the triangle's energy (0 when
/// WithEnergy is false, which skips the energy's evaluation).
template <class T, class R, bool WithEnergy = true>
LOOM_HD inline T forces(const RestTriangle<R>& t, const Curves<R>& c, const T P[3][3], T F[3][3]) {
  T u[3], v[3], e[3], W[3] = {T(0), T(0), T(0)}, sg[3], ds;
  deformation(t, P, u, v);
  strains(u, v, e);
  curve_eval_raw<WithEnergy>(c.uu, e[0], W[0], sg[0], ds);
  curve_eval_raw<WithEnergy>(c.vv, e[1], W[1], sg[1], ds);
  curve_eval_raw<WithEnergy>(c.uv, e[2], W[2], sg[2], ds);
  if constexpr (WithEnergy) {
    W[0] = W[0] - T(c.uu.w_offset);
    W[1] = W[1] - T(c.vv.w_offset);
    W[2] = W[2] - T(c.uv.w_offset);
  }
  const T s = T(t.area);
  for (int j = 0; j < 3; ++j) {
    const T a = T(t.ru[j]), b = T(t.rv[j]);
    // -s [ s_uu r_uj u + s_vv r_vj v + s_uv (r_uj v + r_vj u) ]
    const T cu = s * (sg[0] * a + sg[2] * b);
    const T cv = s * (sg[1] * b + sg[2] * a);
    for (int k = 0; k < 3; ++k) F[j][k] = -(cu * u[k] + cv * v[k]);
  }
  if constexpr (WithEnergy) return s * (W[0] + W[1] + W[2]);
  return T(0);
}

/// PSD projection of the symmetric 2x2 [[a, c], [c, b]] (eigenvalues clamped at 0).
template <class T>
LOOM_HD inline void project_psd_2x2(T& a, T& b, T& c) {
  using std::sqrt;
  const T mean = T(0.5) * (a + b);
  const T half = T(0.5) * (a - b);
  const T r = sqrt(half * half + c * c);
  const T l1 = mean + r, l2 = mean - r;
  if (!(l2 < T(0))) return;            // already PSD
  if (!(l1 > T(0))) { a = b = c = T(0); return; }  // negative semidefinite
  // Sigma+ = l1 e1 e1^T = l1/(l1 - l2) (Sigma - l2 I), with l1 - l2 = 2r > 0.
  const T f = l1 / (T(2) * r);
  a = f * (a - l2);
  b = f * (b - l2);
  c = f * c;
}

/// Jacobian blocks J[j][i] = dF_j/dP_i (3x3 row-major, 9 blocks), NUMERICS.md 2.3 with
/// the corrected shear term (G1). With psd true the 2x2 stress is replaced by its PSD
/// projection in the geometric term and sigma' by max(0, sigma') (2.4), so -J is PSD;
/// with psd false it is the exact derivative of forces(). J[i][j] = J[j][i]^T exactly.
template <class T, class R>
LOOM_HD inline void jacobian(const RestTriangle<R>& t, const Curves<R>& c, const T P[3][3], bool psd,
                             T J[3][3][9]) {
  T u[3], v[3], e[3], sg[3], dsg[3];
  deformation(t, P, u, v);
  strains(u, v, e);
  curve_stress(c.uu, e[0], sg[0], dsg[0]);
  curve_stress(c.vv, e[1], sg[1], dsg[1]);
  curve_stress(c.uv, e[2], sg[2], dsg[2]);
  if (psd) {
    project_psd_2x2(sg[0], sg[1], sg[2]);
    for (int k = 0; k < 3; ++k)
      if (dsg[k] < T(0)) dsg[k] = T(0);
  }
  // Expand (r_uj v + r_vj u)(r_ui v + r_vi u)^T so that every block is
  //   J_ji = a uu^T + b vv^T + c vu^T + d uv^T + geo I
  // with a = -s (s'_uu r_uj r_ui + s'_uv r_vj r_vi), b = -s (s'_vv r_vj r_vi + s'_uv r_uj r_ui),
  // c = -s s'_uv r_uj r_vi, d = -s s'_uv r_vj r_ui, geo = -s r_j^T Sigma r_i.
  const T ms = -T(t.area);
  T UU[9], VV[9], UV[9];  // u u^T, v v^T, u v^T (v u^T = UV^T)
  for (int r = 0; r < 3; ++r)
    for (int q = 0; q < 3; ++q) {
      UU[3 * r + q] = u[r] * u[q];
      VV[3 * r + q] = v[r] * v[q];
      UV[3 * r + q] = u[r] * v[q];
    }
  for (int j = 0; j < 3; ++j) {
    const T uj = T(t.ru[j]), vj = T(t.rv[j]);
    for (int i = j; i < 3; ++i) {
      const T ui = T(t.ru[i]), vi = T(t.rv[i]);
      const T uu = uj * ui, vv = vj * vi, uvji = uj * vi, vuji = vj * ui;
      const T a = ms * (dsg[0] * uu + dsg[2] * vv);
      const T b = ms * (dsg[1] * vv + dsg[2] * uu);
      const T c = ms * dsg[2] * uvji;
      const T d = ms * dsg[2] * vuji;
      const T geo = ms * (sg[0] * uu + sg[1] * vv + sg[2] * (uvji + vuji));
      T* B = J[j][i];
      if (i == j) {  // symmetric block: compute the upper triangle, mirror it exactly
        for (int r = 0; r < 3; ++r)
          for (int q = r; q < 3; ++q) {
            B[3 * r + q] = a * UU[3 * r + q] + b * VV[3 * r + q] + c * UV[3 * q + r] + d * UV[3 * r + q];
            B[3 * q + r] = B[3 * r + q];
          }
      } else {
        for (int r = 0; r < 3; ++r)
          for (int q = 0; q < 3; ++q)
            B[3 * r + q] = a * UU[3 * r + q] + b * VV[3 * r + q] + c * UV[3 * q + r] + d * UV[3 * r + q];
      }
      B[0] += geo;
      B[4] += geo;
      B[8] += geo;
      if (i != j) {
        T* Bt = J[i][j];
        for (int r = 0; r < 3; ++r)
          for (int q = 0; q < 3; ++q) Bt[3 * q + r] = B[3 * r + q];
      }
    }
  }
}

/// Largest principal strain magnitude: max(|lambda_max - 1|, |1 - lambda_min|) with
/// lambda the principal stretches of the in-plane deformation (C = [[u.u, u.v],[u.v, v.v]]).
template <class T, class R>
LOOM_HD inline T max_principal_strain(const RestTriangle<R>& t, const T P[3][3]) {
  using std::sqrt;
  T u[3], v[3];
  deformation(t, P, u, v);
  const T a = dot3(u, u), b = dot3(v, v), c = dot3(u, v);
  const T mean = T(0.5) * (a + b), half = T(0.5) * (a - b);
  const T r = sqrt(half * half + c * c);
  T lmin = mean - r;
  if (lmin < T(0)) lmin = T(0);
  const T smax = sqrt(mean + r), smin = sqrt(lmin);
  const T e1 = smax - T(1), e2 = T(1) - smin;
  return e1 > e2 ? e1 : e2;
}

}  // namespace loom::gnatv

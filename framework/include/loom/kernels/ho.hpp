// Harmonic-oscillation (HO) spring integration: per-spring math, header-only, host+device.
//
// Corrected method of docs/NUMERICS.md section 1 (Kang & Cho 2011, re-derived). For a spring
// (i, j) with d = x_j - x_i, l = |d|, n = d / l, delta = l - l0, delta_dot = n . (v_j - v_i),
// W = w_i + w_j (inverse masses, 0 for pinned vertices), the relative axial motion over one
// step of length h is integrated exactly (undamped, or with an axial damper c, all regimes):
//
//   Delta(delta_dot) = a_x delta + a_v delta_dot          (exact velocity change)
//   Ex = delta(h) - delta - h delta_dot = b_x delta + b_v delta_dot   (exact excess displacement)
//
// and distributed with inverse-mass shares (equal and opposite impulses):
//   Delta v_i = + w_i s n,  Delta v_j = - w_j s n,   s  = kx delta + kv delta_dot,  kx = -a_x/W, kv = -a_v/W
//   Delta x_i = + w_i e n,  Delta x_j = - w_j e n,   e  = ex delta + ev delta_dot,  ex = -b_x/W, ev = -b_v/W
// (Delta x is added on top of the ballistic h v for the analytic-position variant "HO-A").
//
// The four per-spring constants depend only on k, c, W and h: they are computed once
// (ho_coefficients) and the per-step work is trig-free (ho_spring_s / ho_spring_se).
// The published Kang & Cho formula (eqs. 7-12, sign of eq. 12 fixed) has the same shape with
// |delta_dot| in place of delta_dot (kang_cho_coefficients); it converges to the cloth with k/2.
#pragma once

#include <cmath>
#include <limits>

#include "loom/common.hpp"

namespace loom::kernels {

/// sin(t)/t, accurate for every t (series below 1e-3).
template <class T>
LOOM_HD inline T ho_sinc(T t) {
  using std::abs;
  using std::sin;
  const T t2 = t * t;
  if (abs(t) < T(1e-3)) return T(1) - t2 / T(6) + t2 * t2 / T(120);
  return sin(t) / t;
}

/// (1 - cos t)/t^2 = sinc(t/2)^2 / 2: no cancellation at any t.
template <class T>
LOOM_HD inline T ho_c1(T t) {
  const T s = ho_sinc(t / T(2));
  return s * s / T(2);
}

/// (t - sin t)/t^3 (series below 0.25, where the closed form cancels).
template <class T>
LOOM_HD inline T ho_s2(T t) {
  using std::abs;
  using std::sin;
  const T t2 = t * t;
  if (abs(t) < T(0.25))
    return T(1) / T(6) - t2 * (T(1) / T(120) - t2 * (T(1) / T(5040) - t2 * (T(1) / T(362880) - t2 / T(39916800))));
  return (t - sin(t)) / (t2 * t);
}

/// sinh(a)/a for a >= 0 (series below 1e-2).
template <class T>
LOOM_HD inline T ho_sinhc(T a) {
  using std::sinh;
  const T a2 = a * a;
  if (a < T(1e-2)) return T(1) + a2 / T(6) + a2 * a2 / T(120) + a2 * a2 * a2 / T(5040);
  return sinh(a) / a;
}

/// Exact one-step map of the relative axial motion  delta'' = -omega2 delta - 2 beta delta'
/// over h, as  delta(h) = delta + h delta' + b_x delta + b_v delta',
///            delta'(h) = delta' + a_x delta + a_v delta'.
/// omega2 >= 0, beta >= 0. Handles the under-, critically and over-damped regimes without
/// overflow (exponentials are combined before they are evaluated) and omega2 = 0.
template <class T>
struct HoFlow {
  T a_x, a_v, b_x, b_v;
};

template <class T>
LOOM_HD inline HoFlow<T> ho_flow(T omega2, T beta, T h) {
  using std::cos;
  using std::exp;
  using std::expm1;
  using std::sin;
  using std::sqrt;
  HoFlow<T> f{};
  if (beta == T(0)) {
    // Undamped: series-safe closed forms (NUMERICS 1.2).
    const T th = sqrt(omega2) * h;
    const T th2 = th * th;
    f.a_x = -omega2 * h * ho_sinc(th);
    f.a_v = -th2 * ho_c1(th);
    f.b_x = -th2 * ho_c1(th);
    f.b_v = -h * th2 * ho_s2(th);
    return f;
  }
  // Damped (NUMERICS 1.3): E = exp(-beta h); ECm1 = E C - 1; ES = E S.
  const T bh = beta * h;
  const T wd2 = omega2 - beta * beta;
  T ECm1, ES;
  if (wd2 > T(0)) {
    const T thd = sqrt(wd2) * h;
    const T sh = sin(thd / T(2));
    const T em1 = expm1(-bh);
    ECm1 = em1 * cos(thd) - T(2) * sh * sh;
    ES = exp(-bh) * h * ho_sinc(thd);
  } else if (wd2 == T(0)) {
    ECm1 = expm1(-bh);
    ES = exp(-bh) * h;
  } else {
    const T a = sqrt(-wd2) * h;   // a <= beta h
    ECm1 = (expm1(a - bh) + expm1(-a - bh)) / T(2);
    if (a < T(1e-2))
      ES = exp(-bh) * h * ho_sinhc(a);
    else
      ES = h * (exp(a - bh) - exp(-a - bh)) / (T(2) * a);
  }
  f.a_x = -omega2 * ES;
  f.a_v = ECm1 - beta * ES;
  f.b_x = ECm1 + beta * ES;
  f.b_v = ES - h;
  return f;
}

/// Per-spring constants of the corrected HO update (see the header comment).
template <class T>
struct HoCoeffs {
  T kx = 0, kv = 0;   ///< velocity:  s = kx delta + kv delta_dot
  T ex = 0, ev = 0;   ///< position (HO-A):  e = ex delta + ev delta_dot
};

/// Coefficients for stiffness k, axial damper c, inverse masses wi, wj and step h.
/// Both ends pinned (W = 0): all zero (the spring is skipped).
template <class T>
LOOM_HD inline HoCoeffs<T> ho_coefficients(T k, T c, T wi, T wj, T h) {
  HoCoeffs<T> r{};
  const T W = wi + wj;
  if (!(W > T(0))) return r;
  if (c == T(0)) {
    // Avoid dividing by W: a_x/W = -k h sinc, a_v/W = b_x/W = -k h^2 c1, b_v/W = -k h^3 s2.
    const T th = std::sqrt(k * W) * h;
    const T hh = h * h;
    r.kx = k * h * ho_sinc(th);
    r.kv = k * hh * ho_c1(th);
    r.ex = r.kv;
    r.ev = k * hh * h * ho_s2(th);
    return r;
  }
  const HoFlow<T> f = ho_flow(k * W, c * W / T(2), h);
  r.kx = -f.a_x / W;
  r.kv = -f.a_v / W;
  r.ex = -f.b_x / W;
  r.ev = -f.b_v / W;
  return r;
}

/// Published Kang & Cho 2011 update (eqs. 7-12) with the sign of eq. 12 fixed, kept for
/// reproducing the paper. With A = sqrt(delta^2 + 2 mu delta_dot^2 / k) (eq. 7 as printed),
/// omega T0 = asin(delta/A) (principal branch), H = h mod 2 pi/omega and
/// phi = k A/(2 omega H) (cos omega T0 - cos omega(T0 + H)), the velocity change is
/// Delta v_i = h phi / m_i n. Since cos(asin(delta/A)) = sqrt(2 mu/k) |delta_dot| / A,
///   h phi = kx delta + ka |delta_dot|,
///   kx = h k sin(omega H)/(2 omega H),  ka = h k sqrt(2 mu/k) (1 - cos omega H)/(2 omega H).
/// A = 0 gives 0 (the printed asin(0/0) is NaN); H = 0 uses the limit H -> 0.
template <class T>
struct KangChoCoeffs {
  T kx = 0, ka = 0;
};

template <class T>
LOOM_HD inline KangChoCoeffs<T> kang_cho_coefficients(T k, T wi, T wj, T h) {
  using std::cos;
  using std::fmod;
  using std::sin;
  using std::sqrt;
  KangChoCoeffs<T> r{};
  const T W = wi + wj;
  if (!(W > T(0)) || !(k > T(0))) return r;
  const T mu = T(1) / W;
  const T omega = sqrt(k * W);
  const T two_pi = T(6.283185307179586476925286766559);
  const T H = fmod(h, two_pi / omega);
  const T th = omega * H;
  // sin(th)/(2 th) -> 1/2 and (1 - cos th)/(2 th) -> 0 as H -> 0.
  r.kx = h * k * ho_sinc(th) / T(2);
  // (1 - cos th)/(2 omega H) = th c1(th) / 2  (since th = omega H).
  r.ka = h * k * sqrt(T(2) * mu / k) * th * ho_c1(th) / T(2);
  return r;
}

// The per-spring functions below read the endpoints as x[a + e], x[b + e] (a = 3 i, b = 3 j):
// a base pointer plus an index lets a compiler turn a loop over springs into vector gathers.

/// Geometry of one spring: unit axis n (zero for a degenerate spring; its delta is then -l0, and
/// every impulse, a multiple of n, is zero), delta, delta_dot.
template <class T, class I>
LOOM_HD inline void ho_spring_axis(const T* x, const T* v, I a, I b, T l0, T n[3], T& delta, T& delta_dot) {
  using std::sqrt;
  const T d0 = x[b] - x[a], d1 = x[b + 1] - x[a + 1], d2 = x[b + 2] - x[a + 2];
  const T l2 = d0 * d0 + d1 * d1 + d2 * d2;
  const T l = sqrt(l2);
  // No comparison (a compare under -ftrapping-math, GCC's default, keeps loops over springs from
  // vectorising): adding the smallest normal number changes l only when l is below about 2^53
  // (double) or 2^24 (float) times it, so inv is 1/l to the bit for any spring longer than
  // about 1e-146 m (double) or 4e-16 m (float), with one square root per spring, not two. A
  // degenerate spring (d = 0) gets n = 0 (d times the finite 1/min), so its impulse s n is 0
  // whatever delta is.
  const T inv = T(1) / (l + std::numeric_limits<T>::min());
  n[0] = d0 * inv;
  n[1] = d1 * inv;
  n[2] = d2 * inv;
  delta = l - l0;
  delta_dot = n[0] * (v[b] - v[a]) + n[1] * (v[b + 1] - v[a + 1]) + n[2] * (v[b + 2] - v[a + 2]);
}

/// Velocity impulse per unit inverse mass of spring (i, j): returns s n in g, with
/// Delta v_i = +w_i g and Delta v_j = -w_j g.
template <class T, class I>
LOOM_HD inline void ho_spring_velocity(const T* x, const T* v, I a, I b, T l0, T kx, T kv, T g[3]) {
  T n[3], delta, delta_dot;
  ho_spring_axis(x, v, a, b, l0, n, delta, delta_dot);
  const T s = kx * delta + kv * delta_dot;
  g[0] = s * n[0];
  g[1] = s * n[1];
  g[2] = s * n[2];
}

/// Velocity and analytic-position increments per unit inverse mass (HO-A):
/// Delta v_i = +w_i g, Delta x_i = +w_i p (on top of h v_old), and minus for j.
template <class T, class I>
LOOM_HD inline void ho_spring_velocity_position(const T* x, const T* v, I a, I b, T l0, const HoCoeffs<T>& c,
                                                T g[3], T p[3]) {
  T n[3], delta, delta_dot;
  ho_spring_axis(x, v, a, b, l0, n, delta, delta_dot);
  const T s = c.kx * delta + c.kv * delta_dot;
  const T e = c.ex * delta + c.ev * delta_dot;
  for (int k = 0; k < 3; ++k) {
    g[k] = s * n[k];
    p[k] = e * n[k];
  }
}

/// Published-formula impulse per unit inverse mass (kang_cho_2011 variant).
template <class T, class I>
LOOM_HD inline void kang_cho_spring_velocity(const T* x, const T* v, I a, I b, T l0, T kx, T ka, T g[3]) {
  using std::abs;
  T n[3], delta, delta_dot;
  ho_spring_axis(x, v, a, b, l0, n, delta, delta_dot);
  const T s = kx * delta + ka * abs(delta_dot);
  g[0] = s * n[0];
  g[1] = s * n[1];
  g[2] = s * n[2];
}

/// The end of an HO step for one vertex, shared by the CPU plugin and the CUDA backend: dv is
/// the summed velocity change of the vertex's springs (already times its inverse mass) and, for
/// analytic_position, dx their summed displacement. Free vertices (w > 0) also get gravity:
/// hg = h g and gg = h^2 g / 2. velocity: v += dv + h g, then x += h v (the new v);
/// analytic_position: x += h v_old + h^2 g / 2 + dx, then v += dv + h g.
///
/// The multiply-adds are written as fma calls, so that no compiler contracts them differently in
/// different copies: the CPU plugin's vectorised finalisation (ho_finalise_block_avx2 in
/// plugins/integrators/harmonic_oscillation/ho_window.hpp) performs exactly these operations
/// and gives the same bits (tests/harmonic_oscillation, HoStorage.WindowedSweepIsBitIdentical).
template <class T, bool AnalyticPosition>
LOOM_HD inline void ho_finalise_vertex(T* x, T* v, const T* dv, const T* dx, T w, T h, const T hg[3], const T gg[3]) {
  using std::fma;
  const T f = w > T(0) ? T(1) : T(0);
  for (int e = 0; e < 3; ++e) {
    if constexpr (AnalyticPosition) x[e] = x[e] + fma(h, v[e], fma(f, gg[e], dx[e]));
    v[e] = v[e] + fma(f, hg[e], dv[e]);
    if constexpr (!AnalyticPosition) x[e] = fma(h, v[e], x[e]);
  }
}

}  // namespace loom::kernels

// Stress-strain curves for measured materials (GNATV): piecewise cubic Hermite
// interpolants of sampled data, their derivative and their exact integral.
//
// A curve sigma(eps) is stored by its knots x_k, values y_k and slopes m_k (k = 0..n-1).
// Two ways to choose the slopes:
//   - MonotoneCubic: Fritsch-Carlson/Butland slopes (PCHIP). Monotone data gives a
//     monotone interpolant, so sigma' >= 0 everywhere inside the data.
//   - BSpline: the C2 cubic spline through the samples (the interpolating cubic B-spline
//     on the sample knots) with clamped end slopes: given, or estimated by second-order
//     one-sided differences. It may overshoot, so sigma' can be negative in places.
// Outside [x_0, x_{n-1}] the curve continues linearly with the end slope, clamped at >= 0
// (never a negative stiffness past the data).
// The energy density W(eps) = integral from 0 to eps of sigma is the exact integral of the
// interpolant (quartic per segment), so sigma = W' to rounding.
//
// CurveView is a plain view (pointers + numbers) that the LOOM_HD evaluation functions
// take, so the same code runs on the host and, later, on a device.
#pragma once

#include <algorithm>
#include <cmath>
#include <cstddef>
#include <stdexcept>
#include <string>
#include <vector>

#include "loom/common.hpp"

namespace loom {

enum class CurveInterpolation { MonotoneCubic, BSpline };

/// Real part of a scalar used by the kernels (to choose a segment). Specialise for
/// other scalar types (complex-step, dual numbers) in the code that uses them.
template <class T>
struct ScalarReal {
  LOOM_HD static double get(const T& x) { return static_cast<double>(x); }
};

template <class R = double>
struct CurveView {
  const R* x = nullptr;      ///< knots, strictly increasing
  const R* y = nullptr;      ///< stress at the knots
  const R* m = nullptr;      ///< slope at the knots
  const R* cum = nullptr;    ///< integral of sigma from x_0 to x_k
  int n = 0;                 ///< number of knots (>= 2)
  R inv_step = 0;            ///< 1/step when the knots are uniform, else 0
  R left_slope = 0;          ///< slope used below x_0 (>= 0)
  R right_slope = 0;         ///< slope used above x_{n-1} (>= 0)
  R w_offset = 0;            ///< integral from x_0 to 0 (so that W(0) = 0)
};

/// Segment k with x_k <= e < x_{k+1} (clamped to 0..n-2).
template <class R>
LOOM_HD inline int curve_segment(const CurveView<R>& c, double e) {
  if (c.inv_step > 0) {
    int k = static_cast<int>(std::floor((e - static_cast<double>(c.x[0])) * static_cast<double>(c.inv_step)));
    return k < 0 ? 0 : (k > c.n - 2 ? c.n - 2 : k);
  }
  int lo = 0, hi = c.n - 1;  // binary search: x[lo] <= e < x[hi]
  while (hi - lo > 1) {
    int mid = (lo + hi) / 2;
    if (static_cast<double>(c.x[mid]) <= e) lo = mid; else hi = mid;
  }
  return lo;
}

/// Antiderivative P(e) = integral from x_0 to e of sigma, with sigma and sigma'
/// (P is left untouched when WithEnergy is false).
template <bool WithEnergy = true, class T, class R>
LOOM_HD inline void curve_eval_raw(const CurveView<R>& c, const T& e, T& P, T& s, T& ds) {
  const double er = ScalarReal<T>::get(e);
  const int last = c.n - 1;
  if (er < static_cast<double>(c.x[0])) {
    const T d = e - T(c.x[0]);
    s = T(c.y[0]) + T(c.left_slope) * d;
    ds = T(c.left_slope);
    if constexpr (WithEnergy) P = T(c.y[0]) * d + T(c.left_slope) * d * d * T(0.5);
    return;
  }
  if (er > static_cast<double>(c.x[last])) {
    const T d = e - T(c.x[last]);
    s = T(c.y[last]) + T(c.right_slope) * d;
    ds = T(c.right_slope);
    if constexpr (WithEnergy) P = T(c.cum[last]) + T(c.y[last]) * d + T(c.right_slope) * d * d * T(0.5);
    return;
  }
  const int k = curve_segment(c, er);
  const T h = T(c.x[k + 1] - c.x[k]);
  const T t = (e - T(c.x[k])) / h;
  const T y0 = T(c.y[k]), y1 = T(c.y[k + 1]);
  const T m0 = T(c.m[k]) * h, m1 = T(c.m[k + 1]) * h;  // slopes in t units
  const T t2 = t * t, t3 = t2 * t, t4 = t3 * t;
  // Hermite basis and its antiderivative (from 0).
  const T h00 = T(2) * t3 - T(3) * t2 + T(1), h10 = t3 - T(2) * t2 + t;
  const T h01 = T(-2) * t3 + T(3) * t2, h11 = t3 - t2;
  s = h00 * y0 + h10 * m0 + h01 * y1 + h11 * m1;
  const T d00 = T(6) * t2 - T(6) * t, d10 = T(3) * t2 - T(4) * t + T(1);
  const T d01 = T(-6) * t2 + T(6) * t, d11 = T(3) * t2 - T(2) * t;
  ds = (d00 * y0 + d10 * m0 + d01 * y1 + d11 * m1) / h;
  if constexpr (WithEnergy) {
    const T H00 = t - t3 + T(0.5) * t4, H10 = T(0.5) * t2 - t3 * T(2.0 / 3.0) + T(0.25) * t4;
    const T H01 = t3 - T(0.5) * t4, H11 = t4 * T(0.25) - t3 * T(1.0 / 3.0);
    P = T(c.cum[k]) + h * (H00 * y0 + H10 * m0 + H01 * y1 + H11 * m1);
  }
}

/// Energy density W(e) (W(0) = 0), stress sigma(e) = W'(e) and stiffness sigma'(e).
template <class T, class R>
LOOM_HD inline void curve_eval(const CurveView<R>& c, const T& e, T& W, T& s, T& ds) {
  curve_eval_raw(c, e, W, s, ds);
  W = W - T(c.w_offset);
}

/// Stress and stiffness only.
template <class T, class R>
LOOM_HD inline void curve_stress(const CurveView<R>& c, const T& e, T& s, T& ds) {
  T P;
  curve_eval_raw<false>(c, e, P, s, ds);
}

/// Error in a curve's data (the caller adds the file and line).
class CurveError : public std::runtime_error {
 public:
  CurveError(const std::string& what, int sample = -1) : std::runtime_error(what), sample_(sample) {}
  int sample() const { return sample_; }  ///< offending sample index, or -1

 private:
  int sample_;
};

/// A curve that owns its data. Build with Curve::build; evaluate through view().
class Curve {
 public:
  Curve() = default;

  /// Build from knots (strictly increasing) and stress samples (finite), n >= 2.
  /// For BSpline, left/right_slope give the clamped end slopes (NaN = estimate by a
  /// second-order one-sided difference). Throws CurveError.
  static Curve build(std::vector<double> strain, std::vector<double> stress, CurveInterpolation kind,
                     double bspline_left_slope = std::nan(""), double bspline_right_slope = std::nan("")) {
    const std::size_t n = strain.size();
    if (n < 2) throw CurveError("a curve needs at least 2 samples, got " + std::to_string(n));
    if (stress.size() != n)
      throw CurveError("strain and stress have different lengths (" + std::to_string(n) + " and " +
                       std::to_string(stress.size()) + ")");
    for (std::size_t k = 0; k < n; ++k) {
      if (!std::isfinite(strain[k])) throw CurveError("strain sample " + std::to_string(k) + " is not finite", int(k));
      if (!std::isfinite(stress[k])) throw CurveError("stress sample " + std::to_string(k) + " is not finite", int(k));
      if (k > 0 && !(strain[k] > strain[k - 1]))
        throw CurveError("strain samples must be strictly increasing; sample " + std::to_string(k) + " (" +
                             std::to_string(strain[k]) + ") is not above sample " + std::to_string(k - 1) +
                             " (" + std::to_string(strain[k - 1]) + ")",
                         int(k));
    }
    Curve c;
    c.kind_ = kind;
    c.x_ = std::move(strain);
    c.y_ = std::move(stress);
    c.m_.assign(n, 0.0);
    if (kind == CurveInterpolation::MonotoneCubic) c.pchip_slopes();
    else c.spline_slopes(bspline_left_slope, bspline_right_slope);
    c.finish();
    return c;
  }

  /// Uniform samples at start + k*step.
  static Curve build_uniform(double start, double step, std::vector<double> stress, CurveInterpolation kind,
                             double bspline_left_slope = std::nan(""), double bspline_right_slope = std::nan("")) {
    if (!std::isfinite(start)) throw CurveError("start is not finite");
    if (!(step > 0) || !std::isfinite(step))
      throw CurveError("step must be positive and finite (the strain grid must increase), got " + std::to_string(step));
    std::vector<double> x(stress.size());
    for (std::size_t k = 0; k < x.size(); ++k) x[k] = start + step * static_cast<double>(k);
    Curve c = build(std::move(x), std::move(stress), kind, bspline_left_slope, bspline_right_slope);
    c.uniform_step_ = step;
    c.x_0_ = start;
    return c;
  }

  CurveView<double> view() const {
    CurveView<double> v;
    v.x = x_.data(); v.y = y_.data(); v.m = m_.data(); v.cum = cum_.data();
    v.n = static_cast<int>(x_.size());
    v.inv_step = uniform_step_ > 0 ? 1.0 / uniform_step_ : 0.0;
    v.left_slope = left_slope_; v.right_slope = right_slope_;
    v.w_offset = w_offset_;
    return v;
  }

  double stress(double e) const { double s, d; curve_stress(view(), e, s, d); return s; }
  double stiffness(double e) const { double s, d; curve_stress(view(), e, s, d); return d; }
  double energy(double e) const { double W, s, d; curve_eval(view(), e, W, s, d); return W; }

  /// Smallest sigma' over the data range (exact: the minimum of each segment's quadratic).
  double min_stiffness() const {
    double best = std::min(left_slope_, right_slope_);
    for (std::size_t k = 0; k + 1 < x_.size(); ++k) {
      const double h = x_[k + 1] - x_[k];
      // sigma'(t)/1 = a t^2 + b t + c in t in [0,1] (times 1/h)
      const double y0 = y_[k], y1 = y_[k + 1], m0 = m_[k] * h, m1 = m_[k + 1] * h;
      const double a = 6 * y0 + 3 * m0 - 6 * y1 + 3 * m1;
      const double b = -6 * y0 - 4 * m0 + 6 * y1 - 2 * m1;
      const double cc = m0;
      double v = std::min(cc, a + b + cc);
      if (a > 0) {
        const double t = -b / (2 * a);
        if (t > 0 && t < 1) v = std::min(v, (a * t + b) * t + cc);
      }
      best = std::min(best, v / h);
    }
    return best;
  }

  const std::vector<double>& strain() const { return x_; }
  const std::vector<double>& samples() const { return y_; }
  const std::vector<double>& slopes() const { return m_; }
  double left_slope() const { return left_slope_; }
  double right_slope() const { return right_slope_; }
  CurveInterpolation kind() const { return kind_; }
  std::size_t size() const { return x_.size(); }

 private:
  // Fritsch-Carlson with Fritsch-Butland weighted harmonic means inside and the
  // shape-preserving three-point formula at the ends (slopes within the monotone region).
  void pchip_slopes() {
    const std::size_t n = x_.size();
    std::vector<double> h(n - 1), d(n - 1);
    for (std::size_t k = 0; k + 1 < n; ++k) {
      h[k] = x_[k + 1] - x_[k];
      d[k] = (y_[k + 1] - y_[k]) / h[k];
    }
    if (n == 2) { m_[0] = m_[1] = d[0]; return; }
    for (std::size_t k = 1; k + 1 < n; ++k) {
      if (d[k - 1] * d[k] <= 0) { m_[k] = 0; continue; }
      const double w1 = 2 * h[k] + h[k - 1], w2 = h[k] + 2 * h[k - 1];
      m_[k] = (w1 + w2) / (w1 / d[k - 1] + w2 / d[k]);
    }
    auto end = [](double h0, double h1, double d0, double d1) {
      double m = ((2 * h0 + h1) * d0 - h0 * d1) / (h0 + h1);
      if (m * d0 <= 0) m = 0;
      else if (d0 * d1 <= 0 && std::fabs(m) > 3 * std::fabs(d0)) m = 3 * d0;
      return m;
    };
    m_[0] = end(h[0], h[1], d[0], d[1]);
    m_[n - 1] = end(h[n - 2], h[n - 3], d[n - 2], d[n - 3]);
  }

  // C2 cubic spline with clamped end slopes: for interior k,
  // h_k m_{k-1} + 2(h_{k-1}+h_k) m_k + h_{k-1} m_{k+1} = 3(h_k d_{k-1} + h_{k-1} d_k).
  void spline_slopes(double left, double right) {
    const std::size_t n = x_.size();
    std::vector<double> h(n - 1), d(n - 1);
    for (std::size_t k = 0; k + 1 < n; ++k) {
      h[k] = x_[k + 1] - x_[k];
      d[k] = (y_[k + 1] - y_[k]) / h[k];
    }
    if (std::isnan(left)) left = n >= 3 ? ((2 * h[0] + h[1]) * d[0] - h[0] * d[1]) / (h[0] + h[1]) : d[0];
    if (std::isnan(right))
      right = n >= 3 ? ((2 * h[n - 2] + h[n - 3]) * d[n - 2] - h[n - 2] * d[n - 3]) / (h[n - 2] + h[n - 3]) : d[0];
    m_[0] = left;
    m_[n - 1] = right;
    if (n == 2) return;
    // Thomas algorithm on the interior unknowns m_1..m_{n-2}.
    const std::size_t q = n - 2;
    std::vector<double> lo(q), di(q), up(q), rhs(q);
    for (std::size_t i = 0; i < q; ++i) {
      const std::size_t k = i + 1;
      lo[i] = h[k];
      di[i] = 2 * (h[k - 1] + h[k]);
      up[i] = h[k - 1];
      rhs[i] = 3 * (h[k] * d[k - 1] + h[k - 1] * d[k]);
    }
    rhs[0] -= lo[0] * m_[0];
    rhs[q - 1] -= up[q - 1] * m_[n - 1];
    for (std::size_t i = 1; i < q; ++i) {
      const double w = lo[i] / di[i - 1];
      di[i] -= w * up[i - 1];
      rhs[i] -= w * rhs[i - 1];
    }
    m_[q] = rhs[q - 1] / di[q - 1];
    for (std::size_t i = q - 1; i-- > 0;) m_[i + 1] = (rhs[i] - up[i] * m_[i + 2]) / di[i];
  }

  void finish() {
    const std::size_t n = x_.size();
    left_slope_ = std::max(0.0, m_[0]);
    right_slope_ = std::max(0.0, m_[n - 1]);
    cum_.assign(n, 0.0);
    for (std::size_t k = 0; k + 1 < n; ++k) {
      const double h = x_[k + 1] - x_[k];
      cum_[k + 1] = cum_[k] + h * (0.5 * (y_[k] + y_[k + 1]) + h * (m_[k] - m_[k + 1]) / 12.0);
    }
    double P, s, ds;
    w_offset_ = 0;
    curve_eval_raw(view(), 0.0, P, s, ds);
    w_offset_ = P;
  }

  CurveInterpolation kind_ = CurveInterpolation::MonotoneCubic;
  std::vector<double> x_, y_, m_, cum_;
  double uniform_step_ = 0, x_0_ = 0;
  double left_slope_ = 0, right_slope_ = 0, w_offset_ = 0;
};

}  // namespace loom

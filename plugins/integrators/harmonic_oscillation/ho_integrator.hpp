// harmonic_oscillation: Kang & Cho 2011 per-spring harmonic-oscillation integration, corrected
// (docs/NUMERICS.md section 1; per-spring math in loom/kernels/ho.hpp).
//
// Variants:
//   velocity          exact per-spring velocity change (inverse-mass shares), then x += h v_new
//   analytic_position also the exact per-spring position increment (HO-A), x += h (v_old + h g/2) + dx
//   kang_cho_2011     the published formula (eqs. 7-12, sign of eq. 12 fixed); converges to k/2
// Springs are superposed Jacobi-style (every spring sees the state at the start of the step).
#pragma once

#include <array>
#include <cstddef>
#include <string>
#include <vector>

#include "loom/integrator.hpp"
#include "loom/kernels/ho.hpp"
#include "loom/params.hpp"
#include "loom/spring_layout.hpp"

#ifdef _OPENMP
#include <omp.h>
#else
inline int omp_get_max_threads() { return 1; }
#endif

namespace loom {

enum class HoVariant { Velocity, AnalyticPosition, KangCho2011 };
HoVariant parse_ho_variant(const std::string& s);
const char* to_string(HoVariant v);

/// Springs in traversal order with i < j and their per-step constants. T = double in the
/// plugin; the benchmark also builds a float copy.
template <class T>
struct HoSprings {
  std::vector<Index> i, j;
  std::vector<T> l0, k, c;        ///< rest length, stiffness, axial damper (from the material)
  std::vector<T> kx, kv;          ///< velocity constants (kang_cho_2011: kx, ka)
  std::vector<T> ex, ev;          ///< position constants (analytic_position only)
  Index size() const { return static_cast<Index>(i.size()); }
};

/// Build the traversal layout and the spring arrays from a spring set over n vertices.
void build_ho_springs(Index n, const SpringSet& set, SpringLayout& layout, HoSprings<double>& out);

/// Below this many springs a step runs on the calling thread.
constexpr Index kHoSerialSprings = 8192;

/// (Re)compute the per-spring constants for step h and inverse masses w.
template <class T>
void update_ho_coefficients(HoSprings<T>& s, HoVariant variant, const T* w, T h) {
  const Index S = s.size();
  const bool pos = variant == HoVariant::AnalyticPosition;
  s.kx.resize(S);
  s.kv.resize(S);
  s.ex.resize(pos ? S : 0);
  s.ev.resize(pos ? S : 0);
  // coefficients are computed in double even for float data
#pragma omp parallel for schedule(static) if (S >= kHoSerialSprings)
  for (Index q = 0; q < S; ++q) {
    const double wi = static_cast<double>(w[s.i[q]]), wj = static_cast<double>(w[s.j[q]]);
    if (variant == HoVariant::KangCho2011) {
      const auto c = kernels::kang_cho_coefficients<double>(s.k[q], wi, wj, h);
      s.kx[q] = static_cast<T>(c.kx);
      s.kv[q] = static_cast<T>(c.ka);
    } else {
      const auto c = kernels::ho_coefficients<double>(s.k[q], s.c[q], wi, wj, h);
      s.kx[q] = static_cast<T>(c.kx);
      s.kv[q] = static_cast<T>(c.kv);
      if (pos) {
        s.ex[q] = static_cast<T>(c.ex);
        s.ev[q] = static_cast<T>(c.ev);
      }
    }
  }
}

/// One HO step on raw arrays (3n positions/velocities, n inverse masses), race free through
/// the layout, no allocation. vnew and xnew are work arrays of 3n (xnew used by
/// analytic_position only). On return x and v hold the new state (for analytic_position the
/// new positions are in xnew and the new velocities in vnew: the caller swaps).
template <class T, HoVariant V>
void ho_step_arrays(const SpringLayout& layout, const HoSprings<T>& s, T* x, T* v, T* vnew, T* xnew,
                    const T* w, T h, const std::array<T, 3>& g) {
  const Index* I = s.i.data();
  const Index* J = s.j.data();
  const T* L0 = s.l0.data();
  const T* KX = s.kx.data();
  const T* KV = s.kv.data();
  const T* EX = s.ex.data();
  const T* EV = s.ev.data();
  const T hg0 = h * g[0], hg1 = h * g[1], hg2 = h * g[2];
  const T hh2 = h * h / T(2);
  auto init = [&](Index v0, Index v1) {
    for (Index q = v0; q < v1; ++q) {
      const T f = w[q] > T(0) ? T(1) : T(0);
      const std::size_t d = 3 * static_cast<std::size_t>(q);
      vnew[d] = v[d] + f * hg0;
      vnew[d + 1] = v[d + 1] + f * hg1;
      vnew[d + 2] = v[d + 2] + f * hg2;
      if constexpr (V == HoVariant::AnalyticPosition) {
        xnew[d] = x[d] + h * v[d] + f * hh2 * g[0];
        xnew[d + 1] = x[d + 1] + h * v[d + 1] + f * hh2 * g[1];
        xnew[d + 2] = x[d + 2] + h * v[d + 2] + f * hh2 * g[2];
      }
    }
  };
  auto body = [&](Index q) {
    const std::size_t a = 3 * static_cast<std::size_t>(I[q]);
    const std::size_t b = 3 * static_cast<std::size_t>(J[q]);
    const T wi = w[I[q]], wj = w[J[q]];
    T gv[3];
    if constexpr (V == HoVariant::AnalyticPosition) {
      const kernels::HoCoeffs<T> c{KX[q], KV[q], EX[q], EV[q]};
      T p[3];
      kernels::ho_spring_velocity_position(x + a, x + b, v + a, v + b, L0[q], c, gv, p);
      for (int e = 0; e < 3; ++e) {
        xnew[a + e] += wi * p[e];
        xnew[b + e] -= wj * p[e];
      }
    } else if constexpr (V == HoVariant::KangCho2011) {
      kernels::kang_cho_spring_velocity(x + a, x + b, v + a, v + b, L0[q], KX[q], KV[q], gv);
    } else {
      kernels::ho_spring_velocity(x + a, x + b, v + a, v + b, L0[q], KX[q], KV[q], gv);
    }
    for (int e = 0; e < 3; ++e) {
      vnew[a + e] += wi * gv[e];
      vnew[b + e] -= wj * gv[e];
    }
  };
  const bool serial = s.size() < kHoSerialSprings || omp_get_max_threads() == 1;
  if (serial) {
    // small problems: a parallel region costs more than the work (and far more on a loaded machine)
    init(0, layout.num_vertices());
    for (Index q = 0; q < s.size(); ++q) body(q);
  } else {
    layout.for_each(init, body);
  }
  if constexpr (V != HoVariant::AnalyticPosition) {
    const std::ptrdiff_t m = 3 * static_cast<std::ptrdiff_t>(layout.num_vertices());
#pragma omp parallel for schedule(static) if (!serial)
    for (std::ptrdiff_t d = 0; d < m; ++d) {
      x[d] += h * vnew[d];
      v[d] = vnew[d];
    }
  }
}

class HoIntegrator final : public Integrator {
 public:
  explicit HoIntegrator(const Params& p = Params());
  explicit HoIntegrator(HoVariant variant) : variant_(variant) {}
  std::string name() const override { return "harmonic_oscillation"; }
  IntegratorNeeds needs() const override { return {true, false, false}; }
  void prepare(Scene& scene, double h) override;
  void step(Scene& scene, double h) override;
  StepStats last_step() const override { return {}; }

  HoVariant variant() const { return variant_; }
  const HoSprings<double>& springs() const { return springs_; }
  const SpringLayout& layout() const { return layout_; }

 private:
  HoVariant variant_ = HoVariant::Velocity;
  SpringLayout layout_;
  HoSprings<double> springs_;
  std::vector<double> vnew_, xnew_;
  double h_ = -1;
  const SpringSet* source_ = nullptr;
};

}  // namespace loom

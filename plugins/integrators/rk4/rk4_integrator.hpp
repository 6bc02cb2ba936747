// rk4: classical fourth-order Runge-Kutta over (x, v). Four force evaluations per step,
// forces divided by mass, pinned vertices follow their prescribed velocity at every stage.
#pragma once

#include <array>
#include <cstddef>
#include <vector>

#include "loom/explicit_springs.hpp"
#include "loom/integrator.hpp"
#include "loom/kernels/rk4.hpp"
#include "loom/param_spec.hpp"
#include "loom/params.hpp"

namespace loom {

/// Below this many vertices the vertex loops run on the calling thread.
constexpr Index kRk4SerialVertices = kParallelMinVertices;  // the rule in common.hpp

/// One RK4 step on raw arrays (3n each; w has n entries). force(xs, vs, f) overwrites f with
/// the internal forces at (xs, vs). Work arrays xs, vs, f, ax, av (3n each) are the caller's.
template <class T, class Force>
void rk4_step_arrays(Index n, T* x, T* v, const T* w, const std::array<T, 3>& g, T h, T* xs, T* vs, T* f, T* ax,
                     T* av, Force&& force) {
  using namespace kernels;
  const T hh = h / T(2);
  const bool par = n >= kRk4SerialVertices;
  force(static_cast<const T*>(x), static_cast<const T*>(v), f);
#pragma omp parallel for schedule(static) if (par)
  for (Index i = 0; i < n; ++i)
    for (int a = 0; a < 3; ++a) {
      const std::size_t d = 3 * static_cast<std::size_t>(i) + a;
      rk4_first(x[d], v[d], rk4_accel(f[d], w[i], g[a]), xs[d], vs[d], ax[d], av[d], hh);
    }
  for (int stage = 2; stage <= 3; ++stage) {
    force(static_cast<const T*>(xs), static_cast<const T*>(vs), f);
    const T next = stage == 2 ? hh : h;
#pragma omp parallel for schedule(static) if (par)
    for (Index i = 0; i < n; ++i)
      for (int a = 0; a < 3; ++a) {
        const std::size_t d = 3 * static_cast<std::size_t>(i) + a;
        rk4_middle(x[d], v[d], rk4_accel(f[d], w[i], g[a]), xs[d], vs[d], ax[d], av[d], next);
      }
  }
  force(static_cast<const T*>(xs), static_cast<const T*>(vs), f);
#pragma omp parallel for schedule(static) if (par)
  for (Index i = 0; i < n; ++i)
    for (int a = 0; a < 3; ++a) {
      const std::size_t d = 3 * static_cast<std::size_t>(i) + a;
      rk4_last(x[d], v[d], rk4_accel(f[d], w[i], g[a]), vs[d], ax[d], av[d], h);
    }
}

/// RK4 on a spring network with each stage update fused into the force pass (SpringSweep: one
/// parallel region per stage instead of two). before(stage) runs before the force pass of
/// stages 2, 3 and 4 (the caller places moving pins into xs, vs there). f: zero on entry and
/// on return.
template <class T, class Before>
void rk4_step_springs(const SpringSweep<T>& sw, T* x, T* v, const T* w, const std::array<T, 3>& g, T h, T* xs,
                      T* vs, T* f, T* ax, T* av, Before&& before) {
  using namespace kernels;
  const T hh = h / T(2);
  sw.forces(x, v, f, [=](Index q, const T* fq) {
    for (int a = 0; a < 3; ++a) {
      const std::size_t d = 3 * static_cast<std::size_t>(q) + a;
      rk4_first(x[d], v[d], rk4_accel(fq[a], w[q], g[a]), xs[d], vs[d], ax[d], av[d], hh);
    }
  });
  for (int stage = 2; stage <= 3; ++stage) {
    before(stage);
    const T next = stage == 2 ? hh : h;
    sw.forces(xs, vs, f, [=](Index q, const T* fq) {
      for (int a = 0; a < 3; ++a) {
        const std::size_t d = 3 * static_cast<std::size_t>(q) + a;
        rk4_middle(x[d], v[d], rk4_accel(fq[a], w[q], g[a]), xs[d], vs[d], ax[d], av[d], next);
      }
    });
  }
  before(4);
  sw.forces(xs, vs, f, [=](Index q, const T* fq) {
    for (int a = 0; a < 3; ++a) {
      const std::size_t d = 3 * static_cast<std::size_t>(q) + a;
      rk4_last(x[d], v[d], rk4_accel(fq[a], w[q], g[a]), vs[d], ax[d], av[d], h);
    }
  });
}

/// The keys of rk4 (cpu and cuda): merge_springs on the cpu; precision and host_sync_every on cuda.
const ParamSpec& rk4_spec();

class Rk4Integrator final : public Integrator {
 public:
  explicit Rk4Integrator(const Params& p = Params());
  std::string name() const override { return "rk4"; }
  void prepare(Scene& scene, double h) override;
  void step(Scene& scene, double h) override;
  StepStats last_step() const override { return stats_; }
  /// Whether the step runs the fused spring path (a spring material).
  bool fused() const { return sweep_source_ != nullptr; }
  /// Springs the fused path folded into others (key `merge_springs`; 0 before prepare()).
  Index merged_springs() const { return fused() ? sweep_.merged : 0; }

 private:
  std::vector<double> xs_, vs_, f_, accx_, accv_;
  SpringSweep<double> sweep_;
  const SpringSet* sweep_source_ = nullptr;
  StepStats stats_;
};

}  // namespace loom

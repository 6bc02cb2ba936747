#include "rk4_integrator.hpp"


#include "loom/kernels/rk4.hpp"

namespace loom {

Rk4Integrator::Rk4Integrator(const Params&) {}

void Rk4Integrator::prepare(Scene& scene, double) {
  if (!scene.material) throw InputError(scene.source + ": rk4 needs a material; add a 'material:' section");
  const std::size_t m = scene.state.x.size();
  xs_.assign(m, 0.0);
  vs_.assign(m, 0.0);
  f_.assign(m, 0.0);
  accx_.assign(m, 0.0);
  accv_.assign(m, 0.0);
  stats_ = {};
  stats_.force_evaluations = 4;
}

void Rk4Integrator::step(Scene& scene, double h) {
  State& s = scene.state;
  const Material& mat = *scene.material;
  if (xs_.size() != s.x.size()) prepare(scene, h);
  const Index n = s.size();
  double* x = s.x.data();
  double* v = s.v.data();
  const double* w = s.inv_mass.data();
  double* xs = xs_.data();
  double* vs = vs_.data();
  double* f = f_.data();
  double* ax = accx_.data();
  double* av = accv_.data();
  const double g0 = scene.gravity[0], g1 = scene.gravity[1], g2 = scene.gravity[2];
  const double hh = 0.5 * h;
  using namespace kernels;

  // Stage 1 at (x, v).
  mat.compute_forces(s.x, s.v, f_);
#pragma omp parallel for schedule(static) if (n >= 4096)
  for (Index i = 0; i < n; ++i) {
    const double g[3] = {g0, g1, g2};
    for (int a = 0; a < 3; ++a) {
      const std::size_t d = 3 * static_cast<std::size_t>(i) + a;
      rk4_first(x[d], v[d], rk4_accel(f[d], w[i], g[a]), xs[d], vs[d], ax[d], av[d], hh);
    }
  }
  // Stages 2 and 3.
  for (int stage = 2; stage <= 3; ++stage) {
    mat.compute_forces(xs_, vs_, f_);
    const double next = stage == 2 ? hh : h;
#pragma omp parallel for schedule(static) if (n >= 4096)
    for (Index i = 0; i < n; ++i) {
      const double g[3] = {g0, g1, g2};
      for (int a = 0; a < 3; ++a) {
        const std::size_t d = 3 * static_cast<std::size_t>(i) + a;
        rk4_middle(x[d], v[d], rk4_accel(f[d], w[i], g[a]), xs[d], vs[d], ax[d], av[d], next);
      }
    }
  }
  // Stage 4 and the update.
  mat.compute_forces(xs_, vs_, f_);
#pragma omp parallel for schedule(static) if (n >= 4096)
  for (Index i = 0; i < n; ++i) {
    const double g[3] = {g0, g1, g2};
    for (int a = 0; a < 3; ++a) {
      const std::size_t d = 3 * static_cast<std::size_t>(i) + a;
      rk4_last(x[d], v[d], rk4_accel(f[d], w[i], g[a]), vs[d], ax[d], av[d], h);
    }
  }
  finish_step(s, h);
}

}  // namespace loom

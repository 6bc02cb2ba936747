#include "rk4_integrator.hpp"

#include <span>

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
  const std::size_t m = s.x.size();
  const std::array<double, 3> g{scene.gravity[0], scene.gravity[1], scene.gravity[2]};
  rk4_step_arrays<double>(s.size(), s.x.data(), s.v.data(), s.inv_mass.data(), g, h, xs_.data(), vs_.data(),
                          f_.data(), accx_.data(), accv_.data(),
                          [&](const double* x, const double* v, double* f) {
                            mat.compute_forces(std::span<const double>(x, m), std::span<const double>(v, m),
                                               std::span<double>(f, m));
                          });
  finish_step(s, h);
}

}  // namespace loom

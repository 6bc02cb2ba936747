#include "rk4_integrator.hpp"

#include <span>
#include <stdexcept>

namespace loom {

const ParamSpec& rk4_spec() {
  static const ParamSpec spec = [] {
    ParamSpec s("rk4", "classical 4th-order Runge-Kutta");
    s.flag("merge_springs", SpringSweep<double>::kMergeDuplicatesDefault).backends({"cpu", "cuda"}).help(kMergeSpringsHelp);
    declare_device_keys(s);
    return s;
  }();
  return spec;
}

Rk4Integrator::Rk4Integrator(const Params& p) {
  if (p.valid()) {
    if (p.has("type")) p.mark_used("type");
    sweep_.merge_duplicates = ParamReader(p, rk4_spec()).flag("merge_springs");
  }
}

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
  const SpringSet* set = scene.material->springs();
  const Index n = scene.state.size();
  if (set && (set != sweep_source_ || sweep_.n != n || sweep_.source_size != set->size())) sweep_.build(n, *set);
  sweep_source_ = set;
}

void Rk4Integrator::step(Scene& scene, double h) {
  State& s = scene.state;
  const Material& mat = *scene.material;
  if (xs_.size() != s.x.size()) prepare(scene, h);
  const std::size_t m = s.x.size();
  const std::array<double, 3> g{scene.gravity[0], scene.gravity[1], scene.gravity[2]};
  // Stage k (1..4) evaluates forces at time t + c_k h, c = (0, 1/2, 1/2, 1). Moving pins are
  // placed at that time in the stage arrays (xs, vs) before the force evaluation, so every
  // stage sees the prescribed pins; at the end they get exactly p(t + h), v(t + h).
  const PinSet& pins = scene.pins;
  const double t0 = s.time;
  if (sweep_source_) {
    if (mat.springs() != sweep_source_) throw std::logic_error("rk4: material changed after prepare()");
    rk4_step_springs<double>(sweep_, s.x.data(), s.v.data(), s.inv_mass.data(), g, h, xs_.data(), vs_.data(),
                             f_.data(), accx_.data(), accv_.data(), [&](int stage) {
                               if (pins.moving()) pins.place(t0 + (stage == 4 ? h : 0.5 * h), xs_.data(), vs_.data());
                             });
    pins.apply(s, t0 + h);
    finish_step(s, h);
    return;
  }
  int stage = 0;
  rk4_step_arrays<double>(s.size(), s.x.data(), s.v.data(), s.inv_mass.data(), g, h, xs_.data(), vs_.data(),
                          f_.data(), accx_.data(), accv_.data(),
                          [&](const double* x, const double* v, double* f) {
                            ++stage;
                            if (stage > 1 && pins.moving())
                              pins.place(t0 + (stage == 4 ? h : 0.5 * h), xs_.data(), vs_.data());
                            mat.compute_forces(std::span<const double>(x, m), std::span<const double>(v, m),
                                               std::span<double>(f, m));
                          });
  pins.apply(s, t0 + h);
  finish_step(s, h);
}

}  // namespace loom

// Forward Euler: the smallest complete integrator plugin.
#include <loom/plugin.hpp>

class ToyEuler final : public loom::Integrator {
 public:
  std::string name() const override { return "toy_euler"; }
  void prepare(loom::Scene& scene, double) override { f_.assign(scene.state.x.size(), 0.0); }
  void step(loom::Scene& scene, double h) override {
    loom::State& s = scene.state;
    scene.material->compute_forces(s.x, s.v, f_);
    for (loom::Index i = 0; i < s.size(); ++i)
      for (int k = 0; k < 3; ++k) {
        s.x[3 * i + k] += h * s.v[3 * i + k];
        if (s.inv_mass[i] > 0) s.v[3 * i + k] += h * (s.inv_mass[i] * f_[3 * i + k] + scene.gravity[k]);
      }
    loom::finish_step(s, h);
  }

 private:
  std::vector<double> f_;
};

static const loom::ParamSpec& toy_spec() {
  static const loom::ParamSpec spec("toy_euler", "forward Euler: no keys of its own (dt, substeps: the framework's)");
  return spec;
}

static void register_toy(loom::Registry& r) {
  r.add_integrator({loom::PluginKind::Integrator, "toy_euler", "cpu", "0.1", "out-of-tree example: forward Euler", "",
                    &toy_spec()},
                   [](const loom::Params&) { return std::make_unique<ToyEuler>(); });
}
LOOM_PLUGIN(register_toy)

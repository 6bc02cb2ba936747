// Test integrator: forward Euler with gravity; `blow_up_at` multiplies velocities by 1e6 at
// that step so that the divergence guard can be tested; `retry_at` reports that step as one
// halving after a failed solve (StepStats::retries), for the run summary's count.
#include <loom/plugin.hpp>

namespace {
class ExplicitEuler final : public loom::Integrator {
 public:
  explicit ExplicitEuler(const loom::Params& p)
      : blow_up_at_(p.get("blow_up_at", -1)), nan_at_(p.get("nan_at", -1)), retry_at_(p.get("retry_at", -1)) {}
  std::string name() const override { return "test_explicit_euler"; }
  void prepare(loom::Scene& s, double) override { f_.assign(s.state.x.size(), 0.0); }
  void step(loom::Scene& s, double h) override {
    auto& st = s.state;
    s.material->compute_forces(st.x, st.v, f_);
    for (loom::Index i = 0; i < st.size(); ++i) {
      const double w = st.inv_mass[i];
      for (int k = 0; k < 3; ++k) {
        st.x[3 * i + k] += h * st.v[3 * i + k];
        if (w > 0) st.v[3 * i + k] += h * (w * f_[3 * i + k] + s.gravity[k]);
      }
    }
    if (st.step == blow_up_at_) st.v[3 * 5 + 1] *= 1e6;
    if (st.step == nan_at_) st.x[3 * 7] = 0.0 / 0.0;
    retried_ = st.step == retry_at_ ? 1 : 0;
    loom::finish_step(st, h);
  }
  loom::StepStats last_step() const override { return {1, 0, 0, 0, 0, retried_}; }

 private:
  long blow_up_at_, nan_at_, retry_at_;
  int retried_ = 0;
  std::vector<double> f_;
};
void reg(loom::Registry& r) {
  r.add_integrator({loom::PluginKind::Integrator, "test_explicit_euler", "cpu", "1.0", "test: forward Euler"},
                   [](const loom::Params& p) { return std::make_unique<ExplicitEuler>(p); });
}
}  // namespace
LOOM_PLUGIN(reg)

// Test integrator: forward Euler with gravity; `blow_up_at` multiplies velocities by 1e6 at
// that step so that the divergence guard can be tested; `retry_at` reports that step as one
// halving after a failed solve (StepStats::retries), for the run summary's count. `own_copy:
// true` keeps x and v to itself between steps as the CUDA backend does (taken from scene.state
// in prepare(), written back by sync_to_host, the guard run on the copy), so that the framework's
// hand-over of a state it set itself (loom run --resume) can be tested without a GPU.
#include <loom/plugin.hpp>

#include <cmath>
#include <vector>

namespace {
class ExplicitEuler final : public loom::Integrator {
 public:
  explicit ExplicitEuler(const loom::Params& p)
      : blow_up_at_(p.get("blow_up_at", -1)),
        nan_at_(p.get("nan_at", -1)),
        retry_at_(p.get("retry_at", -1)),
        own_copy_(p.get("own_copy", false)) {}
  std::string name() const override { return "test_explicit_euler"; }
  void prepare(loom::Scene& s, double) override {
    sync_to_host(s);   // as the CUDA backend: a repeated prepare starts from the current state
    f_.assign(s.state.x.size(), 0.0);
    if (own_copy_) {
      x_ = s.state.x;
      v_ = s.state.v;
    }
  }
  void step(loom::Scene& s, double h) override {
    auto& st = s.state;
    std::vector<double>& x = own_copy_ ? x_ : st.x;
    std::vector<double>& v = own_copy_ ? v_ : st.v;
    s.material->compute_forces(x, v, f_);
    for (loom::Index i = 0; i < st.size(); ++i) {
      const double w = st.inv_mass[i];
      for (int k = 0; k < 3; ++k) {
        x[3 * i + k] += h * v[3 * i + k];
        if (w > 0) v[3 * i + k] += h * (w * f_[3 * i + k] + s.gravity[k]);
      }
    }
    if (st.step == blow_up_at_) v[3 * 5 + 1] *= 1e6;
    if (st.step == nan_at_) x[3 * 7] = 0.0 / 0.0;
    retried_ = st.step == retry_at_ ? 1 : 0;
    stale_ = own_copy_;
    loom::finish_step(st, h);
  }
  void sync_to_host(loom::Scene& s) override {
    if (!stale_) return;
    s.state.x = x_;
    s.state.v = v_;
    stale_ = false;
  }
  loom::Index first_unguarded_vertex(double vmax2) override {
    if (!stale_) return -2;
    for (std::size_t i = 0; 3 * i < x_.size(); ++i) {
      const double a = x_[3 * i] + x_[3 * i + 1] + x_[3 * i + 2];
      const double s2 = v_[3 * i] * v_[3 * i] + v_[3 * i + 1] * v_[3 * i + 1] + v_[3 * i + 2] * v_[3 * i + 2];
      if (!(s2 <= vmax2) || !std::isfinite(a)) return static_cast<loom::Index>(i);
    }
    return -1;
  }
  loom::StepStats last_step() const override { return {1, 0, 0, 0, 0, retried_}; }

 private:
  long blow_up_at_, nan_at_, retry_at_;
  bool own_copy_ = false;
  bool stale_ = false;   ///< x_, v_ are ahead of scene.state (own_copy)
  int retried_ = 0;
  std::vector<double> f_, x_, v_;
};
void reg(loom::Registry& r) {
  r.add_integrator({loom::PluginKind::Integrator, "test_explicit_euler", "cpu", "1.0", "test: forward Euler"},
                   [](const loom::Params& p) { return std::make_unique<ExplicitEuler>(p); });
}
}  // namespace
LOOM_PLUGIN(reg)

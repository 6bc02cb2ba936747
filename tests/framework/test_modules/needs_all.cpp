// Test integrator that needs springs, a Jacobian and a solver: exercises combo checks.
#include <loom/plugin.hpp>
namespace {
class NeedsAll final : public loom::Integrator {
 public:
  explicit NeedsAll(const loom::Params& p) : what_(p.get_choice("needs", "solver", {"solver", "springs", "jacobian"})) {}
  std::string name() const override { return "test_needs_all"; }
  loom::IntegratorNeeds needs() const override {
    loom::IntegratorNeeds n;
    n.linear_solver = what_ == "solver";
    n.springs = what_ == "springs";
    n.jacobian = what_ == "jacobian";
    return n;
  }
  void prepare(loom::Scene&, double) override {}
  void step(loom::Scene& s, double h) override { loom::finish_step(s.state, h); }

 private:
  std::string what_;
};
void reg(loom::Registry& r) {
  r.add_integrator({loom::PluginKind::Integrator, "test_needs_all", "cpu", "1.0", "test"},
                   [](const loom::Params& p) { return std::make_unique<NeedsAll>(p); });
}
}  // namespace
LOOM_PLUGIN(reg)

// Test solver: dv = S b + z (exact when A = I). Exercises solver selection.
#include <loom/plugin.hpp>

namespace {
class Identity final : public loom::LinearSolver {
 public:
  explicit Identity(const loom::Params& p) : scale_(p.get_positive("scale", 1.0)) {}
  std::string name() const override { return "test_identity"; }
  void analyze_pattern(const loom::BsrMatrix&, const loom::Filter&) override {}
  bool factorize(const loom::BsrMatrix&, const loom::Filter&, loom::SolveReport&) override { return true; }
  loom::SolveReport solve(const loom::BsrMatrix&, const loom::Filter& S, std::span<const double> b,
                          std::span<const double> z, std::span<double> dv) override {
    for (std::size_t i = 0; i < dv.size(); ++i) dv[i] = scale_ * b[i];
    S.apply(dv);
    for (std::size_t i = 0; i < dv.size(); ++i) dv[i] += z[i];
    loom::SolveReport r;
    r.converged = true;
    r.iterations = 1;
    return r;
  }

 private:
  double scale_;
};
void reg(loom::Registry& r) {
  r.add_solver({loom::PluginKind::Solver, "test_identity", "cpu", "1.0", "test: identity"},
               [](const loom::Params& p) { return std::make_unique<Identity>(p); });
}
}  // namespace
LOOM_PLUGIN(reg)

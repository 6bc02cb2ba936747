// Test material: no internal forces, unit masses (or `mass` per vertex). Lets the framework
// tests run scenes without depending on the real material plugins.
#include <loom/plugin.hpp>

#include <algorithm>

namespace {
class GravityOnly final : public loom::Material {
 public:
  explicit GravityOnly(const loom::Params& p) : mass_(p.get_positive("mass", 1.0)) {}
  std::string name() const override { return "test_gravity_only"; }
  void compute_masses(std::span<double> m) const override { std::fill(m.begin(), m.end(), mass_); }
  void compute_forces(std::span<const double>, std::span<const double>, std::span<double> f) const override {
    std::fill(f.begin(), f.end(), 0.0);
  }
  double elastic_energy(std::span<const double>) const override { return 0; }
  double max_strain(std::span<const double>) const override { return 0; }

 private:
  double mass_;
};
void reg(loom::Registry& r) {
  r.add_material({loom::PluginKind::Material, "test_gravity_only", "cpu", "1.0", "test: no internal forces"},
                 [](const loom::Params& p, const loom::Mesh&) { return std::make_unique<GravityOnly>(p); });
}
}  // namespace
LOOM_PLUGIN(reg)

// A material with no internal forces: the smallest complete material plugin.
#include <loom/plugin.hpp>

#include <algorithm>

class ToySpringless final : public loom::Material {
 public:
  explicit ToySpringless(double mass) : mass_(mass) {}
  std::string name() const override { return "toy_springless"; }
  void compute_masses(std::span<double> m) const override { std::fill(m.begin(), m.end(), mass_); }
  void compute_forces(std::span<const double>, std::span<const double>, std::span<double> f) const override {
    std::fill(f.begin(), f.end(), 0.0);
  }
  double elastic_energy(std::span<const double>) const override { return 0.0; }
  double max_strain(std::span<const double>) const override { return 0.0; }

 private:
  double mass_;
};

static void register_toy(loom::Registry& r) {
  r.add_material({loom::PluginKind::Material, "toy_springless", "cpu", "0.1", "out-of-tree example: no forces"},
                 [](const loom::Params& p, const loom::Mesh&) {
                   return std::make_unique<ToySpringless>(p.get_positive("mass", 1.0));
                 });
}
LOOM_PLUGIN(register_toy)

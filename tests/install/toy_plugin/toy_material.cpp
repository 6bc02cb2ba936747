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

// The keys the plugin reads, declared once: `loom plugins --params toy_springless` prints them,
// the registry refuses reads of undeclared keys and suggests declared ones for a typo.
static const loom::ParamSpec& toy_spec() {
  static const loom::ParamSpec spec = [] {
    loom::ParamSpec s("toy_springless", "out-of-tree example: no forces");
    s.number("mass", 1.0).range(loom::ParamRange::positive()).units("kg").help("mass of every vertex");
    return s;
  }();
  return spec;
}

static void register_toy(loom::Registry& r) {
  r.add_material({loom::PluginKind::Material, "toy_springless", "cpu", "0.1", "out-of-tree example: no forces", "",
                  &toy_spec()},
                 [](const loom::Params& p, const loom::Mesh&) {
                   return std::make_unique<ToySpringless>(loom::ParamReader(p, toy_spec()).number("mass"));
                 });
}
LOOM_PLUGIN(register_toy)

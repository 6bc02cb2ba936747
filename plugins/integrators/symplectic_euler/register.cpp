#include <memory>

#include "loom/plugin.hpp"
#include "symplectic_euler.hpp"

static void register_symplectic_euler(loom::Registry& r) {
  loom::PluginInfo info;
  info.kind = loom::PluginKind::Integrator;
  info.name = "symplectic_euler";
  info.description = "explicit symplectic (semi-implicit) Euler: v += h a(x, v), x += h v";
  info.params = &loom::symplectic_euler::spec();
  r.add_integrator(info, [](const loom::Params& p) {
                     return std::make_unique<loom::symplectic_euler::SymplecticEuler>(p);
                   });
}

LOOM_PLUGIN(register_symplectic_euler)

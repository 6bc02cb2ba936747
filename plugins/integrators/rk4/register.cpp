#include <memory>

#include "loom/plugin.hpp"
#include "rk4_integrator.hpp"

static void register_rk4(loom::Registry& r) {
  r.add_integrator({loom::PluginKind::Integrator, "rk4", "cpu", "1.0",
                    "classical 4th-order Runge-Kutta on (x, v): 4 force evaluations per step", "", &loom::rk4_spec()},
                   [](const loom::Params& p) { return std::make_unique<loom::Rk4Integrator>(p); });
}

LOOM_PLUGIN(register_rk4)

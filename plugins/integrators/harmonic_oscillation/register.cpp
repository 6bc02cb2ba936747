#include <memory>

#include "ho_integrator.hpp"
#include "loom/plugin.hpp"

static void register_ho(loom::Registry& r) {
  r.add_integrator({loom::PluginKind::Integrator, "harmonic_oscillation", "cpu", "1.0",
                    "Kang & Cho 2011 harmonic-oscillation spring integration, corrected (variants velocity, "
                    "analytic_position, kang_cho_2011)", "", &loom::harmonic_oscillation_spec()},
                   [](const loom::Params& p) { return std::make_unique<loom::HoIntegrator>(p); });
}

LOOM_PLUGIN(register_ho)

#include <loom/plugin.hpp>

#include <memory>

#include "baraff_witkin.hpp"

static void register_baraff_witkin(loom::Registry& r) {
  r.add_integrator({loom::PluginKind::Integrator, "baraff_witkin", "cpu", "1.0",
                    "Baraff-Witkin linearised implicit Euler with constraint filter, Kang-Cho and Rayleigh damping", "",
                    &loom::baraff_witkin_spec()},
                   [](const loom::Params& p) {
                     return std::make_unique<loom::BaraffWitkin>(loom::parse_baraff_witkin_options(p));
                   });
}

LOOM_PLUGIN(register_baraff_witkin)

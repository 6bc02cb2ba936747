#include <memory>

#include <loom/plugin.hpp>

#include "gnatv_material.hpp"

static void register_gnatv(loom::Registry& r) {
  r.add_material({loom::PluginKind::Material, "gnatv", "cpu", "1.0",
                  "Volino et al. 2009 nonlinear anisotropic triangle material from measured stress-strain curves", "",
                  &loom::gnatv::gnatv_spec()},
                 [](const loom::Params& p, const loom::Mesh& m) {
                   return std::make_unique<loom::gnatv::GnatvMaterial>(p, m);
                 });
}

LOOM_PLUGIN(register_gnatv)

#include <memory>

#include "loom/plugin.hpp"
#include "mass_spring.hpp"

static void register_mass_spring(loom::Registry& r) {
  loom::PluginInfo info;
  info.kind = loom::PluginKind::Material;
  info.name = "mass_spring";
  info.description = "Hooke springs on a mesh or grid stencil (Kang & Cho 2011), axial dampers, Jacobians";
  info.params = &loom::mass_spring::mass_spring_spec();
  r.add_material(info, [](const loom::Params& p, const loom::Mesh& m) {
                   return std::make_unique<loom::mass_spring::MassSpringMaterial>(p, m);
                 });
}

LOOM_PLUGIN(register_mass_spring)

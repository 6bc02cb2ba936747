// What a plugin module includes: the registry types and the LOOM_PLUGIN entry-point macro.
//
//   #include <loom/plugin.hpp>
//   static void register_me(loom::Registry& r) {
//     r.add_material({loom::PluginKind::Material, "my_material", "cpu", "1.0", "what it is"},
//                    [](const loom::Params& p, const loom::Mesh& m) { return std::make_unique<MyMaterial>(p, m); });
//   }
//   LOOM_PLUGIN(register_me)
#pragma once

#include "loom/registry.hpp"

#define LOOM_PLUGIN_EXPORT extern "C" __attribute__((visibility("default")))

#define LOOM_PLUGIN(register_function)                                                     \
  LOOM_PLUGIN_EXPORT int loom_plugin_abi_version() { return ::loom::kPluginAbiVersion; }  \
  LOOM_PLUGIN_EXPORT void loom_register_plugin(::loom::Registry& registry) {               \
    register_function(registry);                                                           \
  }

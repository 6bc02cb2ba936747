// A module built for another plugin ABI version: the loader must refuse it.
#include <loom/plugin.hpp>
LOOM_PLUGIN_EXPORT int loom_plugin_abi_version() { return loom::kPluginAbiVersion + 41; }
LOOM_PLUGIN_EXPORT void loom_register_plugin(loom::Registry&) {}

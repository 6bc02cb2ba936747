// Shared by the benchmarks that build their scenes through the plugin loader, as the CLI does
// (bench/CMakeLists.txt puts bench/ on every benchmark's include path; this folder has no
// CMakeLists.txt, so it is no benchmark folder itself).
#pragma once

#include "loom/registry.hpp"

namespace loom_bench {

/// One plugin loader, and the registry it fills, for the whole benchmark process: the plugin
/// modules are loaded once and serve every scene built through it.
inline loom::PluginLoader& loader() {
  static loom::Registry registry;
  static loom::PluginLoader l(registry);
  return l;
}

}  // namespace loom_bench

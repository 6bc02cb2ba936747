// Shared set-up of the plugin conformance tests: the plugin modules of the build, loaded once,
// and the plugin names of a kind (the registered ones, plus the source folders whose module
// was not built, which the tests skip with a message).
#pragma once

#include <memory>
#include <string>
#include <vector>

#include "loom/registry.hpp"

namespace loom::conformance {

struct Loaded {
  Registry reg;
  std::unique_ptr<PluginLoader> loader;
  std::vector<std::string> errors;
};

/// Every module in the build's plugin folder, loaded once per process.
Loaded& plugins();

/// Names of the cpu plugins of `kind` the build registered, followed by the folders of
/// plugins/<kind>s/ that registered nothing (not built here); sorted, unique.
std::vector<std::string> plugin_names(PluginKind kind);

/// The keys a plugin needs besides its defaults to be built at all (a required key); a new
/// plugin with a required key adds its line here (the test says so when it is missing).
std::string required_keys(const std::string& name);

}  // namespace loom::conformance

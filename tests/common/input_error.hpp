// Shared by the tests (tests/CMakeLists.txt puts tests/ on every test's include path; this
// folder has no CMakeLists.txt, so it is not a test folder itself).
#pragma once

#include <functional>
#include <string>

#include "loom/common.hpp"

namespace loom_test {

/// The message of the loom::InputError that f throws, or "" when it throws none.
inline std::string error_of(const std::function<void()>& f) {
  try {
    f();
  } catch (const loom::InputError& e) {
    return e.what();
  }
  return "";
}

}  // namespace loom_test

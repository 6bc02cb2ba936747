// Small text helpers shared by the framework's messages and reports (one of each).
#pragma once

#include <string>
#include <string_view>
#include <vector>

namespace loom {

/// A number for a message: %g with `precision` significant digits (6: "0.001", "1e+06").
std::string fmt(double v, int precision = 6);

/// "a, b, c" (or with another separator); empty items are kept.
std::string join(const std::vector<std::string>& items, std::string_view sep = ", ");

}  // namespace loom

// The one clock helper for the timings in stats, solver reports and self-collision statistics.
#pragma once

#include <chrono>

namespace loom {

using Clock = std::chrono::steady_clock;

/// Seconds from a to b.
inline double seconds_between(Clock::time_point a, Clock::time_point b) {
  return std::chrono::duration<double>(b - a).count();
}

/// Seconds elapsed since t0.
inline double seconds_since(Clock::time_point t0) { return seconds_between(t0, Clock::now()); }

}  // namespace loom

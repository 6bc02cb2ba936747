// Shared by the tests (tests/CMakeLists.txt puts tests/ on every test's include path): the bytes
// of a restart.bin encoded from the layout documented in docs/OUTPUT.md ("Resuming a run"),
// independently of loom::restart_bytes.
#pragma once

#include <cstdint>
#include <string>

#include "loom/restart.hpp"

namespace loom_test {

constexpr std::uint64_t kFnv1aBasis = 14695981039346656037ULL;  ///< the 64-bit FNV-1a offset basis

/// Little endian (as this machine): "LOOMRST1", int32 frame, int32 frames, int64 step, float64
/// time, int64 force evaluations, int64 linear iterations, int64 n, x[3n], v[3n], int64 k,
/// integrator state[k], then the 64-bit FNV-1a hash (prime 1099511628211) of all bytes before
/// it, started from `basis`.
inline std::string restart_file_bytes(const loom::RestartData& r, std::uint64_t basis = kFnv1aBasis) {
  std::string b = "LOOMRST1";
  auto put = [&](auto v) { b.append(reinterpret_cast<const char*>(&v), sizeof(v)); };
  put(std::int32_t(r.frame));
  put(std::int32_t(r.frames));
  put(std::int64_t(r.step));
  put(r.time);
  put(std::int64_t(r.force_evaluations));
  put(std::int64_t(r.linear_iterations));
  put(std::int64_t(r.x.size() / 3));
  for (double d : r.x) put(d);
  for (double d : r.v) put(d);
  put(std::int64_t(r.integrator_state.size()));
  for (double d : r.integrator_state) put(d);
  std::uint64_t h = basis;
  for (unsigned char c : b) h = (h ^ c) * 1099511628211ULL;
  put(h);
  return b;
}

}  // namespace loom_test

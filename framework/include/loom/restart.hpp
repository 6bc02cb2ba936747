// Restart points for `loom run --resume`: a run writes DIR/restart.bin (atomically), the exact
// state after a complete frame that a continuation needs: after frame 0, about once per
// output.restart_interval of wall time, after the last frame and at an early stop
// (Simulation::run; docs/OUTPUT.md).
#pragma once

#include <cstdint>
#include <string>
#include <vector>

namespace loom {

/// Everything a run needs to continue from the end of a frame as if it had never stopped.
struct RestartData {
  int frame = 0;                        ///< the last complete frame
  int frames = 0;                       ///< the frames the run was asked for
  std::int64_t step = 0;                ///< State::step
  double time = 0;                      ///< State::time
  long long force_evaluations = 0;      ///< running totals (stats.csv columns)
  long long linear_iterations = 0;
  std::vector<double> x, v;             ///< positions and velocities, 3n, bit for bit
  std::vector<double> integrator_state; ///< Integrator::restart_state()
};

/// Binary layout (little endian): char[8] "LOOMRST1", int32 frame, int32 frames, int64 step, float64 time,
/// int64 force evaluations, int64 linear iterations, int64 n (vertices), float64 x[3n],
/// float64 v[3n], int64 k, float64 integrator state[k], uint64 FNV-1a hash of all bytes before it
/// (64-bit: offset basis 14695981039346656037, prime 1099511628211; read_restart also accepts
/// the basis 1469598103934665603 that builds before 2026-11-29 used).
std::string restart_bytes(const RestartData& r);
/// Write DIR/restart.bin atomically (temporary file, then rename).
void write_restart(const std::string& dir, const RestartData& r);
/// Read DIR/restart.bin; throws InputError naming the file and the fix when it is missing,
/// truncated or damaged.
RestartData read_restart(const std::string& dir);

}  // namespace loom

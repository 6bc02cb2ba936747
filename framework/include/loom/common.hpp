// Loom common definitions: errors, exit codes, the host+device marker.
#pragma once

#include <cstdint>
#include <stdexcept>
#include <string>

#if defined(__CUDACC__)
#define LOOM_HD __host__ __device__
#else
#define LOOM_HD
#endif

namespace loom {

using Index = std::int32_t;

/// The one rule for when a loop runs on one thread (docs/ARCHITECTURE.md "Threads"): a loop
/// whose work is less than kParallelMinVertices vertex updates runs on the calling thread,
/// because below it waking and joining threads costs more than the work (measured: a 576-vertex
/// cloth ran 30x slower on 2 threads of a loaded machine with every loop parallel). Loops over
/// other items use the same rule in their units, defined here and nowhere else:
constexpr Index kParallelMinVertices = 4096;
/// Springs and hinges: about half a vertex update's work each (a mesh has about 3 springs
/// per vertex, 6 with shear and bend springs).
constexpr Index kParallelMinSprings = 2 * kParallelMinVertices;
/// Rows of a 3x3-block sparse matrix (one per vertex) in the linear solvers: a row product
/// touches about 7 blocks, twice a vertex update's work.
constexpr Index kParallelMinRows = kParallelMinVertices / 2;

/// Process exit codes of the `loom` CLI (documented in README.md).
enum ExitCode : int {
  kExitOk = 0,
  kExitInternal = 1,   ///< unexpected failure (a bug or an I/O error while running)
  kExitBadInput = 2,   ///< scene, mesh, material file or CLI flag rejected
  kExitDiverged = 3,   ///< the simulation diverged (NaN/Inf or a bound exceeded)
  kExitSolverFailed = 4,  ///< a linear solve failed and the scene's policy says stop
  kExitIntersections = 5  ///< `loom check`: some frame has intersecting triangle pairs
};

/// Bad input: a scene file, mesh, material file or CLI flag. The message names the
/// file, the line where there is one, and the fix.
class InputError : public std::runtime_error {
 public:
  explicit InputError(const std::string& what) : std::runtime_error(what) {}
};

/// The simulation left the range where its numbers mean anything.
class DivergenceError : public std::runtime_error {
 public:
  explicit DivergenceError(const std::string& what) : std::runtime_error(what) {}
};

/// Writing the run's output failed (disk full, quota, file size limit, I/O error). Exit 1; the
/// frames written before it are complete and kept.
class OutputError : public std::runtime_error {
 public:
  explicit OutputError(const std::string& what) : std::runtime_error(what) {}
};

/// A linear solve failed (not converged, indefinite system) and the policy says stop.
class SolverError : public std::runtime_error {
 public:
  explicit SolverError(const std::string& what) : std::runtime_error(what) {}
};

}  // namespace loom

#pragma once
// An estimate of the peak memory a run needs, from the vertex count and the combo, made before
// the mesh and the solver allocate anything, and the memory this machine offers. `loom validate`
// prints both; a scene whose estimate exceeds the machine's memory is refused (InputError) with
// the numbers, instead of dying in the out-of-memory killer or std::bad_alloc half-way through
// the set-up. The coefficients are peak resident sizes measured on Loom's own runs (see
// docs/BENCHMARKS.md "Memory per vertex"); the estimate is meant to be right within about 50 %.
#include <cstdint>
#include <optional>
#include <string>

namespace loom {

struct MemoryCombo {
  std::int64_t vertices = 0;
  std::string integrator;      ///< integrator type ("" when not known yet)
  std::string solver;          ///< linear solver type ("" for explicit integrators or not known)
  bool sa_amg = false;         ///< eigen_pcg with the sa_amg preconditioner
  bool bending = false;        ///< hinge bending on top of the membrane
  bool self_collision = false;
};

struct MemoryEstimate {
  double bytes = 0;            ///< estimated peak resident memory of the run
  std::string basis;           ///< one line: what the estimate is made of
};

MemoryEstimate estimate_run_memory(const MemoryCombo& combo);

/// The memory this process may use: MemTotal from /proc/meminfo, lowered by a cgroup limit
/// (memory.max, v2, or memory.limit_in_bytes, v1); nullopt where neither can be read.
std::optional<double> machine_memory_bytes();

/// "1.23 GiB", "456 MiB", "12.0 KiB".
std::string format_bytes(double bytes);

}  // namespace loom

// The threading policy: how many OpenMP threads a run uses and how they wait.
//
// One place for the rule (docs/ARCHITECTURE.md, "Threads"):
// - `threads: auto` (the default) uses the cores this process may run on: the affinity mask
//   (taskset, mpirun binding) and the cgroup CPU quota (containers), whichever is smaller.
// - An explicit count is capped at those cores (more threads than cores only adds waiting at
//   every barrier) with a note; a count above kMaxThreads is refused.
// - Idle threads spin only briefly before they sleep (GOMP_SPINCOUNT, set by the `loom`
//   executable before the OpenMP runtime starts unless the user set OMP_WAIT_POLICY or
//   GOMP_SPINCOUNT), so a busy machine does not lose a core to a thread that spins at a
//   barrier while its partner is descheduled.
// - Small loops run serially: kParallelMinVertices (common.hpp) is the threshold.
#pragma once

namespace loom {

/// Largest thread count a scene may ask for (a guard against typos such as 100000).
constexpr int kMaxThreads = 1024;

/// Iterations an idle OpenMP thread spins before it sleeps (libgomp's GOMP_SPINCOUNT):
/// about 10-50 microseconds, enough to catch the partner's next parallel region in a step,
/// short enough not to steal a core from another process.
constexpr long kSpinCount = 20000;

/// Cores this process may use: min(affinity mask, cgroup quota rounded up), at least 1.
int usable_cores();

/// The thread count for a scene's `threads` value: 0 means auto (usable_cores()); larger
/// requests are capped at usable_cores(). `capped` tells whether the request was reduced.
int resolve_thread_count(int requested, bool* capped = nullptr);

/// Called first in main(): when neither OMP_WAIT_POLICY nor GOMP_SPINCOUNT is set, set
/// GOMP_SPINCOUNT = kSpinCount and re-execute the program so the OpenMP runtime (which reads
/// its environment once, at load) starts with it. Returns normally when nothing is to be done
/// or the re-exec failed (the run then continues with the runtime's default policy).
void set_wait_policy_and_reexec(int argc, char** argv);

}  // namespace loom

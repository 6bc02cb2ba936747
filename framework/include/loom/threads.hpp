// The threading policy: how many OpenMP threads a run uses and how they wait.
//
// One place for the rule (docs/ARCHITECTURE.md, "Threads"):
// - `threads: auto` (the default) uses the cores this process may run on: the affinity mask
//   (taskset, mpirun binding) and the cgroup CPU quota (containers), whichever is smaller,
//   less the cores other runnable processes occupy when the run starts (/proc/loadavg).
// - An explicit count is capped at those cores (more threads than cores only adds waiting at
//   every barrier) with a note; a count above kMaxThreads is refused.
// - Small loops run serially: kParallelMinVertices (common.hpp) is the threshold.
#pragma once

namespace loom {

/// Largest thread count a scene may ask for (a guard against typos such as 100000).
constexpr int kMaxThreads = 1024;


/// Cores this process may use: min(affinity mask, cgroup quota rounded up), at least 1.
int usable_cores();

/// The thread count for a scene's `threads` value: 0 means auto (OMP_NUM_THREADS when set,
/// else usable_cores() less the other runnable processes, at least 1); larger
/// requests are capped at usable_cores(). `capped` tells whether the request was reduced.
int resolve_thread_count(int requested, bool* capped = nullptr);


}  // namespace loom

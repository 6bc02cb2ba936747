// The threading policy: how many OpenMP threads a run uses and how they wait.
//
// One place for the rule (docs/ARCHITECTURE.md, "Threads"):
// - `threads: auto` (the default) uses the cores this process may run on: the affinity mask
//   (taskset, mpirun binding) and the cgroup CPU quota (containers), whichever is smaller.
//   The scene is set up on those cores less the other runnable processes (/proc/loadavg); the
//   steps then start on choose_start_threads(): 1 thread when the mesh is below
//   kParallelMinVertices (most loops run serially there and a second thread only adds
//   barriers; under an iterative linear solver, whose row loops are most of the step, below its
//   LinearSolver::parallel_min_rows(), kParallelMinRows by default) or when other processes
//   kept the cores busy during the set-up (/proc/stat, loom/cpu_load.hpp; the runnable count
//   when the set-up was too short to measure), else the
//   free cores. loom/thread_controller.hpp then adapts the count to the step times.
// - An explicit count is capped at those cores (more threads than cores only adds waiting at
//   every barrier) with a note; a count above kMaxThreads is refused.
// - Small loops run serially: kParallelMinVertices (common.hpp) is the threshold.
#pragma once

#include "loom/common.hpp"

namespace loom {

/// Largest thread count a scene may ask for (a guard against typos such as 100000).
constexpr int kMaxThreads = 1024;


/// Cores this process may use: min(affinity mask, cgroup quota rounded up), at least 1.
int usable_cores();

/// The thread count for a scene's `threads` value: 0 means auto (OMP_NUM_THREADS when set,
/// else usable_cores() less the other runnable processes now, at least 1: the count the scene
/// is set up on; its steps start on choose_start_threads()'s); larger requests are capped at
/// usable_cores(). `capped` tells whether the request was reduced.
int resolve_thread_count(int requested, bool* capped = nullptr);

class ProcSource;  // loom/cpu_load.hpp
/// Runnable tasks other than this process (/proc/loadavg): the minimum of up to five readings
/// 2 ms apart (a process only starting or finishing, such as the shell that launched us, is
/// not a competitor; the sleeps happen only while the count is above 0). -1 when unknown.
int others_runnable_sampled(const ProcSource* src = nullptr);

/// Runnable tasks other than this process, to check a reading that says others take a core:
/// the largest of up to three readings 1 ms apart (it stops at the first that shows one; a
/// CPU-bound competitor is runnable at every reading). -1 when unknown.
int others_runnable_confirm(const ProcSource* src = nullptr);

/// Cores free for this run's threads: min(cores, mask_cpus - the cores others keep busy), where
/// others take a core from half a core's use (others_busy 0.5 -> 1 core); at least 1.
/// -1 when others_busy is unknown (< 0).
int free_cores(int cores, int mask_cpus, double others_busy);

/// The count `threads: auto` starts the steps on, and what it saw.
struct ThreadStart {
  int threads = 1;
  int free = -1;            ///< free cores (free_cores(), or from the runnable count; -1 unknown)
  bool small_mesh = false;  ///< below serial_below (kParallelMinVertices by default): starts on 1 whatever the load
  bool unconfirmed = false; ///< others_busy took cores that the runnable count did not: not trusted
};
/// The start-up rule. cores: usable_cores(); mask_cpus: CPUs in the affinity mask;
/// others_busy: cores other processes kept busy during the set-up (CpuLoadMonitor, -1 unknown);
/// others_runnable: other processes runnable now (-1 not read): the fallback when others_busy
/// is unknown (others_runnable_sampled(); both unknown: all cores are free), and the check of
/// an others_busy that takes cores (others_runnable_confirm()): others take a core only when
/// both say so, so one window's reading (a short set-up is a few ticks per CPU, and a burst
/// that ended counts in it) cannot hold the run on fewer cores by itself;
/// vertices: the mesh's vertex count; serial_below: a mesh with fewer vertices starts on 1
/// (kParallelMinVertices, or an iterative solver's parallel_min_rows() when smaller: see the top
/// of this file).
ThreadStart choose_start_threads(int cores, int mask_cpus, double others_busy, int others_runnable,
                                 long long vertices, long long serial_below = kParallelMinVertices);


}  // namespace loom

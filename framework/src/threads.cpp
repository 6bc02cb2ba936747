#include "loom/threads.hpp"

#include <sched.h>
#include <unistd.h>

#include <algorithm>
#include <cmath>
#include <cstdlib>
#include <fstream>
#include <string>
#include <thread>
#include <chrono>

namespace loom {

namespace {

int affinity_cores() {
  cpu_set_t set;
  CPU_ZERO(&set);
  if (sched_getaffinity(0, sizeof(set), &set) != 0) {
    const long n = sysconf(_SC_NPROCESSORS_ONLN);
    return n > 0 ? static_cast<int>(n) : 1;
  }
  return std::max(1, CPU_COUNT(&set));
}

// cgroup v2 "cpu.max" ("max 100000" or "<quota> <period>") and v1 cfs files; 0 = no quota.
int cgroup_quota_cores() {
  std::ifstream v2("/sys/fs/cgroup/cpu.max");
  std::string quota;
  long period = 0;
  if (v2 >> quota >> period) {
    if (quota == "max" || period <= 0) return 0;
    const double q = std::atof(quota.c_str());
    return q > 0 ? static_cast<int>(std::ceil(q / period)) : 0;
  }
  std::ifstream q1("/sys/fs/cgroup/cpu/cpu.cfs_quota_us"), p1("/sys/fs/cgroup/cpu/cpu.cfs_period_us");
  long q = 0, p = 0;
  if ((q1 >> q) && (p1 >> p) && q > 0 && p > 0) return static_cast<int>((q + p - 1) / p);
  return 0;
}

// Runnable tasks other than this process, from /proc/loadavg's "running/total" field (the
// count includes the reader itself). 0 when it cannot be read.
int other_runnable_tasks() {
  std::ifstream in("/proc/loadavg");
  double l1, l5, l15;
  std::string rt;
  if (!(in >> l1 >> l5 >> l15 >> rt)) return 0;
  const auto slash = rt.find('/');
  if (slash == std::string::npos) return 0;
  const int running = std::atoi(rt.substr(0, slash).c_str());
  return std::max(0, running - 1);
}

}  // namespace

int usable_cores() {
  int n = affinity_cores();
  const int quota = cgroup_quota_cores();
  if (quota > 0) n = std::min(n, quota);
  return std::max(1, n);
}

int resolve_thread_count(int requested, bool* capped) {
  const int cores = usable_cores();
  if (capped) *capped = requested > cores;
  if (requested <= 0) {
    // auto: OMP_NUM_THREADS, when set, still chooses (capped at the usable cores).
    const char* env = std::getenv("OMP_NUM_THREADS");
    const int from_env = env ? std::atoi(env) : 0;
    if (from_env > 0) return std::min(from_env, cores);
    // Otherwise leave the cores other runnable processes occupy right now: on a busy machine
    // every barrier of a parallel step waits for a descheduled thread (measured: 2 threads
    // next to one CPU-bound process ran 2x slower than 1 thread; docs/BENCHMARKS.md).
    // The minimum over a few samples 2 ms apart: a process that is only starting or
    // finishing (the shell that launched us, a pipe) is not a competitor.
    int others = other_runnable_tasks();
    for (int k = 0; k < 4 && others > 0; ++k) {
      std::this_thread::sleep_for(std::chrono::milliseconds(2));
      others = std::min(others, other_runnable_tasks());
    }
    return std::max(1, cores - others);
  }
  return std::min(requested, cores);
}


}  // namespace loom

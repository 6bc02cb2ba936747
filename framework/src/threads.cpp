#include "loom/threads.hpp"

#include "loom/common.hpp"
#include "loom/cpu_load.hpp"

#include <sched.h>
#include <unistd.h>

#include <algorithm>
#include <cmath>
#include <cstdlib>
#include <fstream>
#include <string>
#include <thread>
#include <chrono>
#include <vector>

namespace loom {

namespace {

// The CPUs this process may use: its affinity mask, or the OpenMP places' CPUs when the runtime
// binds threads (affinity_cpus, loom/cpu_load.hpp).
int affinity_cores() {
  const std::vector<int> cpus = affinity_cpus();
  if (cpus.empty()) {
    const long n = sysconf(_SC_NPROCESSORS_ONLN);
    return n > 0 ? static_cast<int>(n) : 1;
  }
  return std::max(1, static_cast<int>(cpus.size()));
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

}  // namespace

int usable_cores() {
  int n = affinity_cores();
  const int quota = cgroup_quota_cores();
  if (quota > 0) n = std::min(n, quota);
  return std::max(1, n);
}

int others_runnable_sampled(const ProcSource* src) {
  int others = read_others_runnable(src);
  for (int k = 0; k < 4 && others > 0; ++k) {
    std::this_thread::sleep_for(std::chrono::milliseconds(2));
    const int o = read_others_runnable(src);
    if (o >= 0) others = std::min(others, o);
  }
  return others;
}

int others_runnable_confirm(const ProcSource* src) {
  int others = read_others_runnable(src);
  for (int k = 0; k < 2 && others == 0; ++k) {
    std::this_thread::sleep_for(std::chrono::milliseconds(1));
    others = std::max(others, read_others_runnable(src));
  }
  return others;
}

int resolve_thread_count(int requested, bool* capped) {
  const int cores = usable_cores();
  if (capped) *capped = requested > cores;
  if (requested <= 0) {
    // auto: OMP_NUM_THREADS, when set, still chooses (capped at the usable cores).
    const char* env = std::getenv("OMP_NUM_THREADS");
    const int from_env = env ? std::atoi(env) : 0;
    if (from_env > 0) return std::min(from_env, cores);
    // Otherwise the set-up leaves the cores other runnable processes occupy right now (one
    // reading: the steps' count is measured over the set-up, choose_start_threads).
    return std::max(1, cores - std::max(0, read_others_runnable()));
  }
  return std::min(requested, cores);
}

int free_cores(int cores, int mask_cpus, double others_busy) {
  if (others_busy < 0) return -1;
  const int taken = static_cast<int>(std::floor(others_busy + 0.5));
  return std::max(1, std::min(cores, std::max(1, mask_cpus) - taken));
}

ThreadStart choose_start_threads(int cores, int mask_cpus, double others_busy, int others_runnable,
                                 long long vertices, long long serial_below) {
  ThreadStart s;
  cores = std::max(1, cores);
  const int by_runnable = others_runnable >= 0 ? std::max(1, cores - others_runnable) : -1;
  s.free = others_busy >= 0 ? free_cores(cores, mask_cpus, others_busy) : by_runnable;
  if (others_busy >= 0 && by_runnable > s.free) {  // the busy reading is not confirmed now
    s.free = by_runnable;
    s.unconfirmed = true;
  }
  s.small_mesh = vertices >= 0 && vertices < serial_below;
  s.threads = s.small_mesh ? 1 : (s.free > 0 ? s.free : cores);
  return s;
}

}  // namespace loom

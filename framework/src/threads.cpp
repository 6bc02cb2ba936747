#include "loom/threads.hpp"

#include <sched.h>
#include <unistd.h>

#include <algorithm>
#include <cmath>
#include <cstdlib>
#include <fstream>
#include <string>

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
    return from_env > 0 ? std::min(from_env, cores) : cores;
  }
  return std::min(requested, cores);
}

void set_wait_policy_and_reexec(int argc, char** argv) {
  (void)argc;
  if (std::getenv("OMP_WAIT_POLICY") || std::getenv("GOMP_SPINCOUNT") || std::getenv("LOOM_REEXECED")) return;
  const std::string spin = std::to_string(kSpinCount);
  ::setenv("GOMP_SPINCOUNT", spin.c_str(), 1);
  ::setenv("LOOM_REEXECED", "1", 1);  // never loop, even if the runtime ignores the variable
  ::execv("/proc/self/exe", argv);
  // execv returned: keep running with the default policy (the variables stay set for children).
}

}  // namespace loom

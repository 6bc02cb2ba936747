// What other processes do on the cores this process may use, read from /proc (issue 16), for
// `threads: auto` (docs/ARCHITECTURE.md, "Threads"; the rule itself is in loom/threads.hpp).
//
// - CPU time: /proc/stat's per-CPU lines (user nice system idle iowait irq softirq steal ...,
//   in clock ticks) summed over the CPUs of the affinity mask, minus this process's own time
//   over a window. The result is the number of cores that others kept busy on average
//   ("busy": user, nice, system, irq, softirq and steal, the last being time a hypervisor gave
//   to another machine). This process's own time is its CPU clock (CLOCK_PROCESS_CPUTIME_ID,
//   nanoseconds, all threads), not /proc/self/stat's utime + stime: those two are each cut
//   to whole 10 ms ticks, and over kang_cho_fig7_ho_k2000's set-up they grew 0.24-1.67 ticks
//   (mean 0.74) less than the clock in 30 of 30 runs (docs/ARCHITECTURE.md, "Threads: measured
//   (issue 16, the 0.50 cores at kang_cho_fig7_ho_k2000's set-up)"), which others' share then
//   gained: +0.1 core on the 7-tick set-up of an idle machine.
// - Resolution: /proc/stat's counters are whole ticks (10 ms), so each CPU's share of a window
//   may be off by about a tick. A window is long enough only when that rounding, one tick per
//   CPU, moves the reading by at most a quarter core: at least 4 ticks per CPU watched, and at
//   least `min_ticks`. Shorter windows read "unknown" and keep growing.
// - Runnable tasks: /proc/loadavg's "running/total" field, an instant count, less this
//   process's own running threads (/proc/self/task/N/stat; an OpenMP worker still spinning after
//   the set-up's last parallel region is running too), the fallback when no window is long
//   enough yet and the check of a reading that says others take a core.
// Every reading goes through ProcSource, so tests feed recorded /proc texts, a busy machine,
// an idle one or no /proc at all (every reading unknown: the callers fall back to the cores).
// Cost: one read of /proc/stat and one clock reading per window reading (measured in
// docs/ARCHITECTURE.md); readings are taken at start-up and when a probe is due, never per step.
#pragma once

#include <string>
#include <string_view>
#include <vector>

namespace loom {

/// Where /proc texts come from (the real files by default; tests give recorded texts).
class ProcSource {
 public:
  virtual ~ProcSource() = default;
  /// The whole text of `path` ("/proc/stat", "/proc/self/stat", "/proc/loadavg"); false when
  /// it cannot be read.
  virtual bool read(const char* path, std::string& text) const;
  /// This process's CPU time (all threads, user + system) in clock ticks, with their fraction:
  /// CLOCK_PROCESS_CPUTIME_ID, or /proc/self/stat's utime + stime (through read()) when the
  /// clock fails; -1 when unknown.
  virtual double self_cpu_ticks() const;
  /// This process's threads that are running or runnable now (state R in
  /// /proc/self/task/N/stat; the caller is one of them); -1 when unknown.
  virtual int self_running_threads() const;
};

/// Ticks summed over some CPUs of /proc/stat: busy (not idle, not iowait) and total.
struct CpuTicks {
  long long busy = 0, total = 0;
  int cpus = 0;  ///< CPUs of the list found in the text
};

/// Sums the "cpuN" lines of a /proc/stat text over `cpus` (all "cpuN" lines when empty).
/// Lines need at least 4 numbers (user nice system idle); later fields (iowait, irq, softirq,
/// steal) are used when present; guest and guest_nice are already inside user and nice.
/// cpus == 0 in the result: nothing usable (no such lines).
CpuTicks parse_proc_stat(std::string_view text, const std::vector<int>& cpus);

/// utime + stime (ticks) from a /proc/<pid>/stat text (the command name may hold spaces and
/// parentheses); -1 when malformed.
long long parse_self_stat_ticks(std::string_view text);

/// The running count of a /proc/loadavg text ("0.48 1.82 2.58 3/112 26335" -> 3); -1 when malformed.
int parse_loadavg_running(std::string_view text);

/// The state letter of a /proc/<pid>/stat (or task) text ('R', 'S', ...); 0 when malformed.
char parse_stat_state(std::string_view text);

/// Runnable tasks other than this process's right now (/proc/loadavg's running count less
/// src->self_running_threads(), or less 1, the reader, when that is unknown; src null: the real
/// files); -1 when unknown.
int read_others_runnable(const ProcSource* src = nullptr);

/// The CPUs this process may run on (sched_getaffinity; with OpenMP binding threads, also the
/// CPUs of every OpenMP place: the initial thread is then bound to one place), in increasing order.
std::vector<int> affinity_cpus();

/// Others' CPU use on a set of CPUs over a window between two readings.
class CpuLoadMonitor {
 public:
  /// cpus: the CPUs to watch (empty: affinity_cpus()); src: null for the real /proc;
  /// min_ticks: the shortest window, in ticks per CPU (also at least 4 per CPU watched: the
  /// resolution rule at the top of this file).
  explicit CpuLoadMonitor(std::vector<int> cpus = {}, const ProcSource* src = nullptr, long long min_ticks = 5);

  /// Starts a window now (taken by the constructor too).
  void mark();
  /// Cores that other processes kept busy on average on the watched CPUs since the window
  /// began, and a new window begins; -1 when unknown (no /proc, or the window has fewer than
  /// min_window_ticks() ticks per CPU: then the window goes on).
  double others_busy_cores();
  /// read_others_runnable() through this monitor's source.
  int others_runnable() const { return read_others_runnable(src_); }
  int cpus() const { return static_cast<int>(cpus_.size()); }
  long long last_window_ticks() const { return last_window_; }  ///< per CPU, of the last known reading
  /// The shortest window that gives a reading, in ticks per CPU (see the top of this file).
  long long min_window_ticks() const;

 private:
  bool snapshot(CpuTicks& t, double& self) const;
  std::vector<int> cpus_;
  const ProcSource* src_;
  long long min_ticks_;
  bool have_ = false;
  CpuTicks t0_;
  double self0_ = 0;
  long long last_window_ = 0;
};

}  // namespace loom

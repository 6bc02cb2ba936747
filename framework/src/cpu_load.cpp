#include "loom/cpu_load.hpp"

#include <dirent.h>
#include <sched.h>
#include <time.h>
#include <unistd.h>

#ifdef _OPENMP
#include <omp.h>
#endif

#include <algorithm>
#include <charconv>
#include <cstdio>

namespace loom {

bool ProcSource::read(const char* path, std::string& text) const {
  // Plain stdio: /proc files report size 0, so read until end of file.
  std::FILE* f = std::fopen(path, "re");
  if (!f) return false;
  text.clear();
  char buf[4096];
  std::size_t n;
  while ((n = std::fread(buf, 1, sizeof buf, f)) > 0) text.append(buf, n);
  const bool ok = !std::ferror(f);
  std::fclose(f);
  return ok && !text.empty();
}

double ProcSource::self_cpu_ticks() const {
  static const long hz = sysconf(_SC_CLK_TCK);
  timespec ts{};
  if (hz > 0 && clock_gettime(CLOCK_PROCESS_CPUTIME_ID, &ts) == 0)
    return (static_cast<double>(ts.tv_sec) + 1e-9 * static_cast<double>(ts.tv_nsec)) * static_cast<double>(hz);
  std::string text;
  if (!read("/proc/self/stat", text)) return -1;
  return static_cast<double>(parse_self_stat_ticks(text));  // -1 when malformed
}

int ProcSource::self_running_threads() const {
  DIR* d = opendir("/proc/self/task");
  if (!d) return -1;
  int running = 0;
  std::string text;
  while (const dirent* e = readdir(d)) {
    if (e->d_name[0] < '0' || e->d_name[0] > '9') continue;
    const std::string path = std::string("/proc/self/task/") + e->d_name + "/stat";
    if (read(path.c_str(), text) && parse_stat_state(text) == 'R') ++running;
  }
  closedir(d);
  return running;
}

namespace {

// Reads unsigned integers separated by blanks from s; returns how many were read (at most max).
int read_numbers(std::string_view s, long long* out, int max) {
  int k = 0;
  std::size_t i = 0;
  while (k < max) {
    while (i < s.size() && (s[i] == ' ' || s[i] == '\t')) ++i;
    if (i >= s.size() || s[i] < '0' || s[i] > '9') break;
    long long v = 0;
    const auto r = std::from_chars(s.data() + i, s.data() + s.size(), v);
    if (r.ec != std::errc()) break;
    out[k++] = v;
    i = static_cast<std::size_t>(r.ptr - s.data());
  }
  return k;
}

}  // namespace

CpuTicks parse_proc_stat(std::string_view text, const std::vector<int>& cpus) {
  CpuTicks t;
  std::size_t pos = 0;
  while (pos < text.size()) {
    std::size_t end = text.find('\n', pos);
    if (end == std::string_view::npos) end = text.size();
    const std::string_view line = text.substr(pos, end - pos);
    pos = end + 1;
    // "cpuN ..." (not the aggregate "cpu  ..." line)
    if (line.size() < 4 || line.compare(0, 3, "cpu") != 0 || line[3] < '0' || line[3] > '9') continue;
    int id = 0;
    const auto r = std::from_chars(line.data() + 3, line.data() + line.size(), id);
    if (r.ec != std::errc()) continue;
    if (!cpus.empty() && !std::binary_search(cpus.begin(), cpus.end(), id)) continue;
    long long v[10] = {};
    const int n = read_numbers(line.substr(static_cast<std::size_t>(r.ptr - line.data())), v, 10);
    if (n < 4) continue;
    // user nice system idle iowait irq softirq steal guest guest_nice
    const long long busy = v[0] + v[1] + v[2] + v[5] + v[6] + v[7];
    t.busy += busy;
    t.total += busy + v[3] + v[4];
    ++t.cpus;
  }
  return t;
}

long long parse_self_stat_ticks(std::string_view text) {
  // "pid (comm) state ppid ...": fields after the last ')' start with the state (field 3);
  // utime and stime are fields 14 and 15.
  const std::size_t close = text.rfind(')');
  if (close == std::string_view::npos) return -1;
  std::string_view rest = text.substr(close + 1);
  int field = 2;
  std::size_t i = 0;
  long long utime = -1;
  while (i < rest.size()) {
    while (i < rest.size() && rest[i] == ' ') ++i;
    if (i >= rest.size()) break;
    std::size_t j = i;
    while (j < rest.size() && rest[j] != ' ' && rest[j] != '\n') ++j;
    ++field;
    if (field == 14 || field == 15) {
      long long v = 0;
      const auto r = std::from_chars(rest.data() + i, rest.data() + j, v);
      if (r.ec != std::errc() || r.ptr != rest.data() + j) return -1;
      if (field == 14) utime = v;
      else return utime + v;
    }
    i = j;
    if (i < rest.size() && rest[i] == '\n') break;
  }
  return -1;
}

char parse_stat_state(std::string_view text) {
  // "pid (comm) S ...": the state follows the last ')' and a blank.
  const std::size_t close = text.rfind(')');
  if (close == std::string_view::npos || close + 2 >= text.size() || text[close + 1] != ' ') return 0;
  const char c = text[close + 2];
  return (c >= 'A' && c <= 'Z') || (c >= 'a' && c <= 'z') ? c : 0;
}

int parse_loadavg_running(std::string_view text) {
  // "l1 l5 l15 running/total last_pid"
  int field = 0;
  std::size_t i = 0;
  while (i < text.size()) {
    while (i < text.size() && (text[i] == ' ' || text[i] == '\t')) ++i;
    if (i >= text.size() || text[i] == '\n') break;
    std::size_t j = i;
    while (j < text.size() && text[j] != ' ' && text[j] != '\t' && text[j] != '\n') ++j;
    if (++field == 4) {
      const std::string_view f = text.substr(i, j - i);
      const std::size_t slash = f.find('/');
      if (slash == std::string_view::npos || slash == 0) return -1;
      int running = 0;
      const auto r = std::from_chars(f.data(), f.data() + slash, running);
      if (r.ec != std::errc() || r.ptr != f.data() + slash) return -1;
      return running;
    }
    i = j;
  }
  return -1;
}

std::vector<int> affinity_cpus() {
  std::vector<int> out;
  cpu_set_t set;
  CPU_ZERO(&set);
  if (sched_getaffinity(0, sizeof(set), &set) == 0) {
#ifdef _OPENMP
    // When the OpenMP runtime binds threads (OMP_PROC_BIND set, or OMP_PLACES), libgomp builds
    // its places from the process's mask at start-up and then binds the initial thread to the
    // first place: this thread's own mask is then one place (with OMP_PLACES=cores, one core,
    // and `threads: 2` was capped at 1). The team runs on all the places: their CPUs count.
    if (omp_get_proc_bind() != omp_proc_bind_false) {
      std::vector<int> ids;
      for (int p = 0; p < omp_get_num_places(); ++p) {
        const int m = omp_get_place_num_procs(p);
        if (m <= 0) continue;
        ids.assign(static_cast<std::size_t>(m), -1);
        omp_get_place_proc_ids(p, ids.data());
        for (int id : ids)
          if (id >= 0 && id < CPU_SETSIZE) CPU_SET(id, &set);
      }
    }
#endif
    for (int c = 0; c < CPU_SETSIZE; ++c)
      if (CPU_ISSET(c, &set)) out.push_back(c);
  }
  return out;  // empty: every CPU line counts
}

namespace {
const ProcSource& real_proc() {
  static const ProcSource src;
  return src;
}
}  // namespace

int read_others_runnable(const ProcSource* src) {
  const ProcSource& p = src ? *src : real_proc();
  std::string text;
  if (!p.read("/proc/loadavg", text)) return -1;
  const int running = parse_loadavg_running(text);
  if (running < 0) return -1;
  // Our own running threads are not others (at least the reader, which is one of them).
  const int ours = p.self_running_threads();
  return std::max(0, running - std::max(1, ours));
}

CpuLoadMonitor::CpuLoadMonitor(std::vector<int> cpus, const ProcSource* src, long long min_ticks)
    : cpus_(std::move(cpus)), src_(src ? src : &real_proc()), min_ticks_(std::max(1LL, min_ticks)) {
  if (cpus_.empty() && !src) cpus_ = affinity_cpus();
  std::sort(cpus_.begin(), cpus_.end());
  mark();
}

bool CpuLoadMonitor::snapshot(CpuTicks& t, double& self) const {
  std::string text;
  if (!src_->read("/proc/stat", text)) return false;
  t = parse_proc_stat(text, cpus_);
  if (t.cpus == 0) return false;
  self = src_->self_cpu_ticks();
  return self >= 0;
}

long long CpuLoadMonitor::min_window_ticks() const {
  // One tick of rounding per CPU may move the reading by at most a quarter core.
  const long long n = have_ ? t0_.cpus : static_cast<long long>(cpus_.size());
  return std::max(min_ticks_, 4LL * std::max(1LL, n));
}

void CpuLoadMonitor::mark() { have_ = snapshot(t0_, self0_); }

double CpuLoadMonitor::others_busy_cores() {
  CpuTicks t;
  double self = 0;
  if (!snapshot(t, self)) {
    have_ = false;
    return -1;
  }
  if (!have_ || t.cpus != t0_.cpus) {  // no start, or a CPU went on/offline: start again
    t0_ = t;
    self0_ = self;
    have_ = true;
    return -1;
  }
  const long long window = (t.total - t0_.total) / t.cpus;  // ticks per CPU
  // Too short to say (fewer ticks than the resolution rule needs for the CPUs in the text):
  // keep the window.
  if (window < min_window_ticks()) return -1;
  const double others = static_cast<double>(t.busy - t0_.busy) - (self - self0_);
  t0_ = t;
  self0_ = self;
  last_window_ = window;
  // Ticks are sampled: a window may show a little less than our own time; never negative.
  return std::max(0.0, others / static_cast<double>(window));
}

}  // namespace loom

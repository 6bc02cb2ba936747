// The load readings of `threads: auto` (loom/cpu_load.hpp) and its start-up rule
// (choose_start_threads, loom/threads.hpp; AutoThreadStart, loom/thread_start.hpp): the /proc
// parsers on texts recorded on Linux machines, the monitor and the rule on made-up "busy" and
// "idle" readings fed through ProcSource, and the safe fallback without /proc.
#include <gtest/gtest.h>

#include <deque>
#include <map>
#include <string>

#include "loom/common.hpp"
#include "loom/cpu_load.hpp"
#include "loom/thread_start.hpp"
#include "loom/threads.hpp"

using namespace loom;

namespace {

// Recorded on the 2-vCPU development VM (kernel 6.18; intr line shortened).
const char* kStat2 =
    "cpu  9118207 124541 758117 986729 10129 0 2372 22803 0 0\n"
    "cpu0 4570932 74525 366729 484091 3340 0 191 11276 0 0\n"
    "cpu1 4547274 50015 391387 502637 6789 0 2181 11527 0 0\n"
    "intr 38903227 0 0 0 0 0 0 0 0 0 0 0 0 0 0 0 0 0 0 0 0 0 0 0 0 1 1 14 0 0 0 0 11034 2111 0 910\n"
    "ctxt 103950649\n"
    "btime 1795896338\n"
    "processes 450319\n"
    "procs_running 9\n"
    "procs_blocked 0\n"
    "softirq 10359830 0 2245869 4 109579 938716 0 11 2417590 0 4648061\n";

// A 2.6.18-era kernel: 7 numbers per CPU (no steal, guest); CPU 1 offline (no line).
const char* kStatOld =
    "cpu  100 2 30 900 5 1 2\n"
    "cpu0 60 1 20 400 3 1 1\n"
    "cpu2 40 1 10 500 2 0 1\n"
    "intr 1234 5 6\n";

// /proc/<pid>/stat of `cat` and of a process whose name holds spaces and parentheses.
const char* kSelfCat =
    "26334 (cat) R 26331 26331 20327 0 -1 4194304 97 0 0 0 0 0 0 0 20 0 1 0 5526197 3133440 360 "
    "18446744073709551615 94848375132160 94848375152041 140731440651712 0 0 0 0 0 0 0 0 0 17 1 0 0 0 0 0\n";
const char* kSelfOdd =
    "4242 (loom (run) x) S 1 4242 4242 0 -1 4194560 5000 0 0 0 1234 567 0 0 20 0 3 0 100 1000 50 0\n";

// A ProcSource that serves texts per path: a queue (one text per read; the last one stays),
// or nothing (a path that is not there). This process's CPU time: the queue `clock` (ticks with
// their fraction, as CLOCK_PROCESS_CPUTIME_ID gives) when given, else the /proc/self/stat texts
// (whole ticks); its running threads: `running_self` (the reader alone by default).
struct FakeProc : ProcSource {
  mutable std::map<std::string, std::deque<std::string>> files;
  mutable std::deque<double> clock;
  int running_self = 1;
  bool read(const char* path, std::string& text) const override {
    auto it = files.find(path);
    if (it == files.end() || it->second.empty()) return false;
    text = it->second.front();
    if (it->second.size() > 1) it->second.pop_front();
    return true;
  }
  double self_cpu_ticks() const override {
    if (!clock.empty()) {
      const double c = clock.front();
      if (clock.size() > 1) clock.pop_front();
      return c;
    }
    std::string text;
    if (!read("/proc/self/stat", text)) return -1;
    return static_cast<double>(parse_self_stat_ticks(text));
  }
  int self_running_threads() const override { return running_self; }
  void push(const char* path, std::string text) { files[path].push_back(std::move(text)); }
};

// A /proc/stat text of two CPUs with the given busy and idle ticks each.
std::string stat2(long long busy0, long long idle0, long long busy1, long long idle1) {
  // busy split as user + system + steal to exercise the field sum
  auto line = [](int id, long long busy, long long idle) {
    const long long u = busy / 2, s = busy / 4, st = busy - u - s;
    return "cpu" + std::to_string(id) + " " + std::to_string(u) + " 0 " + std::to_string(s) + " " +
           std::to_string(idle) + " 0 0 0 " + std::to_string(st) + " 0 0\n";
  };
  return "cpu  0 0 0 0 0 0 0 0 0 0\n" + line(0, busy0, idle0) + line(1, busy1, idle1) + "procs_running 1\n";
}
std::string self(long long utime, long long stime) {
  return "77 (loom) R 1 77 77 0 -1 0 0 0 0 0 " + std::to_string(utime) + " " + std::to_string(stime) +
         " 0 0 20 0 2 0 1 1 1\n";
}

}  // namespace

TEST(ProcParsers, ProcStatSumsBusyAndTotalOverTheChosenCpus) {
  // busy = user + nice + system + irq + softirq + steal; total = busy + idle + iowait.
  const long long b0 = 4570932 + 74525 + 366729 + 0 + 191 + 11276, t0 = b0 + 484091 + 3340;
  const long long b1 = 4547274 + 50015 + 391387 + 0 + 2181 + 11527, t1 = b1 + 502637 + 6789;
  const CpuTicks all = parse_proc_stat(kStat2, {});
  EXPECT_EQ(all.cpus, 2);  // the aggregate "cpu " line is not a CPU
  EXPECT_EQ(all.busy, b0 + b1);
  EXPECT_EQ(all.total, t0 + t1);
  const CpuTicks one = parse_proc_stat(kStat2, {1});
  EXPECT_EQ(one.cpus, 1);
  EXPECT_EQ(one.busy, b1);
  EXPECT_EQ(one.total, t1);
  EXPECT_EQ(parse_proc_stat(kStat2, {5}).cpus, 0);  // a CPU not in the text
}

TEST(ProcParsers, ProcStatOfAnOldKernelWithAnOfflineCpu) {
  const CpuTicks t = parse_proc_stat(kStatOld, {0, 1, 2});
  EXPECT_EQ(t.cpus, 2);
  EXPECT_EQ(t.busy, (60 + 1 + 20 + 1 + 1) + (40 + 1 + 10 + 0 + 1));
  EXPECT_EQ(t.total, t.busy + (400 + 3) + (500 + 2));
  // Four numbers are enough (user nice system idle); three are not.
  EXPECT_EQ(parse_proc_stat("cpu3 5 0 5 90\n", {}).total, 100);
  EXPECT_EQ(parse_proc_stat("cpu3 5 0 5\n", {}).cpus, 0);
  EXPECT_EQ(parse_proc_stat("", {}).cpus, 0);
  EXPECT_EQ(parse_proc_stat("no such file\n", {}).cpus, 0);
}

TEST(ProcParsers, SelfStatTicksAfterTheCommandName) {
  EXPECT_EQ(parse_self_stat_ticks(kSelfCat), 0);
  EXPECT_EQ(parse_self_stat_ticks(kSelfOdd), 1234 + 567);
  EXPECT_EQ(parse_self_stat_ticks("4242 (x) S 1 2 3"), -1);  // cut short
  EXPECT_EQ(parse_self_stat_ticks("garbage"), -1);
  EXPECT_EQ(parse_self_stat_ticks(""), -1);
}

TEST(ProcParsers, LoadavgRunningCount) {
  EXPECT_EQ(parse_loadavg_running("0.48 1.82 2.58 3/112 26335\n"), 3);
  EXPECT_EQ(parse_loadavg_running("12.00 9.50 8.25 17/1024 4\n"), 17);
  EXPECT_EQ(parse_loadavg_running("0.48 1.82 2.58\n"), -1);
  EXPECT_EQ(parse_loadavg_running("0.48 1.82 2.58 x/112 1\n"), -1);
  EXPECT_EQ(parse_loadavg_running(""), -1);
}

TEST(ProcParsers, TheLiveProcFilesParse) {
  std::string text;
  if (!ProcSource().read("/proc/stat", text)) GTEST_SKIP() << "no /proc on this machine";
  const auto cpus = affinity_cpus();
  const CpuTicks t = parse_proc_stat(text, cpus);
  EXPECT_GE(t.cpus, 1);
  EXPECT_GT(t.total, t.busy - 1);
  ASSERT_TRUE(ProcSource().read("/proc/self/stat", text));
  EXPECT_GE(parse_self_stat_ticks(text), 0);
  ASSERT_TRUE(ProcSource().read("/proc/loadavg", text));
  EXPECT_GE(parse_loadavg_running(text), 1);  // this test is running
  CpuLoadMonitor m;
  EXPECT_GE(m.cpus(), 1);
}

// Window of 100 ticks per CPU on 2 CPUs; we used 60 ticks; the CPUs' busy ticks grew by 170:
// others kept (170 - 60) / 100 = 1.1 cores busy.
TEST(CpuLoadMonitor, OthersBusyCoresIsBusyMinusOurOwnOverTheWindow) {
  FakeProc p;
  p.push("/proc/stat", stat2(1000, 1000, 2000, 500));
  p.push("/proc/stat", stat2(1000 + 90, 1000 + 10, 2000 + 80, 500 + 20));
  p.push("/proc/self/stat", self(300, 100));
  p.push("/proc/self/stat", self(340, 120));
  CpuLoadMonitor m({}, &p);
  EXPECT_DOUBLE_EQ(m.others_busy_cores(), (170.0 - 60.0) / 100.0);
  EXPECT_EQ(m.last_window_ticks(), 100);
}

TEST(CpuLoadMonitor, AShortWindowIsUnknownAndKeepsGrowing) {
  FakeProc p;
  p.push("/proc/stat", stat2(0, 0, 0, 0));
  p.push("/proc/stat", stat2(2, 1, 3, 0));     // 3 ticks per CPU: below the 5 needed
  p.push("/proc/stat", stat2(10, 10, 20, 0));  // 20 per CPU since the first reading
  p.push("/proc/self/stat", self(0, 0));
  CpuLoadMonitor m({}, &p, 5);
  EXPECT_EQ(m.others_busy_cores(), -1);
  EXPECT_DOUBLE_EQ(m.others_busy_cores(), 30.0 / 20.0);
}

TEST(CpuLoadMonitor, OnlyTheCpusOfTheMask) {
  // CPU 0 fully busy (a competitor pinned there), CPU 1 idle; watching CPU 1 only sees no load.
  FakeProc p;
  p.push("/proc/stat", stat2(0, 0, 0, 0));
  p.push("/proc/stat", stat2(100, 0, 0, 100));
  p.push("/proc/self/stat", self(0, 0));
  CpuLoadMonitor on1({1}, &p);
  EXPECT_DOUBLE_EQ(on1.others_busy_cores(), 0.0);
  FakeProc q = p;
  q.files["/proc/stat"] = {stat2(0, 0, 0, 0), stat2(100, 0, 0, 100)};
  CpuLoadMonitor both({}, &q);
  EXPECT_DOUBLE_EQ(both.others_busy_cores(), 100.0 / 100.0);
}

TEST(CpuLoadMonitor, NoProcIsUnknownEverywhere) {
  FakeProc none;
  CpuLoadMonitor m({}, &none);
  EXPECT_EQ(m.others_busy_cores(), -1);
  EXPECT_EQ(m.others_runnable(), -1);
  FakeProc half;  // /proc/stat but no /proc/self/stat
  half.push("/proc/stat", stat2(0, 0, 0, 0));
  CpuLoadMonitor h({}, &half);
  EXPECT_EQ(h.others_busy_cores(), -1);
}

TEST(StartRule, FreeCoresRoundsOthersToWholeCoresFromHalfACore) {
  EXPECT_EQ(free_cores(2, 2, 0.0), 2);
  EXPECT_EQ(free_cores(2, 2, 0.49), 2);
  EXPECT_EQ(free_cores(2, 2, 0.5), 1);
  EXPECT_EQ(free_cores(2, 2, 1.0), 1);
  EXPECT_EQ(free_cores(2, 2, 3.0), 1);    // at least 1
  EXPECT_EQ(free_cores(4, 4, 1.4), 3);
  EXPECT_EQ(free_cores(2, 16, 3.0), 2);   // a 2-core quota on 16 CPUs: 13 free, capped at 2
  EXPECT_EQ(free_cores(2, 2, -1), -1);
}

TEST(StartRule, BusyIdleSmallAndUnknown) {
  const long long big = 4 * kParallelMinVertices, small = kParallelMinVertices - 1;
  EXPECT_EQ(choose_start_threads(2, 2, 1.0, -1, big).threads, 1);   // a competitor on one core
  EXPECT_EQ(choose_start_threads(2, 2, 0.05, -1, big).threads, 2);  // idle
  EXPECT_EQ(choose_start_threads(4, 4, 1.2, -1, big).threads, 3);
  const ThreadStart s = choose_start_threads(2, 2, 0.0, -1, small);  // idle, small mesh: serial
  EXPECT_EQ(s.threads, 1);
  EXPECT_TRUE(s.small_mesh);
  EXPECT_EQ(s.free, 2);
  EXPECT_EQ(choose_start_threads(2, 2, 0.0, -1, kParallelMinVertices).threads, 2);
  // Under an iterative solver whose row loops run in parallel from kParallelMinRows
  // (LinearSolver::parallel_min_rows): ground_plane's 2304 vertices start on the free cores.
  EXPECT_EQ(choose_start_threads(2, 2, 0.0, -1, 2304).threads, 1);
  EXPECT_EQ(choose_start_threads(2, 2, 0.0, -1, 2304, kParallelMinRows).threads, 2);
  EXPECT_EQ(choose_start_threads(2, 2, 1.0, -1, 2304, kParallelMinRows).threads, 1);  // busy: still 1
  EXPECT_TRUE(choose_start_threads(2, 2, 0.0, -1, kParallelMinRows - 1, kParallelMinRows).small_mesh);
  // Window unknown: the runnable count decides; both unknown: all cores.
  EXPECT_EQ(choose_start_threads(2, 2, -1, 1, big).threads, 1);
  EXPECT_EQ(choose_start_threads(2, 2, -1, 0, big).threads, 2);
  const ThreadStart u = choose_start_threads(2, 2, -1, -1, big);
  EXPECT_EQ(u.threads, 2);
  EXPECT_EQ(u.free, -1);
}

// The set-up window and the gate, end to end on fake readings.
TEST(AutoThreadStart, BusySetUpStartsOnOneAndTheGateHoldsBackMoreThreads) {
  FakeProc p;
  // Set-up: 100 ticks per CPU; we used 80, the CPUs 190: others 1.1 cores.
  p.push("/proc/stat", stat2(0, 0, 0, 0));
  p.push("/proc/stat", stat2(100, 0, 90, 10));
  p.push("/proc/self/stat", self(0, 0));
  p.push("/proc/self/stat", self(80, 0));
  AutoThreadStart a(&p, {0, 1});
  auto ctl = a.finish(2, 4 * kParallelMinVertices);
  ASSERT_NE(ctl, nullptr);
  EXPECT_EQ(a.start().threads, 1);
  EXPECT_EQ(ctl->threads(), 1);
  EXPECT_NEAR(ctl->start_load(), 1.1, 1e-12);
  // The same readings go on (the last text stays): the cores stay busy, so a long run where
  // 2 threads would be 20x slower never tries them.
  for (int s = 0; s < 2000; ++s) ctl->record(ctl->threads() == 1 ? 0.002 : 0.040);
  EXPECT_EQ(ctl->probes(), 0);
  EXPECT_GE(ctl->gated_probes(), 1);
  EXPECT_EQ(ctl->threads(), 1);
}

TEST(AutoThreadStart, IdleSetUpStartsOnTheCoresAndNoProcFallsBack) {
  FakeProc p;
  p.push("/proc/stat", stat2(0, 0, 0, 0));
  p.push("/proc/stat", stat2(100, 0, 100, 0));
  p.push("/proc/self/stat", self(0, 0));
  p.push("/proc/self/stat", self(195, 0));  // our own set-up kept both CPUs busy
  AutoThreadStart a(&p, {0, 1});
  auto ctl = a.finish(2, 4 * kParallelMinVertices);
  EXPECT_EQ(a.start().threads, 2);
  EXPECT_NEAR(a.others_busy(), 0.05, 1e-12);
  // No /proc/stat: the runnable count decides (/proc/loadavg: 2 running, us and one other).
  FakeProc loadavg;
  loadavg.push("/proc/loadavg", "1.00 1.00 1.00 2/100 999\n");
  AutoThreadStart b(&loadavg, {0, 1});
  auto c2 = b.finish(2, 4 * kParallelMinVertices);
  EXPECT_EQ(b.start().threads, 1);
  EXPECT_EQ(b.others_busy(), -1);
  EXPECT_EQ(others_runnable_sampled(&loadavg), 1);
  FakeProc none;  // nothing known: the cores
  AutoThreadStart c(&none, {0, 1});
  c.finish(2, 4 * kParallelMinVertices);
  EXPECT_EQ(c.start().threads, 2);
  EXPECT_EQ(others_runnable_sampled(&none), -1);
  AutoThreadStart d(&none, {0, 1});
  EXPECT_EQ(d.finish(1, 4 * kParallelMinVertices), nullptr);  // one core: nothing to adapt
  EXPECT_EQ(d.start().threads, 1);
}

// hanging_cloth under `threads: auto` (576 vertices, ~30 us steps, a set-up too short to
// measure): the steps start on 1 thread and stay there with no probe and no /proc reading
// after the set-up, even where 2 threads would measure faster (ThreadController's small-step
// rule, min_step_seconds).
TEST(AutoThreadStart, SmallSceneShortStepsNeverProbeNorReadProc) {
  struct CountingProc : FakeProc {
    mutable int reads = 0;
    bool read(const char* path, std::string& text) const override {
      ++reads;
      return FakeProc::read(path, text);
    }
  } p;
  p.push("/proc/stat", stat2(100, 100, 100, 100));  // the same ticks: a window too short to say
  p.push("/proc/self/stat", self(10, 0));
  p.push("/proc/loadavg", "1.00 1.00 1.00 2/100 999\n");
  AutoThreadStart a(&p, {0, 1});
  auto ctl = a.finish(2, 24 * 24);
  ASSERT_NE(ctl, nullptr);
  EXPECT_EQ(a.others_busy(), -1);
  EXPECT_EQ(a.start().threads, 1);
  ctl->set_run_steps(10020);
  const int reads_at_start = p.reads;
  for (int s = 0; s < 10020; ++s) {
    ASSERT_EQ(ctl->threads(), 1) << s;
    ctl->record(ctl->threads() == 1 ? 30e-6 : 20e-6);
  }
  EXPECT_EQ(ctl->probes(), 0);
  EXPECT_GE(ctl->small_step_holds(), 1);
  EXPECT_EQ(ctl->gate_reads(), 0);
  EXPECT_EQ(p.reads, reads_at_start);
}

// kang_cho_fig7_ho_k2000 alone on the quiet VM (docs/BENCHMARKS.md, tenth round; docs/ARCHITECTURE.md,
// "Threads: measured (issue 16, the 0.50 cores at kang_cho_fig7_ho_k2000's set-up)"): a set-up of
// 7 ticks per CPU on 2 CPUs. Nothing else ran: the CPUs' busy ticks grew by 13 and the process
// used 11.2 ticks by its clock, but /proc/self/stat's utime + stime, each cut to whole ticks,
// grew by 10 (4 + 2 -> 11 + 5: the cuts dropped 0.7 of a tick at the start, 1.9 at the end). The old reading,
// (13 - 10) / 7 = 0.43 rounded to whole ticks and the window accepted from 5 ticks, was within a
// tick of taking a core; with one more tick of rounding (14 busy) it read 0.57 and started on 1.
// Now: the clock is subtracted, and a 7-tick window on 2 CPUs cannot resolve half a core (one
// tick of rounding per CPU is 0.29 core): unknown, so the runnable count decides (nothing else
// runnable: both cores).
TEST(CpuLoadMonitor, AShortSetUpCannotTakeACoreFromRounding) {
  for (const long long busy : {13LL, 14LL}) {
    FakeProc p;
    p.push("/proc/stat", stat2(1000, 1000, 2000, 500));
    p.push("/proc/stat", stat2(1000 + busy / 2, 1000 + 7 - busy / 2, 2000 + busy - busy / 2, 500 + 7 - (busy - busy / 2)));
    p.push("/proc/self/stat", self(4, 2));
    p.push("/proc/self/stat", self(11, 5));
    p.clock = {6.7, 17.9};  // 11.2 ticks of CPU by the process's clock
    p.push("/proc/loadavg", "0.20 0.30 0.40 1/100 999\n");  // the reader alone
    AutoThreadStart a(&p, {0, 1});
    auto ctl = a.finish(2, 4 * kParallelMinVertices);
    EXPECT_EQ(a.others_busy(), -1) << busy;  // the window is too short to say
    EXPECT_EQ(a.start().threads, 2) << busy;
    EXPECT_EQ(a.start().free, 2) << busy;
    EXPECT_EQ(a.others_runnable(), 0) << busy;
  }
  // The same set-up over 8 ticks per CPU is long enough, and reads others' share from the clock:
  // (16 - 11.2) / 8 = 0.6 cores, not (16 - 10) / 8 = 0.75.
  FakeProc q;
  q.push("/proc/stat", stat2(1000, 1000, 2000, 500));
  q.push("/proc/stat", stat2(1008, 1000, 2008, 500));
  q.push("/proc/self/stat", self(4, 2));
  q.push("/proc/self/stat", self(11, 5));
  q.clock = {6.7, 17.9};
  CpuLoadMonitor m({}, &q);
  EXPECT_EQ(m.min_window_ticks(), 8);
  EXPECT_NEAR(m.others_busy_cores(), (16.0 - 11.2) / 8.0, 1e-12);
}

// A long enough window that reads a core busy is trusted only when something else is runnable
// now: a burst that ended during the set-up does not hold the run on 1 thread, a CPU-bound
// competitor (runnable at every reading) does.
TEST(AutoThreadStart, ABusyReadingMustBeConfirmedByARunnableProcess) {
  auto setup = [](FakeProc& p, const char* loadavg, int running_self) {
    // 20 ticks per CPU; we used 20 (one thread), the CPUs 34: others 0.7 cores.
    p.push("/proc/stat", stat2(0, 0, 0, 0));
    p.push("/proc/stat", stat2(20, 0, 14, 6));
    p.clock = {0.0, 20.0};
    p.push("/proc/loadavg", loadavg);
    p.running_self = running_self;
  };
  FakeProc ended;  // only we are running now: the busy reading is not confirmed
  setup(ended, "0.50 0.40 0.30 1/100 999\n", 1);
  AutoThreadStart a(&ended, {0, 1});
  auto ca = a.finish(2, 4 * kParallelMinVertices);
  EXPECT_NEAR(a.others_busy(), 0.7, 1e-12);
  EXPECT_EQ(a.others_runnable(), 0);
  EXPECT_EQ(a.start().threads, 2);
  EXPECT_TRUE(a.start().unconfirmed);
  ASSERT_NE(ca, nullptr);
  EXPECT_TRUE(ca->start_unconfirmed());
  FakeProc spinning;  // two running, both ours (an OpenMP worker still spinning): not others
  setup(spinning, "0.50 0.40 0.30 2/100 999\n", 2);
  AutoThreadStart b(&spinning, {0, 1});
  b.finish(2, 4 * kParallelMinVertices);
  EXPECT_EQ(b.others_runnable(), 0);
  EXPECT_EQ(b.start().threads, 2);
  FakeProc competitor;  // two running, one ours: a competitor
  setup(competitor, "1.00 1.00 1.00 2/100 999\n", 1);
  AutoThreadStart c(&competitor, {0, 1});
  auto cc = c.finish(2, 4 * kParallelMinVertices);
  EXPECT_EQ(c.others_runnable(), 1);
  EXPECT_EQ(c.start().threads, 1);
  EXPECT_FALSE(c.start().unconfirmed);
  ASSERT_NE(cc, nullptr);
  EXPECT_EQ(cc->start_runnable(), 1);
}

TEST(ProcParsers, RunnableCountLeavesOutOurOwnRunningThreads) {
  FakeProc p;
  p.push("/proc/loadavg", "2.00 1.00 1.00 3/100 999\n");
  p.running_self = 2;  // the reader and a spinning worker
  EXPECT_EQ(read_others_runnable(&p), 1);
  p.running_self = 3;
  EXPECT_EQ(read_others_runnable(&p), 0);
  p.running_self = -1;  // unknown: the reader only
  EXPECT_EQ(read_others_runnable(&p), 2);
  EXPECT_EQ(parse_stat_state(kSelfCat), 'R');
  EXPECT_EQ(parse_stat_state(kSelfOdd), 'S');
  EXPECT_EQ(parse_stat_state("4242 (x)"), 0);
  EXPECT_EQ(parse_stat_state("garbage"), 0);
}

// The real sources agree: the process's clock in ticks is /proc/self/stat's utime + stime plus
// what their cut to whole ticks dropped (less than a tick each), and at least one thread of this
// process (the reader) is running.
TEST(ProcParsers, TheProcessClockIsSelfStatWithTheFractions) {
  const ProcSource src;
  std::string before, after;
  if (!src.read("/proc/self/stat", before)) GTEST_SKIP() << "no /proc on this machine";
  const double clock = src.self_cpu_ticks();
  ASSERT_TRUE(src.read("/proc/self/stat", after));
  EXPECT_GE(clock, static_cast<double>(parse_self_stat_ticks(before)) - 1e-9);
  EXPECT_LT(clock, static_cast<double>(parse_self_stat_ticks(after)) + 2.0);
  EXPECT_GE(src.self_running_threads(), 1);
}

// The gate after a busy start: the first reading comes a few steps after the set-up, when the
// window is too short to measure; it is asked again at the next due probe (not a whole
// min_interval of steps later), so the start-up figure gives way as soon as a window is long
// enough. kang_cho_fig7_ho_k2000's tenth-round miss held 354 steps (0.29 s) on 1 thread that way.
TEST(AutoThreadStart, AnUnknownGateReadingIsAskedAgainAtTheNextDueProbe) {
  FakeProc p;
  // Set-up: others 1.1 cores over 100 ticks per CPU, a competitor runnable: start on 1.
  p.push("/proc/stat", stat2(0, 0, 0, 0));
  p.push("/proc/stat", stat2(100, 0, 90, 10));
  // The gate: 1 tick per CPU after the set-up (unknown), then 20 ticks per CPU in which our one
  // thread kept CPU 0 busy and CPU 1 idled: the competitor has gone.
  p.push("/proc/stat", stat2(101, 0, 91, 11));
  p.push("/proc/stat", stat2(120, 0, 90, 30));
  p.clock = {0.0, 80.0, 81.0, 100.0};
  p.push("/proc/loadavg", "1.00 1.00 1.00 2/100 999\n");
  AutoThreadStart a(&p, {0, 1});
  auto ctl = a.finish(2, 4 * kParallelMinVertices);
  ASSERT_NE(ctl, nullptr);
  EXPECT_EQ(a.start().threads, 1);
  int on1 = 0;
  for (int s = 0; s < 1000 && ctl->chosen() == 1; ++s) {
    on1 += ctl->threads() == 1;
    ctl->record(ctl->threads() == 1 ? 0.001 : 0.0005);
  }
  EXPECT_EQ(ctl->chosen(), 2);
  EXPECT_GE(ctl->gate_reads(), 2);
  // The first probe falls due after 10 step times of 1 thread (plus the skipped first step and
  // the 3 baseline samples); the reading that lets 2 threads in is the next due probe's, 10
  // step times later; the probe itself is 3 samples of 2 threads. Waiting for min_interval
  // (0.25 s of 1 ms steps) would be at least 250.
  EXPECT_LT(on1, 40);
}

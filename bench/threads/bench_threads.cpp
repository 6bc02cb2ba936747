// What `threads: auto`'s load readings cost (issue 16; loom/cpu_load.hpp, loom/thread_start.hpp).
//   build/bin/bench_threads --benchmark_repetitions=3 --benchmark_report_aggregates_only=true
// BM_LoadReading: one reading of the others' CPU use (/proc/stat parsed + the process's CPU clock):
//   taken at the end of the set-up and by the load gate at most once per 0.25 s of steps.
// BM_SetUpAndStart: a whole start-up decision as Simulation::build makes it (monitor created,
//   one reading, the rule, the controller attached), for a large mesh.
// BM_RunnableSampled: the fallback when the set-up was too short to measure (up to five
//   /proc/loadavg readings 2 ms apart while others are runnable: wall time, not CPU).
// BM_ParseProcStat: the parser alone on a 2-CPU /proc/stat text.
// The CPU column is the cost to the run; compare it with a step (0.05-3000 ms on the shipped scenes).
#include <benchmark/benchmark.h>

#include <string>

#include "loom/common.hpp"
#include "loom/cpu_load.hpp"
#include "loom/thread_start.hpp"
#include "loom/threads.hpp"

namespace {

void BM_LoadReading(benchmark::State& state) {
  loom::CpuLoadMonitor m({}, nullptr, 0);
  for (auto _ : state) benchmark::DoNotOptimize(m.others_busy_cores());
}
BENCHMARK(BM_LoadReading);

void BM_SetUpAndStart(benchmark::State& state) {
  for (auto _ : state) {
    loom::AutoThreadStart a;
    auto ctl = a.finish(loom::usable_cores(), 16 * loom::kParallelMinVertices);
    benchmark::DoNotOptimize(ctl.get());
  }
}
BENCHMARK(BM_SetUpAndStart);

void BM_RunnableSampled(benchmark::State& state) {
  for (auto _ : state) benchmark::DoNotOptimize(loom::others_runnable_sampled());
}
BENCHMARK(BM_RunnableSampled)->UseRealTime();

void BM_ParseProcStat(benchmark::State& state) {
  const std::string text =
      "cpu  9118207 124541 758117 986729 10129 0 2372 22803 0 0\n"
      "cpu0 4570932 74525 366729 484091 3340 0 191 11276 0 0\n"
      "cpu1 4547274 50015 391387 502637 6789 0 2181 11527 0 0\n"
      "intr 38903227 0 0 0 0 0 0 0 0 0 0 0 0 0 0 0 0 0 0 0 0 0 0 0 0 1 1 14 0 0 0 0 11034 2111 0 910\n"
      "ctxt 103950649\nbtime 1795896338\nprocesses 450319\nprocs_running 9\nprocs_blocked 0\n";
  for (auto _ : state) benchmark::DoNotOptimize(loom::parse_proc_stat(text, {}).busy);
}
BENCHMARK(BM_ParseProcStat);

}  // namespace

BENCHMARK_MAIN();

#include "loom/thread_start.hpp"

#include "loom/common.hpp"

namespace loom {

AutoThreadStart::AutoThreadStart(const ProcSource* src, std::vector<int> cpus)
    : load_(std::make_shared<CpuLoadMonitor>(std::move(cpus), src)), src_(src) {}

std::unique_ptr<ThreadController> AutoThreadStart::finish(int cores, long long vertices) {
  const int mask = load_->cpus() > 0 ? load_->cpus() : cores;
  others_busy_ = load_->others_busy_cores();
  const bool small = vertices >= 0 && vertices < kParallelMinVertices;
  const int runnable = others_busy_ < 0 && !small && cores > 1 ? others_runnable_sampled(src_) : -1;
  start_ = choose_start_threads(cores, mask, others_busy_, runnable, vertices);
  if (cores < 2) return nullptr;
  auto ctl = std::make_unique<ThreadController>(start_.threads, cores);
  ctl->set_start_load(others_busy_);
  // The gate: the cores free since the last reading, or the last known figure while the
  // window is still too short to measure.
  ctl->set_free_cores([load = load_, cores, mask, last = start_.free]() mutable {
    const int f = free_cores(cores, mask, load->others_busy_cores());
    if (f > 0) last = f;
    return last;
  });
  return ctl;
}

}  // namespace loom

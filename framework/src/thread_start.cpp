#include "loom/thread_start.hpp"

#include "loom/common.hpp"

namespace loom {

AutoThreadStart::AutoThreadStart(const ProcSource* src, std::vector<int> cpus)
    : load_(std::make_shared<CpuLoadMonitor>(std::move(cpus), src)), src_(src) {}

std::unique_ptr<ThreadController> AutoThreadStart::finish(int cores, long long vertices, long long serial_below) {
  const int mask = load_->cpus() > 0 ? load_->cpus() : cores;
  others_busy_ = load_->others_busy_cores();
  const bool small = vertices >= 0 && vertices < serial_below;
  // The runnable count: the fallback when the set-up was too short to measure, and the check
  // of a reading that takes cores from the run (choose_start_threads); not for a small mesh,
  // which starts on 1 thread anyway.
  int runnable = -1;
  if (!small && cores > 1) {
    if (others_busy_ < 0) runnable = others_runnable_sampled(src_);
    else if (free_cores(cores, mask, others_busy_) < cores) runnable = others_runnable_confirm(src_);
  }
  runnable_ = runnable;
  start_ = choose_start_threads(cores, mask, others_busy_, runnable, vertices, serial_below);
  if (cores < 2) return nullptr;
  auto ctl = std::make_unique<ThreadController>(start_.threads, cores);
  ctl->set_start_load(others_busy_, runnable, start_.unconfirmed);
  // The gate: the cores free since the last reading; -1 while the window is still too short
  // to measure (the controller keeps its last figure, this start's, and asks again at the
  // next due probe).
  ctl->set_free_cores([load = load_, cores, mask]() { return free_cores(cores, mask, load->others_busy_cores()); },
                      start_.free);
  return ctl;
}

}  // namespace loom

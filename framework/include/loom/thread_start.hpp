// `threads: auto` from set-up to steps (docs/ARCHITECTURE.md, "Threads"): measure the other
// processes' CPU use while the scene is set up, choose the count the steps start on
// (choose_start_threads, loom/threads.hpp) and attach the step-time controller with a load
// gate that reads the same monitor when a probe is due (loom/thread_controller.hpp).
#pragma once

#include <memory>

#include "loom/cpu_load.hpp"
#include "loom/thread_controller.hpp"
#include "loom/threads.hpp"

namespace loom {

class AutoThreadStart {
 public:
  /// Begins the set-up window (the real /proc; src for tests).
  explicit AutoThreadStart(const ProcSource* src = nullptr, std::vector<int> cpus = {});
  /// At the end of the set-up: the start count (see choose_start_threads) for a mesh of
  /// `vertices`, and the controller to adapt it (null on one usable core). When the set-up was
  /// too short to measure and the mesh is not small, the runnable count decides
  /// (others_runnable_sampled: up to 8 ms of sleep while others are runnable); when the reading
  /// takes cores from the run, the runnable count must confirm it (others_runnable_confirm: up
  /// to 2 ms of sleep while nothing else is runnable). serial_below: choose_start_threads'. Call once.
  std::unique_ptr<ThreadController> finish(int cores, long long vertices,
                                           long long serial_below = kParallelMinVertices);
  const ThreadStart& start() const { return start_; }
  double others_busy() const { return others_busy_; }  ///< during the set-up; -1 unknown
  int others_runnable() const { return runnable_; }     ///< the runnable count read at the start; -1 not read

 private:
  std::shared_ptr<CpuLoadMonitor> load_;
  const ProcSource* src_;
  ThreadStart start_;
  double others_busy_ = -1;
  int runnable_ = -1;
};

}  // namespace loom

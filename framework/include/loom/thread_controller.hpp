// The adaptive part of `threads: auto` (docs/ARCHITECTURE.md, "Threads"): during a run, measure
// the step time with each candidate thread count, keep the fastest, and measure again now and
// then, at a bounded cost.
//
// The start-up rule (choose_start_threads, loom/threads.hpp) chooses a count from the mesh size
// and the other processes' CPU use measured during the set-up. It cannot see what a count
// costs for this scene beyond the size rule, nor a competitor that starts or stops later. The
// controller corrects it from the step times themselves:
// - Samples: whole steps are batched until a batch lasts at least `sample_seconds` (2 ms); a
//   sample is the batch's mean step time. A count's time is the median of `samples` (3) samples.
//   The first step of the run (set-up work) is not sampled.
// - Step-cost variation: when the steps themselves differ in cost whatever the count (contact
//   and friction solves, self-collision list rebuilds every few steps), one-step samples of two
//   counts compare different steps, and a count "wins" on a cheap step. The chosen count's last
//   8 samples measure it: while the third-largest is more than `cost_spread` (20%) above the
//   third-smallest, a sample spans twice as many steps (and still at least 2 ms; never
//   shortened again), up to `max_sample_steps` (16) and while the longer sample would last at
//   most `max_sample_seconds` (0.5 s: the drift rule below needs 3 samples, so a competitor
//   that starts still shows within a few seconds); the baseline then starts again with the
//   longer samples, and probes use the same length. Two slow (preempted) or two fast samples
//   among the 8 do not count. Every other step 4x as expensive, 2 threads 1.25x faster:
//   one-step samples switched 84 times in 2000 steps, with 43% of the time on 1 thread;
//   2-step samples compare exactly (tests).
// - Probe: the current count's last samples are its baseline; each other candidate (1 and the
//   usable cores) is then run for `samples` samples, or for one sample when that sample is more
//   than `reject_factor` (1.5) x the baseline (a clearly worse count costs one sample, not three).
//   The fastest median wins; another count replaces the current one only when it is at least
//   `switch_gain` (3%) faster.
// - When: the first probe after `first_probe_steps` (10) step times (and the baseline's 3
//   samples): a probe of a count twice as slow then costs about one step in ten, once, and a
//   wrong start-up guess is corrected early in a short run. Early down-probe: a count below the
//   start count whose worst cost is at most `early_probe_cost` (1.5) step times is tried at
//   once, as soon as the baseline exists (that first probe leaves the other counts out for the
//   next probe, due as after any decision). With
//   fewer threads a step is at most start/count times as long (the same work on fewer
//   threads), so its worst cost is (start/count - 1) step times per sample: one sample when
//   that ratio is above `reject_factor`, `samples` otherwise; so 1 of 2 threads costs at most
//   one step, 2 of 3 or 4 at most 1.5, 1 of 4 (3 step times) waits for the 10. Why: a start on
//   2 threads next to a competitor the set-up did not see (the scene draped_ball_gnatv_bw with
//   the start forced to 2 under a load average of 9: 2-thread steps 350-420 ms against 70-120
//   ms on 1) spent 11 steps (about 4 s, more than the other 29 steps) before its first probe.
//   Later probes when the time since the last decision reaches the expected cost of
//   the next probe divided by `overhead` (3%), and at least `min_interval`; so probing costs
//   about 3% of the step time. The expected cost is the larger of what the last probe cost (its
//   steps' excess over the baseline) and the losers' median excess times their probe steps, and
//   at least half the previous estimate (a preempted step can cost many medians, so one cheap
//   probe does not bring the next one forward). When the chosen count's step time drifts by more
//   than `drift` (1.5x either way: a competitor started or stopped, the scene changed), the next
//   probe may come twice as early (6%).
// - Run length: when the run's total step count is known (set_run_steps; Simulation::run gives
//   frames x steps per frame), a probe starts only when the rest of the run can repay it: a count
//   `repay_gain` (10%) faster over the steps left after the probe must win back what the probe may
//   cost, taken as the larger of the expected cost above and the sum over the other counts of: a
//   count `reject_factor` times slower run for its whole probe, or, for a count above the chosen
//   one that was never measured (the start-up rule saw a competitor and started lower),
//   `unmeasured_cost` (10) step times: one step of more threads than free cores waits at every
//   barrier for a descheduled thread (measured under load: 20x the one-thread step on
//   draped_ball_rk4). Short runs (a few dozen steps of a slow scene, a short run that started
//   below the cores because the machine was busy, or the tail of any run) are then not probed and
//   keep the start-up count. Unknown length (0): no such limit.
// - Load gate: when the controller is given a reading of the cores free now (set_free_cores:
//   usable cores less those other processes kept busy since the last reading, from /proc/stat;
//   loom/cpu_load.hpp), a due probe leaves out every count above the chosen one that exceeds
//   the free cores (more threads than free cores wait at every barrier for a descheduled
//   thread), and is not started when no count is left (counted in gated_probes()). A count
//   above the chosen one that the reading allows costs what any other count may cost (the
//   `unmeasured_cost` bound is for an unknown reading). So next to a busy process a run never
//   tries more threads, and it tries them again once the reading shows the cores free.
// - Small steps: while the chosen count's step time is below `min_step_seconds` (100 us), a due
//   probe leaves out every count above the chosen one, before any load reading, and is not
//   started when no count is left (counted in small_step_holds()). Such a step has no loop long
//   enough to be split: loops below kParallelMinVertices (4096) vertex updates run serially
//   (loom/common.hpp), and 4096 vertex updates of the cheapest steps take 200-290 us on one
//   thread (HO in table1, 71 ns per vertex; hanging_cloth's symplectic Euler, 61 ns).
//   So more threads can only add barriers, and their probe (one 2 ms sample at least, a
//   scheduler slice when a thread is descheduled) is pure risk: a small scene on 1 thread stays
//   on 1 thread without trials. A count below the chosen one is still tried, and when the step
//   grows (contact, a larger scene after a reset) probes of more threads resume.
// The controller is pure logic on the step times it is given (no clock of its own), so tests
// drive it with made-up times. Simulation::step feeds it and applies threads().
#pragma once

#include <functional>

namespace loom {

struct ThreadControllerConfig {
  double sample_seconds = 2e-3;   ///< a sample is a batch of whole steps lasting at least this
  int samples = 3;                ///< samples per count in a probe (median); at most kMaxSamples
  double reject_factor = 1.5;     ///< a probe sample this much slower than the baseline ends that probe
  double switch_gain = 0.03;      ///< another count must be this much faster to replace the current one
  double overhead = 0.03;         ///< probing may cost this fraction of the step time
  double first_probe_steps = 10;  ///< first probe after this many (baseline) step times
  double min_interval = 0.25;     ///< later probes never sooner than this (seconds) after a decision
  double drift = 1.5;             ///< the chosen count's time changed by this factor: probe twice as early
  double repay_gain = 0.10;       ///< with a known run length: a probe must be repaid by a count this much faster
  double unmeasured_cost = 10;    ///< ... and a never-measured count above the chosen one may cost this many step times
  double min_step_seconds = 1e-4; ///< a chosen count's step shorter than this never tries more threads
  double early_probe_cost = 1.5;  ///< first probe: fewer threads whose worst cost is at most this many step times go at once
  double cost_spread = 0.2;       ///< the chosen count's last 8 samples spread more than this (3rd-largest / 3rd-smallest - 1): samples twice as long
  int max_sample_steps = 16;      ///< ... up to this many steps per sample
  double max_sample_seconds = 0.5;  ///< ... and while a sample stays this short (a competitor still shows within seconds)
};

class ThreadController {
 public:
  using Config = ThreadControllerConfig;
  static constexpr int kMaxSamples = 8;
  static constexpr int kMaxCandidates = 3;

  /// initial: the count the run starts with; max_threads: the usable cores. Candidates are
  /// initial, 1 and max_threads (distinct). With one candidate the controller never changes.
  explicit ThreadController(int initial, int max_threads, Config cfg = {});

  /// The count to use for the next step.
  int threads() const { return current_; }
  /// Feed the wall time of the step just taken with threads().
  void record(double step_seconds);
  /// The run's total number of steps, counted from the first record() (0: unknown, the default).
  /// Probes then start only when the steps left can repay them (see the top of this file).
  void set_run_steps(long total) { run_steps_ = total; }
  /// The load gate (see the top of this file): free() returns the cores free now, -1 when unknown
  /// (the window is still too short to measure: the last figure stays, `initial` before any, and
  /// the next due probe asks again). Read only when a probe is due, and after a known reading at
  /// most once per min_interval of step time.
  void set_free_cores(std::function<int()> free, int initial = -1) {
    free_cores_ = std::move(free);
    free_now_ = initial;
  }
  int initial() const { return cand_[0]; }           ///< the count the run started on
  int gated_probes() const { return gated_; }        ///< probes due but not started: no count fits the free cores
  int small_step_holds() const { return small_held_; }  ///< probes due but not started: the step is below min_step_seconds
  int gate_reads() const { return gate_reads_; }     ///< readings taken by the load gate
  /// What the start-up rule saw (informational): cores other processes kept busy during the set-up, -1 unknown;
  /// other processes runnable at the start, -1 not read; whether the runnable count overruled the load.
  void set_start_load(double cores, int runnable = -1, bool unconfirmed = false) {
    start_load_ = cores;
    start_runnable_ = runnable;
    start_unconfirmed_ = unconfirmed;
  }
  double start_load() const { return start_load_; }
  int start_runnable() const { return start_runnable_; }
  bool start_unconfirmed() const { return start_unconfirmed_; }
  long steps() const { return steps_; }              ///< steps recorded so far
  int skipped_probes() const { return skipped_; }    ///< probes due but not started: the run is too short to repay them

  int probes() const { return probes_; }              ///< probes started so far
  int switches() const { return switches_; }          ///< times the chosen count changed
  bool probing() const { return probing_; }
  int chosen() const { return chosen_; }              ///< the count kept by the last decision
  double probe_loss() const { return probe_loss_total_; }  ///< extra step time spent in probes (s), as measured
  double elapsed() const { return elapsed_; }         ///< total step time fed (s)
  int sample_steps() const { return sample_steps_; }  ///< the fewest steps a sample spans now (1, doubled by cost_spread)
  /// Steps recorded with `count` threads, and their total time (s); 0 for a count never used.
  long steps_on(int count) const;
  double seconds_on(int count) const;

 private:
  static double median(const double* v, int n);
  void on_sample(double s, int steps);
  void start_probe();
  bool probe_pays(double m) const;
  bool lengthen_samples(double s);
  double down_worst(int k) const;
  void next_candidate();
  void decide();

  Config cfg_;
  int cand_[kMaxCandidates] = {};
  int ncand_ = 0;
  int current_ = 1, chosen_ = 1;
  bool probing_ = false;
  bool skip_first_ = true;

  double elapsed_ = 0, since_decision_ = 0;
  int steps_since_decision_ = 0;
  double batch_time_ = 0;
  int batch_steps_ = 0;
  int sample_steps_ = 1;  // a sample spans at least this many steps (and sample_seconds)
  long steps_on_[kMaxCandidates] = {};     // per candidate: steps recorded on it
  double seconds_on_[kMaxCandidates] = {};  // ... and their time
  // The chosen count's last kSpreadSamples samples, for the spread (cost_spread).
  static constexpr int kSpreadSamples = 8;
  double spread_[kSpreadSamples] = {};
  int nspread_ = 0, spread_pos_ = 0;

  // The chosen count's recent samples (a ring) and its time at the last decision.
  double recent_[kMaxSamples] = {};
  int nrecent_ = 0, recent_pos_ = 0;
  double ref_ = 0;
  int decisions_ = 0;
  double next_loss_ = 0;  // expected extra time of the next probe (s)

  // The probe in progress: per candidate, its samples, steps per sample and whether rejected.
  double meas_[kMaxCandidates][kMaxSamples] = {};
  int nmeas_[kMaxCandidates] = {};
  int steps_per_sample_[kMaxCandidates] = {};
  bool rejected_[kMaxCandidates] = {};
  bool measured_[kMaxCandidates] = {};
  bool ever_measured_[kMaxCandidates] = {};   // measured in some probe (or the count chosen at the time)
  int probe_idx_ = 0;      // candidate index being probed
  int baseline_idx_ = 0;   // candidate index of the count that was chosen when the probe began
  double baseline_ = 0;    // its median step time
  double probe_loss_ = 0;  // extra time of this probe so far, against the baseline
  double probe_loss_total_ = 0;
  int probes_ = 0, switches_ = 0;
  long run_steps_ = 0, steps_ = 0;
  int skipped_ = 0;
  std::function<int()> free_cores_;
  int free_now_ = -1;                        // the gate's reading when the due probe was decided
  bool blocked_[kMaxCandidates] = {};        // left out of the due probe by the gate
  int gated_ = 0;
  int small_held_ = 0;
  bool early_tried_ = false;                 // the early down-probe was started or skipped
  double start_load_ = -1;
  int start_runnable_ = -1;
  bool start_unconfirmed_ = false;
  double gate_read_at_ = -1;                 // elapsed_ at the last gate reading
  int gate_reads_ = 0;
};

}  // namespace loom

#include "loom/thread_controller.hpp"

#include <algorithm>

namespace loom {

ThreadController::ThreadController(int initial, int max_threads, Config cfg) : cfg_(cfg) {
  cfg_.samples = std::clamp(cfg_.samples, 1, kMaxSamples);
  cfg_.max_sample_steps = std::max(1, cfg_.max_sample_steps);
  max_threads = std::max(1, max_threads);
  initial = std::clamp(initial, 1, max_threads);
  for (const int c : {initial, 1, max_threads})
    if (std::find(cand_, cand_ + ncand_, c) == cand_ + ncand_) cand_[ncand_++] = c;
  current_ = chosen_ = initial;
}

long ThreadController::steps_on(int count) const {
  for (int k = 0; k < ncand_; ++k)
    if (cand_[k] == count) return steps_on_[k];
  return 0;
}

double ThreadController::seconds_on(int count) const {
  for (int k = 0; k < ncand_; ++k)
    if (cand_[k] == count) return seconds_on_[k];
  return 0;
}

double ThreadController::median(const double* v, int n) {
  n = std::min(n, kMaxSamples);   // (records never exceed it)
  double a[kMaxSamples];
  for (int q = 0; q < n; ++q) {   // insertion sort of at most kMaxSamples values
    int r = q;
    for (; r > 0 && a[r - 1] > v[q]; --r) a[r] = a[r - 1];
    a[r] = v[q];
  }
  return n % 2 ? a[n / 2] : 0.5 * (a[n / 2 - 1] + a[n / 2]);
}

void ThreadController::record(double t) {
  for (int k = 0; k < ncand_; ++k)
    if (cand_[k] == current_) {
      ++steps_on_[k];
      seconds_on_[k] += t;
    }
  ++steps_;
  elapsed_ += t;
  since_decision_ += t;
  ++steps_since_decision_;
  if (ncand_ < 2) return;
  if (skip_first_) {  // the first step of a run carries set-up work: not sampled, not waited on
    skip_first_ = false;
    since_decision_ = 0;
    steps_since_decision_ = 0;
    return;
  }
  if (probing_) probe_loss_ += t - baseline_;
  batch_time_ += t;
  ++batch_steps_;
  if (batch_time_ < cfg_.sample_seconds || batch_steps_ < sample_steps_) return;
  const double s = batch_time_ / batch_steps_;
  const int steps = batch_steps_;
  batch_time_ = 0;
  batch_steps_ = 0;
  on_sample(s, steps);
}

void ThreadController::on_sample(double s, int steps) {
  if (probing_) {
    const int k = probe_idx_;
    meas_[k][nmeas_[k]++] = s;
    ever_measured_[k] = true;
    steps_per_sample_[k] = std::max(steps_per_sample_[k], steps);
    if (s > cfg_.reject_factor * baseline_) rejected_[k] = true;
    if (rejected_[k] || nmeas_[k] >= cfg_.samples) {
      measured_[k] = true;
      next_candidate();
    }
    return;
  }
  if (lengthen_samples(s)) return;
  const int n = cfg_.samples;
  recent_[recent_pos_] = s;
  recent_pos_ = (recent_pos_ + 1) % n;
  nrecent_ = std::min(nrecent_ + 1, n);
  for (int k = 0; k < ncand_; ++k)
    if (cand_[k] == chosen_) steps_per_sample_[k] = steps;
  if (nrecent_ < n) return;
  const double m = median(recent_, nrecent_);
  if (ref_ <= 0) ref_ = m;
  double need;
  bool early = false;  // the early down-probe (see the top of loom/thread_controller.hpp)
  if (decisions_ == 0) {
    need = cfg_.first_probe_steps * m;  // early: a wrong start-up guess costs most in a short run
    if (!early_tried_ && since_decision_ < need)
      for (int k = 0; k < ncand_; ++k)
        if (cand_[k] < chosen_ && down_worst(k) <= cfg_.early_probe_cost) early = true;
    if (early) need = 0;
  } else {
    const bool drifted = m > cfg_.drift * ref_ || m * cfg_.drift < ref_;
    need = std::max(cfg_.min_interval, next_loss_ / ((drifted ? 2.0 : 1.0) * cfg_.overhead));
  }
  if (since_decision_ < need) return;
  // Small steps (see the top of loom/thread_controller.hpp): counts above the chosen one stay
  // out while its step is below min_step_seconds; with nothing else to try, no probe and no
  // /proc reading.
  const bool small = m < cfg_.min_step_seconds;
  bool other = false;
  for (int k = 0; k < ncand_; ++k) other = other || (cand_[k] != chosen_ && !(small && cand_[k] > chosen_));
  if (!other) {
    ++small_held_;
    since_decision_ = 0;
    return;
  }
  // The load gate: counts above the chosen one that exceed the cores free now stay out. A
  // reading costs a /proc read (about 30 us): after a known one, at most one per min_interval
  // of step time; an unknown one (the window since the last is still too short to measure)
  // keeps the last figure and is asked again at the next due probe, so a start-up figure is
  // replaced as soon as the window is long enough rather than a whole interval later.
  if (free_cores_ && (gate_read_at_ < 0 || elapsed_ - gate_read_at_ >= cfg_.min_interval)) {
    const int f = free_cores_();
    ++gate_reads_;
    if (f > 0) {
      free_now_ = f;
      gate_read_at_ = elapsed_;
    }
  }
  bool any = false;
  for (int k = 0; k < ncand_; ++k) {
    blocked_[k] = (cand_[k] > chosen_ && (small || (free_now_ > 0 && cand_[k] > free_now_))) ||
                  (early && !(cand_[k] < chosen_ && down_worst(k) <= cfg_.early_probe_cost));
    any = any || (cand_[k] != chosen_ && !blocked_[k]);
  }
  if (!any) {
    ++gated_;
    since_decision_ = 0;
    return;
  }
  if (early) early_tried_ = true;  // once: a skipped early probe leaves the schedule as it was
  if (probe_pays(m)) {
    start_probe();
  } else {   // wait a full interval before asking again (the answer only gets worse as the run ends)
    ++skipped_;
    if (!early) since_decision_ = 0;  // a skipped early probe keeps the first probe's time
  }
}

// Step costs that vary from step to step (contact and friction solves, self-collision list
// rebuilds every few steps) make one-step samples of two counts incomparable: a probe of 3
// cheap steps against a baseline of expensive ones picks the wrong count (see the top of
// loom/thread_controller.hpp). The chosen count's last kSpreadSamples samples measure the
// variation; while the third-largest exceeds the third-smallest by more than cost_spread,
// samples span twice as many steps (a sample's mean over more steps varies less), up to
// max_sample_steps and max_sample_seconds, and the baseline starts again with the longer
// samples. Two slow steps among eight (preempted steps) or two fast ones do not count as
// variation.
bool ThreadController::lengthen_samples(double s) {
  spread_[spread_pos_] = s;
  spread_pos_ = (spread_pos_ + 1) % kSpreadSamples;
  nspread_ = std::min(nspread_ + 1, kSpreadSamples);
  if (nspread_ < kSpreadSamples || sample_steps_ >= cfg_.max_sample_steps) return false;
  double a[kSpreadSamples];
  std::copy(spread_, spread_ + kSpreadSamples, a);
  std::sort(a, a + kSpreadSamples);
  const double lo = a[2], hi = a[kSpreadSamples - 3];
  if (!(hi > (1.0 + cfg_.cost_spread) * lo)) return false;
  // (a sample is a mean step time: the longer sample lasts about twice sample_steps_ of them)
  if (2.0 * sample_steps_ * 0.5 * (a[3] + a[4]) > cfg_.max_sample_seconds) return false;
  sample_steps_ = std::min(2 * sample_steps_, cfg_.max_sample_steps);
  nspread_ = spread_pos_ = 0;
  nrecent_ = recent_pos_ = 0;
  ref_ = 0;
  return true;
}

// The most a count below the chosen one can cost in a probe, in step times of the chosen
// count: its step is at most chosen/count times as long; one sample when that is above
// reject_factor (the probe then ends), `samples` otherwise; a sample of the chosen count's
// steps per sample.
double ThreadController::down_worst(int k) const {
  int sps = 1;
  for (int j = 0; j < ncand_; ++j)
    if (cand_[j] == chosen_) sps = std::max(1, steps_per_sample_[j]);
  const double r = static_cast<double>(chosen_) / cand_[k];
  return (r > cfg_.reject_factor ? 1 : cfg_.samples) * sps * (r - 1.0);
}

bool ThreadController::probe_pays(double m) const {
  if (run_steps_ <= 0) return true;
  // The probe's length in steps: `samples` samples of each other count, at the larger of its
  // known steps per sample and the chosen count's.
  int sps = 1;
  for (int k = 0; k < ncand_; ++k)
    if (cand_[k] == chosen_) sps = std::max(1, steps_per_sample_[k]);
  double len = 0, bound = 0;
  for (int k = 0; k < ncand_; ++k) {
    if (cand_[k] == chosen_ || blocked_[k]) continue;
    const double lk = cfg_.samples * std::max(sps, steps_per_sample_[k]);
    len += lk;
    // (a count the gate allowed is no riskier than any other)
    const bool unknown_up = cand_[k] > chosen_ && !ever_measured_[k] && free_now_ < 0;
    bound += unknown_up ? cfg_.unmeasured_cost * m : (cfg_.reject_factor - 1.0) * m * lk;
  }
  const double left = static_cast<double>(run_steps_ - steps_) - len;
  const double cost = std::max(next_loss_, bound);
  return left > 0 && cfg_.repay_gain * m * left >= cost;
}

void ThreadController::start_probe() {
  baseline_idx_ = 0;
  for (int k = 0; k < ncand_; ++k) {
    nmeas_[k] = 0;
    rejected_[k] = false;
    measured_[k] = blocked_[k];  // left out: never run in this probe
    if (cand_[k] == chosen_) baseline_idx_ = k;
    else steps_per_sample_[k] = 0;
  }
  const int b = baseline_idx_;
  ever_measured_[b] = true;
  std::copy(recent_, recent_ + nrecent_, meas_[b]);
  nmeas_[b] = nrecent_;
  measured_[b] = true;
  baseline_ = median(recent_, nrecent_);
  probing_ = true;
  ++probes_;
  probe_loss_ = 0;
  probe_idx_ = -1;
  next_candidate();
}

void ThreadController::next_candidate() {
  batch_time_ = 0;
  batch_steps_ = 0;
  for (int k = probe_idx_ + 1; k < ncand_; ++k)
    if (!measured_[k]) {
      probe_idx_ = k;
      current_ = cand_[k];
      return;
    }
  decide();
}

void ThreadController::decide() {
  double med[kMaxCandidates] = {};
  for (int k = 0; k < ncand_; ++k) med[k] = nmeas_[k] > 0 ? median(meas_[k], nmeas_[k]) : 0;
  int w = baseline_idx_, a = baseline_idx_;
  for (int k = 0; k < ncand_; ++k)
    if (nmeas_[k] > 0 && med[k] < med[a]) a = k;
  if (a != w && med[a] < (1.0 - cfg_.switch_gain) * med[w]) w = a;
  // What the next probe is expected to cost: each loser run for as many steps as this probe
  // ran it (the old baseline: one sample if it would be rejected, else `samples`), at its
  // measured excess over the winner.
  // A step that a competitor preempts can take many times its median, so the estimate decays
  // (halves per probe) rather than forgetting a costly probe at once.
  double loss = 0;
  for (int k = 0; k < ncand_; ++k) {
    if (k == w || nmeas_[k] == 0) continue;
    const bool rej = k == baseline_idx_ ? med[k] > cfg_.reject_factor * med[w] : rejected_[k];
    const double n = (rej ? 1 : cfg_.samples) * std::max(1, steps_per_sample_[k]);
    loss += n * std::max(0.0, med[k] - med[w]);
  }
  next_loss_ = std::max({loss, probe_loss_, 0.5 * next_loss_});
  probe_loss_total_ += probe_loss_;
  if (cand_[w] != chosen_) {
    ++switches_;
    nspread_ = spread_pos_ = 0;  // another count's samples
  }
  chosen_ = current_ = cand_[w];
  ref_ = med[w];
  // The winner's probe samples seed its recent samples (drift is judged against ref_).
  nrecent_ = std::min(nmeas_[w], cfg_.samples);
  std::copy(meas_[w], meas_[w] + nrecent_, recent_);
  recent_pos_ = nrecent_ % cfg_.samples;
  since_decision_ = 0;
  steps_since_decision_ = 0;
  ++decisions_;
  probing_ = false;
  batch_time_ = 0;
  batch_steps_ = 0;
}

}  // namespace loom

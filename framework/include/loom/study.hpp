// Work-precision studies: run combos over a ladder of steps against a verified reference,
// and measure error against cost (`loom study SCENE STUDY`).
#pragma once

#include <functional>
#include <string>
#include <vector>

#include "loom/registry.hpp"

namespace loom {

struct StudyOptions {
  std::string scene;       ///< scene file
  std::string study;       ///< study file
  std::string out_dir;     ///< where study.csv (and the plot) go
  bool plot = true;        ///< call scripts/plot_study.py when python3 + matplotlib exist
  bool stability = false;  ///< run the study file's `stability:` atlas instead of the work-precision part
  std::function<void(const std::string&, double)> progress;  ///< (what, fraction done)
};

/// One row of study.csv: a combo at one step size, measured at one time.
struct StudyRow {
  std::string combo;
  double h = 0;
  double time = 0;
  std::string status;          ///< ok, unstable (energy gain > M g L or strain > max_strain), diverged, solver_failed, timeout
  double rms_error = 0;        ///< RMS |x - x_ref| over free vertices / cloth size
  double max_error = 0;        ///< max |x - x_ref| / cloth size
  double observed_order = 0;   ///< log2(e(2h) / e(h)) against the previous rung (0 if none)
  double energy_drift = 0;     ///< (E(t) - E(0)) / (M g L)
  double sag = 0;              ///< lowest free vertex height drop below its start (m)
  double sag_error = 0;        ///< |sag - sag_ref|
  double wall_seconds = 0;     ///< time inside the integrator up to this time
  double wall_per_sim_second = 0;
  long long force_evaluations = 0;
  long long linear_iterations = 0;
  long long steps = 0;
  std::string note;            ///< the divergence message, etc.
};

/// One row of stability.csv: the largest stable step of a combo at one sweep value.
struct StabilityRow {
  std::string combo;
  std::string key;         ///< the swept scene key (e.g. material.stiffness)
  std::string value;       ///< its value (YAML text)
  double h_stable = 0;     ///< largest step found stable (0: none in [h_min, h_max])
  double h_unstable = 0;   ///< smallest step found unstable (0: all stable up to h_max)
  int runs = 0;
  std::string failure;     ///< how the smallest unstable step failed
};

/// Stability atlas: for each combo and each value of the swept key, bisect (in log h) for
/// the largest step that runs to the horizon without diverging (NaN/Inf, speed bound, strain
/// above max_strain, failed solve). Writes OUT/stability.csv.
std::vector<StabilityRow> run_stability(const StudyOptions& opt);

/// Run the study; writes OUT/study.csv, OUT/reference.txt and (if possible) OUT/study.png.
/// Throws InputError for bad study files.
std::vector<StudyRow> run_study(const StudyOptions& opt);

}  // namespace loom

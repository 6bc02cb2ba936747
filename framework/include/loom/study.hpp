// Work-precision studies: run combos over a ladder of steps against a verified reference,
// and measure error against cost (`loom study SCENE STUDY`).
#pragma once

#include <functional>
#include <memory>
#include <string>
#include <vector>

#include "loom/params.hpp"
#include "loom/registry.hpp"

namespace loom {

struct StudyOptions {
  std::string scene;       ///< scene file
  std::string study;       ///< study file
  std::string out_dir;     ///< where study.csv (and the plot) go
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
  /// ok: [h_stable, h_unstable] is the bisection's bracket; timeout: a run reached
  /// max_seconds_per_run before failing or reaching the horizon, so it decided nothing and the
  /// bisection stopped there (the bracket is what was decided before; `failure` names the step).
  std::string status = "ok";
};

// ---- A study in three parts: parse the study file, run it, report (CSV, reference.txt). ----
// Plotting is not part of the library: `loom study` runs scripts/plot_study.py (or
// plot_stability.py) on the CSV afterwards.

struct StudyCombo {
  std::string name;
  std::vector<std::string> sets;  ///< "dotted.key=value" overrides
  Params where;                   ///< its entry in the study file (for messages)
};

/// The work-precision part of a study file.
struct StudyPlan {
  std::string file;
  std::vector<double> times;              ///< simulated times (s) at which errors are measured
  double h0 = 1e-3;                       ///< largest step; h = h0 / 2^k, k < levels
  int levels = 4;
  std::vector<std::string> reference_sets = {"integrator.type=rk4"};
  double h_ref = 0;                       ///< reference step (checked against h_ref / 2)
  double max_seconds = 300;               ///< per run
  double max_strain = 1;                  ///< above it (or energy gain > M g L) a row is "unstable"
  std::vector<StudyCombo> combos;
  Params reference_where, combos_where;   ///< for messages
};
/// Parse and check a study file's work-precision part (InputError with file:line and fix).
StudyPlan parse_study(const std::string& study_file);

/// The reference's own accuracy: the RMS change (over free vertices, / cloth size) of the
/// reference solution when its step is halved, at each study time, and the largest of them.
/// Errors of combos far below it are not resolved by the reference.
struct ReferenceCheck {
  std::string integrator;            ///< the reference's first override (integrator.type=...)
  double h = 0;
  double size = 1;                   ///< cloth size used to make errors dimensionless (m)
  std::vector<double> times;         ///< the study's times (s)
  std::vector<double> rms_change, max_change;  ///< per time
  double largest_rms_change = 0;
};

struct StudyResult {
  std::vector<StudyRow> rows;
  ReferenceCheck reference;
};

/// Build every combo once (InputError naming the combo's entry when one does not build).
void check_study_combos(const StudyPlan& plan, const std::string& scene);

/// Run a parsed study on a scene: the reference at h_ref and h_ref / 2, then every combo on
/// the ladder of steps. `on_reference` is called once the reference is checked, `on_row` with
/// each row as soon as it is measured (the report appends it, so a long study killed half-way
/// keeps its rows).
StudyResult measure_study(const StudyPlan& plan, const std::string& scene,
                          const std::function<void(const std::string&, double)>& progress,
                          const std::function<void(const ReferenceCheck&)>& on_reference,
                          const std::function<void(const StudyRow&)>& on_row);

/// The study's report files, written as the study runs: OUT/reference.txt and OUT/study.csv.
class StudyReport {
 public:
  explicit StudyReport(const std::string& out_dir);
  ~StudyReport();
  void reference(const ReferenceCheck& ref);
  void row(const StudyRow& r);

 private:
  struct Impl;
  std::unique_ptr<Impl> impl_;
};

/// The stability part (`stability:` section) of a study file. The file's other sections (the
/// work-precision part) are declared keys too; any other key is a typo and an error.
struct StabilityPlan {
  std::string file;
  double horizon = 0.5, h_min = 1e-7, h_max = 0.05;
  int bisections = 10;
  double max_strain = 1.0, max_seconds = 60.0;
  std::vector<StudyCombo> combos;
  std::string key;                        ///< swept scene key ("" when none)
  std::vector<std::string> values{""};    ///< its values (YAML text)
};
StabilityPlan parse_stability(const std::string& study_file);

/// How one stability run ended.
enum class StepOutcome { Stable, Unstable, TimedOut };

/// Bisect every combo and sweep value; `on_row` gets each row when it is done.
std::vector<StabilityRow> measure_stability(const StabilityPlan& plan, const std::string& scene,
                                            const std::function<void(const std::string&, double)>& progress,
                                            const std::function<void(const StabilityRow&)>& on_row);

/// OUT/stability.csv, written row by row.
class StabilityReport {
 public:
  explicit StabilityReport(const std::string& out_dir);
  ~StabilityReport();
  void row(const StabilityRow& r);

 private:
  struct Impl;
  std::unique_ptr<Impl> impl_;
};

// ---- The three parts together, as `loom study` runs them. ----

/// Stability atlas: for each combo and each value of the swept key, bisect (in log h) for
/// the largest step that runs to the horizon without diverging (NaN/Inf, speed bound, strain
/// above max_strain, failed solve). A run that times out decides nothing (status timeout).
/// Writes OUT/stability.csv.
std::vector<StabilityRow> run_stability(const StudyOptions& opt);

/// Run the study; writes OUT/study.csv and OUT/reference.txt. Throws InputError for bad study
/// files.
StudyResult run_study(const StudyOptions& opt);

}  // namespace loom

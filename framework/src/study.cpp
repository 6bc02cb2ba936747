#include "loom/study.hpp"
#include "loom/section_specs.hpp"

#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <filesystem>
#include <fstream>
#include <memory>
#include <sstream>

#include "loom/output.hpp"
#include "loom/simulation.hpp"
#include "loom/text.hpp"
#include "loom/clock.hpp"

namespace fs = std::filesystem;

namespace loom {

namespace {

struct Snapshot {
  std::vector<double> x;
  double energy = 0;
  double sag = 0;
  double strain = 0;
};

struct RunResult {
  std::string status = "ok";
  std::string note;
  std::vector<Snapshot> snaps;      // one per time reached
  std::vector<double> wall;         // integrator seconds at each time
  std::vector<long long> force_evals, linear_iters, steps;
};

// A value as one line of YAML (lists and maps in flow form), for key=value overrides.
std::string yaml_scalar(const Params& p) {
  std::string d = p.dump(true);
  std::replace(d.begin(), d.end(), '\n', ' ');
  return d;
}

double total_energy(const Simulation& sim) {
  const Scene& sc = sim.scene();
  return kinetic_energy(sc.state) + gravitational_energy(sc.state, sc.gravity.data()) +
         sc.material->elastic_energy(sc.state.x);
}

// Largest displacement of a free vertex along gravity since the start (m).
double sag_of(const Simulation& sim, const std::vector<double>& x0) {
  const Scene& sc = sim.scene();
  const double g = std::sqrt(sc.gravity[0] * sc.gravity[0] + sc.gravity[1] * sc.gravity[1] + sc.gravity[2] * sc.gravity[2]);
  const double gh[3] = {g > 0 ? sc.gravity[0] / g : 0.0, g > 0 ? sc.gravity[1] / g : -1.0, g > 0 ? sc.gravity[2] / g : 0.0};
  double s = 0;
  for (Index i = 0; i < sc.state.size(); ++i) {
    if (sc.state.pinned[i]) continue;
    const double d = gh[0] * (sc.state.x[3 * i] - x0[3 * i]) + gh[1] * (sc.state.x[3 * i + 1] - x0[3 * i + 1]) +
                     gh[2] * (sc.state.x[3 * i + 2] - x0[3 * i + 2]);
    s = std::max(s, d);
  }
  return s;
}

class Runner {
 public:
  Runner(std::string scene, std::vector<double> times, double max_seconds)
      : scene_(std::move(scene)), times_(std::move(times)), max_seconds_(max_seconds), loader_(registry_) {}

  std::unique_ptr<Simulation> make(const std::vector<std::string>& sets) {
    return std::make_unique<Simulation>(scene_, sets, loader_);
  }

  RunResult run(const std::vector<std::string>& sets, double h, const Params& where) {
    RunResult r;
    std::vector<std::string> all = sets;
    all.push_back("integrator.dt=" + fmt_exact(h));
    std::unique_ptr<Simulation> sim = make(all);
    const std::vector<double> x0 = sim->scene().state.x;
    const auto t0 = Clock::now();
    long long done = 0;
    for (double t : times_) {
      const long long target = std::llround(t / h);
      if (std::abs(target * h - t) > 1e-9 * t)
        where.fail("time " + fmt(t) + " s is not a whole number of steps of h = " + fmt(h) +
                   " s. Fix: choose times that are multiples of every step (h0 / 2^k).");
      try {
        for (; done < target; ++done) {
          sim->step();
          if ((done & 63) == 0 && seconds_since(t0) > max_seconds_) {
            r.status = "timeout";
            r.note = "stopped after " + fmt(max_seconds_) + " s at t = " + fmt(sim->scene().state.time);
            return r;
          }
        }
      } catch (const DivergenceError& e) {
        r.status = "diverged";
        r.note = e.what();
        return r;
      } catch (const SolverError& e) {
        r.status = "solver_failed";
        r.note = e.what();
        return r;
      }
      sim->sync_state();  // x and v as the integrator has them (the CUDA backend keeps them on the device)
      Snapshot s;
      s.x = sim->scene().state.x;
      s.energy = total_energy(*sim);
      s.sag = sag_of(*sim, x0);
      s.strain = sim->scene().material->max_strain(s.x);
      r.snaps.push_back(std::move(s));
      r.wall.push_back(sim->step_seconds_total());
      r.force_evals.push_back(sim->force_evaluations());
      r.linear_iters.push_back(sim->linear_iterations());
      r.steps.push_back(done);
    }
    return r;
  }

  /// Energy at t = 0 and the scale M g L used to make drifts dimensionless.
  void measure_start(double& e_start, double& scale, double& size, std::vector<std::uint8_t>& pinned) {
    auto sim = make({});
    e_start = total_energy(*sim);
    const Scene& sc = sim->scene();
    double lo[3] = {1e300, 1e300, 1e300}, hi[3] = {-1e300, -1e300, -1e300};
    for (Index i = 0; i < sc.state.size(); ++i)
      for (int k = 0; k < 3; ++k) {
        lo[k] = std::min(lo[k], sc.state.x[3 * i + k]);
        hi[k] = std::max(hi[k], sc.state.x[3 * i + k]);
      }
    size = std::max({hi[0] - lo[0], hi[1] - lo[1], hi[2] - lo[2]});
    double m = 0;
    for (double mi : sc.state.mass) m += mi;
    const double g = std::sqrt(sc.gravity[0] * sc.gravity[0] + sc.gravity[1] * sc.gravity[1] + sc.gravity[2] * sc.gravity[2]);
    scale = m * std::max(g, 1e-12) * size;
    pinned = sc.state.pinned;
  }

  static std::string fmt_exact(double v) {
    char buf[40];
    std::snprintf(buf, sizeof(buf), "%.17g", v);
    return buf;
  }

 private:
  std::string scene_;
  std::vector<double> times_;
  double max_seconds_;
  Registry registry_;
  PluginLoader loader_;
};

void errors_against(const Snapshot& a, const Snapshot& ref, const std::vector<std::uint8_t>& pinned, double size,
                    double& rms, double& mx) {
  double s2 = 0;
  mx = 0;
  long long n = 0;
  for (std::size_t i = 0; i < pinned.size(); ++i) {
    if (pinned[i]) continue;
    const double dx = a.x[3 * i] - ref.x[3 * i], dy = a.x[3 * i + 1] - ref.x[3 * i + 1], dz = a.x[3 * i + 2] - ref.x[3 * i + 2];
    const double d2 = dx * dx + dy * dy + dz * dz;
    s2 += d2;
    mx = std::max(mx, std::sqrt(d2));
    ++n;
  }
  rms = n ? std::sqrt(s2 / n) / size : 0.0;
  mx /= size;
}

std::string csv_escape(const std::string& s) {
  std::string o = "\"";
  for (char c : s) {
    if (c == '"') o += "\"\"";
    else if (c == '\n') o += ' ';
    else o += c;
  }
  return o + "\"";
}


// A combo list entry: {name, set: {dotted.key: value, ...}}.
StudyCombo parse_combo(const Params& c) {
  if (!c.is_map()) c.fail("a combo is {name: ..., set: {dotted.key: value, ...}}.");
  StudyCombo combo;
  combo.where = c;
  combo.name = c.require_string("name");
  Params s = c.child("set");
  if (s.valid()) {
    if (!s.is_map()) s.fail("'set' is a mapping of dotted keys to values, e.g. {integrator.type: rk4}.");
    for (const auto& key : s.keys()) combo.sets.push_back(key + "=" + yaml_scalar(s.child(key)));
  }
  c.check_unused();
  return combo;
}

}  // namespace

// ---------------------------------------------------------------- parse

StudyPlan parse_study(const std::string& study_file) {
  StudyPlan plan;
  plan.file = study_file;
  const Params study = with_section_spec(Params::from_file(study_file), "study");  // its keys: section_specs.cpp
  if (!study.is_map()) study.fail("a study file is a mapping with times, steps, combos (and reference).");
  study.child("description");
  study.child("stability");  // read by loom study --stability
  // times
  Params tp = study.child("times");
  if (!tp.valid()) study.fail("missing 'times': the simulated times (s) at which errors are measured, e.g. [0.1, 0.25].");
  plan.times = tp.as_doubles();
  if (plan.times.empty()) tp.fail("give at least one time.");
  for (double t : plan.times)
    if (!(t > 0) || !std::isfinite(t)) tp.fail("times must be finite and > 0.");
  if (!std::is_sorted(plan.times.begin(), plan.times.end())) tp.fail("times must increase.");
  // steps
  Params sp = study.child("steps");
  if (!sp.is_map()) study.fail("missing 'steps': {h0: 2.0e-3, levels: 5} (h = h0 / 2^k, k = 0 .. levels-1).");
  plan.h0 = sp.get_positive("h0", 1e-3);
  plan.levels = sp.get("levels", 4);
  if (plan.levels < 1 || plan.levels > 20) sp.child("levels").fail("levels must be in [1, 20].");
  sp.check_unused();
  // reference
  Params rp = study.child("reference");
  plan.h_ref = plan.h0 / std::pow(2.0, plan.levels + 4);
  if (rp.valid()) {
    if (!rp.is_map()) rp.fail("reference is a mapping like {integrator: rk4, dt: 6.25e-6}.");
    plan.reference_sets = {"integrator.type=" + rp.get("integrator", std::string("rk4"))};
    plan.h_ref = rp.get_positive("dt", plan.h_ref);
    Params rs = rp.child("set");
    if (rs.valid()) {
      if (!rs.is_map()) rs.fail("'set' is a mapping of dotted keys to values.");
      for (const auto& k : rs.keys()) plan.reference_sets.push_back(k + "=" + yaml_scalar(rs.child(k)));
    }
    rp.check_unused();
  }
  plan.reference_where = rp.valid() ? rp : study;
  plan.max_seconds = study.get_positive("max_seconds_per_run", 300.0);
  plan.max_strain = study.get_positive("max_strain", 1.0);
  // combos
  Params cp = study.child("combos");
  if (!cp.is_sequence() || cp.size() == 0)
    study.fail("missing 'combos': a list of {name, set: {integrator.type: ..., ...}}.");
  for (std::size_t k = 0; k < cp.size(); ++k) plan.combos.push_back(parse_combo(with_section_spec(cp.at(k), "study_combos")));
  plan.combos_where = cp;
  study.check_unused();
  return plan;
}

StabilityPlan parse_stability(const std::string& study_file) {
  StabilityPlan plan;
  plan.file = study_file;
  const Params study = with_section_spec(Params::from_file(study_file), "study");
  if (!study.is_map()) study.fail("a study file is a mapping with a 'stability' section (and the work-precision part).");
  // The work-precision part's sections are declared keys of the file (parse_study checks
  // them); anything else at the top level is a typo.
  for (const char* k : {"description", "times", "steps", "reference", "combos", "max_seconds_per_run", "max_strain"})
    study.child(k);
  const Params st = with_section_spec(study.child("stability"), "stability");
  if (!st.is_map())
    study.fail("no 'stability' section. Fix: add stability: {combos: [...], sweep: {key: material.stiffness, "
               "values: [2e3, 2e5]}, horizon: 0.5, h_min: 1e-7, h_max: 0.05}.");
  study.check_unused();
  plan.horizon = st.get_positive("horizon", 0.5);
  plan.h_min = st.get_positive("h_min", 1e-7);
  plan.h_max = st.get_positive("h_max", 0.05);
  if (!(plan.h_min < plan.h_max)) st.fail("h_min must be smaller than h_max.");
  plan.bisections = st.get("bisections", 10);
  if (plan.bisections < 1 || plan.bisections > 40) st.child("bisections").fail("bisections must be in [1, 40].");
  plan.max_strain = st.get_positive("max_strain", 1.0);
  plan.max_seconds = st.get_positive("max_seconds_per_run", 60.0);
  Params cp = st.child("combos");
  if (!cp.is_sequence() || cp.size() == 0) st.fail("missing 'combos': a list of {name, set: {integrator.type: ...}}.");
  for (std::size_t k = 0; k < cp.size(); ++k) plan.combos.push_back(parse_combo(with_section_spec(cp.at(k), "study_combos")));
  Params sw = st.child("sweep");
  if (sw.valid()) {
    plan.key = sw.require_string("key");
    Params vs = sw.child("values");
    if (!vs.is_sequence() || vs.size() == 0) sw.fail("'values' is a non-empty list.");
    plan.values.clear();
    for (std::size_t k = 0; k < vs.size(); ++k) plan.values.push_back(yaml_scalar(vs.at(k)));
    sw.check_unused();
  }
  st.check_unused();
  return plan;
}

// ---------------------------------------------------------------- run

void check_study_combos(const StudyPlan& plan, const std::string& scene) {
  Simulation::set_notes(false);
  Runner runner(scene, plan.times, plan.max_seconds);
  for (const StudyCombo& c : plan.combos) {
    try {
      runner.make(c.sets);
    } catch (const InputError& e) {
      c.where.fail(std::string("combo '") + c.name + "' does not build: " + e.what());
    }
  }
}

StudyResult measure_study(const StudyPlan& plan, const std::string& scene,
                          const std::function<void(const std::string&, double)>& progress_fn,
                          const std::function<void(const ReferenceCheck&)>& on_reference,
                          const std::function<void(const StudyRow&)>& on_row) {
  Simulation::set_notes(false);
  const std::vector<double>& times = plan.times;
  Runner runner(scene, times, plan.max_seconds);
  const std::size_t total_runs = 2 + plan.combos.size() * static_cast<std::size_t>(plan.levels);
  std::size_t runs_done = 0;
  auto progress = [&](const std::string& what) {
    if (progress_fn) progress_fn(what, static_cast<double>(runs_done) / total_runs);
  };

  double e_start = 0, scale = 1, size = 1;
  std::vector<std::uint8_t> pinned;
  runner.measure_start(e_start, scale, size, pinned);

  // Reference, verified by halving its step.
  StudyResult result;
  ReferenceCheck& check = result.reference;
  check.integrator = plan.reference_sets[0];
  check.h = plan.h_ref;
  check.size = size;
  check.times = times;
  progress("reference h = " + fmt(plan.h_ref));
  RunResult ref = runner.run(plan.reference_sets, plan.h_ref, plan.reference_where);
  ++runs_done;
  if (ref.status != "ok")
    throw InputError(plan.file + ": the reference run did not finish (" + ref.status + "): " + ref.note +
                     " Fix: choose a smaller reference.dt.");
  progress("reference check h = " + fmt(plan.h_ref / 2));
  RunResult ref2 = runner.run(plan.reference_sets, plan.h_ref / 2, plan.reference_where);
  ++runs_done;
  if (ref2.status != "ok") throw InputError(plan.file + ": the halved reference run did not finish: " + ref2.note);
  for (std::size_t k = 0; k < times.size(); ++k) {
    double rms, mx;
    errors_against(ref.snaps[k], ref2.snaps[k], pinned, size, rms, mx);
    check.rms_change.push_back(rms);
    check.max_change.push_back(mx);
    check.largest_rms_change = std::max(check.largest_rms_change, rms);
  }
  if (on_reference) on_reference(check);

  for (const StudyCombo& combo : plan.combos) {
    std::vector<double> prev_err(times.size(), 0.0);
    for (int lvl = 0; lvl < plan.levels; ++lvl) {
      const double h = plan.h0 / std::pow(2.0, lvl);
      progress(combo.name + ", h = " + fmt(h));
      RunResult r = runner.run(combo.sets, h, plan.combos_where);
      ++runs_done;
      for (std::size_t k = 0; k < times.size(); ++k) {
        StudyRow row;
        row.combo = combo.name;
        row.h = h;
        row.time = times[k];
        if (k < r.snaps.size()) {
          row.status = "ok";
          // Bounded but blown up: more energy than the cloth could get by falling its own size,
          // or strain beyond the study's bound. Marked, not dropped.
          const double drift = (r.snaps[k].energy - e_start) / scale;
          if (drift > 1.0 || r.snaps[k].strain > plan.max_strain) {
            row.status = "unstable";
            row.note = "energy drift " + fmt(drift) + " (M g L), max strain " + fmt(r.snaps[k].strain);
          }
          errors_against(r.snaps[k], ref.snaps[k], pinned, size, row.rms_error, row.max_error);
          if (prev_err[k] > 0 && row.rms_error > 0) row.observed_order = std::log2(prev_err[k] / row.rms_error);
          prev_err[k] = row.rms_error;
          row.energy_drift = (r.snaps[k].energy - e_start) / scale;
          row.sag = r.snaps[k].sag;
          row.sag_error = std::abs(r.snaps[k].sag - ref.snaps[k].sag);
          row.wall_seconds = r.wall[k];
          row.wall_per_sim_second = r.wall[k] / times[k];
          row.force_evaluations = r.force_evals[k];
          row.linear_iterations = r.linear_iters[k];
          row.steps = r.steps[k];
        } else {
          row.status = r.status;
          row.note = r.note;
          prev_err[k] = 0;
        }
        if (on_row) on_row(row);
        result.rows.push_back(row);
      }
    }
  }
  progress("done");
  return result;
}

namespace {

// One run of the stability atlas: stable to the horizon, unstable, or out of time (which
// decides nothing).
StepOutcome try_step(const StabilityPlan& plan, const std::string& scene, PluginLoader& loader,
                     const std::vector<std::string>& sets, double h, std::string& why) {
  std::vector<std::string> all = sets;
  all.push_back("integrator.dt=" + Runner::fmt_exact(h));
  Simulation sim(scene, all, loader);
  const long long n = static_cast<long long>(std::ceil(plan.horizon / h));
  const auto t0 = Clock::now();
  try {
    for (long long k = 0; k < n; ++k) {
      sim.step();
      if ((k & 255) == 255 || k == n - 1) {
        sim.sync_state();
        const double s = sim.scene().material->max_strain(sim.scene().state.x);
        if (!(s <= plan.max_strain)) {
          why = "strain " + fmt(s) + " > " + fmt(plan.max_strain) + " at t = " + fmt(sim.scene().state.time);
          return StepOutcome::Unstable;
        }
        if (k < n - 1 && seconds_since(t0) > plan.max_seconds) {
          why = "timeout at h = " + fmt(h) + " (t = " + fmt(sim.scene().state.time) + " s of " + fmt(plan.horizon) +
                " s after max_seconds_per_run = " + fmt(plan.max_seconds) + " s)";
          return StepOutcome::TimedOut;
        }
      }
    }
  } catch (const DivergenceError&) {
    why = "diverged";
    return StepOutcome::Unstable;
  } catch (const SolverError&) {
    why = "solver failed";
    return StepOutcome::Unstable;
  }
  return StepOutcome::Stable;
}

}  // namespace

std::vector<StabilityRow> measure_stability(const StabilityPlan& plan, const std::string& scene,
                                            const std::function<void(const std::string&, double)>& progress,
                                            const std::function<void(const StabilityRow&)>& on_row) {
  Simulation::set_notes(false);
  Registry registry;
  PluginLoader loader(registry);
  std::vector<StabilityRow> rows;
  const std::size_t total = plan.combos.size() * plan.values.size();
  std::size_t done = 0;
  for (const StudyCombo& combo : plan.combos) {
    for (const std::string& value : plan.values) {
      if (progress) progress(combo.name + (plan.key.empty() ? "" : ", " + plan.key + " = " + value), double(done) / total);
      std::vector<std::string> sets = combo.sets;
      if (!plan.key.empty()) sets.push_back(plan.key + "=" + value);
      StabilityRow row;
      row.combo = combo.name;
      row.key = plan.key;
      row.value = value;
      std::string why;
      // A timed-out run ends the search: the row keeps what was decided before it.
      auto timed_out = [&](StepOutcome o) {
        if (o != StepOutcome::TimedOut) return false;
        row.status = "timeout";
        row.failure = why;
        return true;
      };
      double lo = plan.h_min, hi = plan.h_max;
      ++row.runs;
      const StepOutcome at_max = try_step(plan, scene, loader, sets, plan.h_max, why);
      if (at_max == StepOutcome::Stable) {
        row.h_stable = plan.h_max;
      } else if (!timed_out(at_max)) {
        row.failure = why;
        row.h_unstable = plan.h_max;
        ++row.runs;
        const StepOutcome at_min = try_step(plan, scene, loader, sets, plan.h_min, why);
        if (at_min == StepOutcome::Unstable) {
          row.h_unstable = plan.h_min;
          row.failure = why;
        } else if (!timed_out(at_min)) {
          row.h_stable = lo;
          for (int b = 0; b < plan.bisections; ++b) {
            const double mid = std::sqrt(lo * hi);
            ++row.runs;
            const StepOutcome o = try_step(plan, scene, loader, sets, mid, why);
            if (timed_out(o)) break;
            if (o == StepOutcome::Stable) {
              lo = mid;
            } else {
              hi = mid;
              row.failure = why;
            }
            row.h_stable = lo;
            row.h_unstable = hi;
          }
          row.h_stable = lo;
          row.h_unstable = hi;
        }
      }
      if (on_row) on_row(row);
      rows.push_back(row);
      ++done;
    }
  }
  if (progress) progress("done", 1.0);
  return rows;
}

// ---------------------------------------------------------------- report

struct StudyReport::Impl {
  std::string dir;
  std::ofstream csv;
};

StudyReport::StudyReport(const std::string& out_dir) : impl_(std::make_unique<Impl>()) {
  impl_->dir = out_dir;
  impl_->csv.open(fs::path(out_dir) / "study.csv");
  impl_->csv << "combo,h,time,status,rms_error,max_error,observed_order,energy_drift,sag,sag_error,wall_seconds,"
                "wall_per_sim_second,force_evaluations,linear_iterations,steps,note\n";
  impl_->csv.precision(8);
}
StudyReport::~StudyReport() = default;

void StudyReport::reference(const ReferenceCheck& ref) {
  std::ofstream rf(fs::path(impl_->dir) / "reference.txt");
  rf << "reference: " << ref.integrator << " h = " << ref.h << " s, checked against h/2\n";
  for (std::size_t k = 0; k < ref.rms_change.size(); ++k)
    rf << "t = " << ref.times[k] << " s: RMS change on halving = " << ref.rms_change[k] << " (max " << ref.max_change[k]
       << ") x cloth size " << ref.size << " m\n";
  rf << "largest RMS change on halving = " << ref.largest_rms_change
     << " x cloth size: combo errors below about this are not resolved by the reference\n";
}

void StudyReport::row(const StudyRow& row) {
  auto& csv = impl_->csv;
  csv << csv_escape(row.combo) << ',' << row.h << ',' << row.time << ',' << row.status << ',' << row.rms_error << ','
      << row.max_error << ',' << row.observed_order << ',' << row.energy_drift << ',' << row.sag << ','
      << row.sag_error << ',' << row.wall_seconds << ',' << row.wall_per_sim_second << ',' << row.force_evaluations
      << ',' << row.linear_iterations << ',' << row.steps << ',' << csv_escape(row.note) << '\n';
  csv.flush();
}

struct StabilityReport::Impl {
  std::ofstream csv;
};

StabilityReport::StabilityReport(const std::string& out_dir) : impl_(std::make_unique<Impl>()) {
  impl_->csv.open(fs::path(out_dir) / "stability.csv");
  impl_->csv << "combo,key,value,h_stable,h_unstable,runs,failure,status\n";
  impl_->csv.precision(6);
}
StabilityReport::~StabilityReport() = default;

void StabilityReport::row(const StabilityRow& row) {
  impl_->csv << csv_escape(row.combo) << ',' << row.key << ',' << csv_escape(row.value) << ',' << row.h_stable << ','
             << row.h_unstable << ',' << row.runs << ',' << csv_escape(row.failure) << ',' << row.status << '\n';
  impl_->csv.flush();
}

// ---------------------------------------------------------------- parse, run, report

StudyResult run_study(const StudyOptions& opt) {
  const StudyPlan plan = parse_study(opt.study);
  check_study_combos(plan, opt.scene);  // before spending time on the reference
  prepare_output_dir(opt.out_dir);
  StudyReport report(opt.out_dir);
  return measure_study(
      plan, opt.scene, opt.progress, [&](const ReferenceCheck& ref) { report.reference(ref); },
      [&](const StudyRow& row) { report.row(row); });
}

std::vector<StabilityRow> run_stability(const StudyOptions& opt) {
  const StabilityPlan plan = parse_stability(opt.study);
  prepare_output_dir(opt.out_dir);
  StabilityReport report(opt.out_dir);
  return measure_stability(plan, opt.scene, opt.progress, [&](const StabilityRow& row) { report.row(row); });
}

}  // namespace loom

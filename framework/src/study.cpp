#include "loom/study.hpp"
#include "loom/spawn.hpp"

#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <filesystem>
#include <fstream>
#include <memory>
#include <sstream>
#include <unistd.h>

#include "loom/output.hpp"
#include "loom/simulation.hpp"

namespace fs = std::filesystem;

namespace loom {

namespace {

struct Combo {
  std::string name;
  std::vector<std::string> sets;  // "key=value"
};

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

std::string fmt(double v) {
  std::ostringstream os;
  os.precision(6);
  os << v;
  return os.str();
}

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
    const auto t0 = std::chrono::steady_clock::now();
    long long done = 0;
    for (double t : times_) {
      const long long target = std::llround(t / h);
      if (std::abs(target * h - t) > 1e-9 * t)
        where.fail("time " + fmt(t) + " s is not a whole number of steps of h = " + fmt(h) +
                   " s. Fix: choose times that are multiples of every step (h0 / 2^k).");
      try {
        for (; done < target; ++done) {
          sim->step();
          if ((done & 63) == 0 &&
              std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count() > max_seconds_) {
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

std::string find_plot_script() {
  std::vector<std::string> candidates = {std::string(LOOM_SOURCE_SCRIPTS_DIR) + "/plot_study.py"};
  char buf[4096];
  const ssize_t n = ::readlink("/proc/self/exe", buf, sizeof(buf) - 1);
  if (n > 0) {
    buf[n] = 0;
    candidates.push_back((fs::path(buf).parent_path().parent_path() / "share/loom/scripts/plot_study.py").string());
  }
  for (const auto& c : candidates)
    if (fs::exists(c)) return c;
  return {};
}

}  // namespace

std::vector<StudyRow> run_study(const StudyOptions& opt) {
  Simulation::set_notes(false);
  Params study = Params::from_file(opt.study);
  if (!study.is_map()) study.fail("a study file is a mapping with times, steps, combos (and reference).");
  study.child("description");
  study.child("stability");  // read by loom study --stability
  // times
  Params tp = study.child("times");
  if (!tp.valid()) study.fail("missing 'times': the simulated times (s) at which errors are measured, e.g. [0.1, 0.25].");
  std::vector<double> times = tp.as_doubles();
  if (times.empty()) tp.fail("give at least one time.");
  for (double t : times)
    if (!(t > 0) || !std::isfinite(t)) tp.fail("times must be finite and > 0.");
  if (!std::is_sorted(times.begin(), times.end())) tp.fail("times must increase.");
  // steps
  Params sp = study.child("steps");
  if (!sp.is_map()) study.fail("missing 'steps': {h0: 2.0e-3, levels: 5} (h = h0 / 2^k, k = 0 .. levels-1).");
  const double h0 = sp.get_positive("h0", 1e-3);
  const int levels = sp.get("levels", 4);
  if (levels < 1 || levels > 20) sp.child("levels").fail("levels must be in [1, 20].");
  sp.check_unused();
  // reference
  Params rp = study.child("reference");
  std::vector<std::string> ref_sets = {"integrator.type=rk4"};
  double h_ref = h0 / std::pow(2.0, levels + 4);
  if (rp.valid()) {
    if (!rp.is_map()) rp.fail("reference is a mapping like {integrator: rk4, dt: 6.25e-6}.");
    ref_sets = {"integrator.type=" + rp.get("integrator", std::string("rk4"))};
    h_ref = rp.get_positive("dt", h_ref);
    Params rs = rp.child("set");
    if (rs.valid()) {
      if (!rs.is_map()) rs.fail("'set' is a mapping of dotted keys to values.");
      for (const auto& k : rs.keys()) ref_sets.push_back(k + "=" + yaml_scalar(rs.child(k)));
    }
    rp.check_unused();
  }
  const double max_seconds = study.get_positive("max_seconds_per_run", 300.0);
  const double max_strain = study.get_positive("max_strain", 1.0);
  // combos
  Params cp = study.child("combos");
  if (!cp.is_sequence() || cp.size() == 0)
    study.fail("missing 'combos': a list of {name, set: {integrator.type: ..., ...}}.");
  std::vector<Combo> combos;
  for (std::size_t k = 0; k < cp.size(); ++k) {
    Params c = cp.at(k);
    if (!c.is_map()) c.fail("a combo is {name: ..., set: {dotted.key: value, ...}}.");
    Combo combo;
    combo.name = c.require_string("name");
    Params s = c.child("set");
    if (s.valid()) {
      if (!s.is_map()) s.fail("'set' is a mapping of dotted keys to values, e.g. {integrator.type: rk4}.");
      for (const auto& key : s.keys()) combo.sets.push_back(key + "=" + yaml_scalar(s.child(key)));
    }
    c.check_unused();
    combos.push_back(combo);
  }
  study.check_unused();

  // Check every combo builds before spending time on the reference.
  Runner runner(opt.scene, times, max_seconds);
  for (std::size_t k = 0; k < combos.size(); ++k) {
    try {
      runner.make(combos[k].sets);
    } catch (const InputError& e) {
      cp.at(k).fail(std::string("combo '") + combos[k].name + "' does not build: " + e.what());
    }
  }

  prepare_output_dir(opt.out_dir);
  const std::size_t total_runs = 2 + combos.size() * static_cast<std::size_t>(levels);
  std::size_t runs_done = 0;
  auto progress = [&](const std::string& what) {
    if (opt.progress) opt.progress(what, static_cast<double>(runs_done) / total_runs);
  };

  double e_start = 0, scale = 1, size = 1;
  std::vector<std::uint8_t> pinned;
  runner.measure_start(e_start, scale, size, pinned);

  // Reference, verified by halving its step.
  progress("reference h = " + fmt(h_ref));
  RunResult ref = runner.run(ref_sets, h_ref, rp.valid() ? rp : study);
  ++runs_done;
  if (ref.status != "ok") throw InputError(opt.study + ": the reference run did not finish (" + ref.status + "): " + ref.note +
                                           " Fix: choose a smaller reference.dt.");
  progress("reference check h = " + fmt(h_ref / 2));
  RunResult ref2 = runner.run(ref_sets, h_ref / 2, rp.valid() ? rp : study);
  ++runs_done;
  if (ref2.status != "ok") throw InputError(opt.study + ": the halved reference run did not finish: " + ref2.note);
  double ref_change = 0;
  {
    std::ofstream rf(fs::path(opt.out_dir) / "reference.txt");
    rf << "reference: " << ref_sets[0] << " h = " << h_ref << " s, checked against h/2\n";
    for (std::size_t k = 0; k < times.size(); ++k) {
      double rms, mx;
      errors_against(ref.snaps[k], ref2.snaps[k], pinned, size, rms, mx);
      ref_change = std::max(ref_change, rms);
      rf << "t = " << times[k] << " s: RMS change on halving = " << rms << " (max " << mx << ") x cloth size " << size
         << " m\n";
    }
  }

  std::vector<StudyRow> rows;
  std::ofstream csv(fs::path(opt.out_dir) / "study.csv");
  csv << "combo,h,time,status,rms_error,max_error,observed_order,energy_drift,sag,sag_error,wall_seconds,"
         "wall_per_sim_second,force_evaluations,linear_iterations,steps,note\n";
  csv.precision(8);
  for (const Combo& combo : combos) {
    std::vector<double> prev_err(times.size(), 0.0);
    for (int lvl = 0; lvl < levels; ++lvl) {
      const double h = h0 / std::pow(2.0, lvl);
      progress(combo.name + ", h = " + fmt(h));
      RunResult r = runner.run(combo.sets, h, cp);
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
          if (drift > 1.0 || r.snaps[k].strain > max_strain) {
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
        csv << csv_escape(row.combo) << ',' << row.h << ',' << row.time << ',' << row.status << ',' << row.rms_error << ','
            << row.max_error << ',' << row.observed_order << ',' << row.energy_drift << ',' << row.sag << ','
            << row.sag_error << ',' << row.wall_seconds << ',' << row.wall_per_sim_second << ',' << row.force_evaluations
            << ',' << row.linear_iterations << ',' << row.steps << ',' << csv_escape(row.note) << '\n';
        csv.flush();
        rows.push_back(row);
      }
    }
  }
  progress("done");
  csv.close();
  if (opt.plot) {
    const std::string script = find_plot_script();
    if (!script.empty()) {
      const SpawnResult r = run_program({"python3", script, (fs::path(opt.out_dir) / "study.csv").string(),
                                         (fs::path(opt.out_dir) / "study.png").string()});
      if (!r.ok())
        std::fprintf(stderr, "loom: note: no plot (%s; python3 with matplotlib is needed: apt-get install python3-matplotlib)\n",
                     r.error.c_str());
    }
  }
  (void)ref_change;
  return rows;
}

std::vector<StabilityRow> run_stability(const StudyOptions& opt) {
  Simulation::set_notes(false);
  Params study = Params::from_file(opt.study);
  for (const auto& k : study.keys()) study.mark_used(k);
  Params st = study.child("stability");
  if (!st.is_map())
    study.fail("no 'stability' section. Fix: add stability: {combos: [...], sweep: {key: material.stiffness, "
               "values: [2e3, 2e5]}, horizon: 0.5, h_min: 1e-7, h_max: 0.05}.");
  const double horizon = st.get_positive("horizon", 0.5);
  const double h_min = st.get_positive("h_min", 1e-7);
  const double h_max = st.get_positive("h_max", 0.05);
  if (!(h_min < h_max)) st.fail("h_min must be smaller than h_max.");
  const int bisections = st.get("bisections", 10);
  if (bisections < 1 || bisections > 40) st.child("bisections").fail("bisections must be in [1, 40].");
  const double max_strain = st.get_positive("max_strain", 1.0);
  const double max_seconds = st.get_positive("max_seconds_per_run", 60.0);
  std::vector<Combo> combos;
  Params cp = st.child("combos");
  if (!cp.is_sequence() || cp.size() == 0) st.fail("missing 'combos': a list of {name, set: {integrator.type: ...}}.");
  for (std::size_t k = 0; k < cp.size(); ++k) {
    Params c = cp.at(k);
    Combo combo;
    combo.name = c.require_string("name");
    Params s = c.child("set");
    if (s.valid())
      for (const auto& key : s.keys()) combo.sets.push_back(key + "=" + yaml_scalar(s.child(key)));
    c.check_unused();
    combos.push_back(combo);
  }
  std::string key;
  std::vector<std::string> values{""};
  Params sw = st.child("sweep");
  if (sw.valid()) {
    key = sw.require_string("key");
    Params vs = sw.child("values");
    if (!vs.is_sequence() || vs.size() == 0) sw.fail("'values' is a non-empty list.");
    values.clear();
    for (std::size_t k = 0; k < vs.size(); ++k) values.push_back(yaml_scalar(vs.at(k)));
    sw.check_unused();
  }
  st.check_unused();

  Registry registry;
  PluginLoader loader(registry);
  prepare_output_dir(opt.out_dir);
  std::ofstream csv(fs::path(opt.out_dir) / "stability.csv");
  csv << "combo,key,value,h_stable,h_unstable,runs,failure\n";
  csv.precision(6);
  std::vector<StabilityRow> rows;
  const std::size_t total = combos.size() * values.size();
  std::size_t done = 0;

  // true = stable to the horizon
  auto try_step = [&](const std::vector<std::string>& sets, double h, std::string& why) {
    std::vector<std::string> all = sets;
    all.push_back("integrator.dt=" + Runner::fmt_exact(h));
    Simulation sim(opt.scene, all, loader);
    const long long n = static_cast<long long>(std::ceil(horizon / h));
    const auto t0 = std::chrono::steady_clock::now();
    try {
      for (long long k = 0; k < n; ++k) {
        sim.step();
        if ((k & 255) == 255 || k == n - 1) {
          const double s = sim.scene().material->max_strain(sim.scene().state.x);
          if (!(s <= max_strain)) {
            why = "strain " + fmt(s) + " > " + fmt(max_strain) + " at t = " + fmt(sim.scene().state.time);
            return false;
          }
          if (std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count() > max_seconds) {
            why = "timeout";
            return true;  // did not fail within the time budget: count as stable, noted
          }
        }
      }
    } catch (const DivergenceError&) {
      why = "diverged";
      return false;
    } catch (const SolverError&) {
      why = "solver failed";
      return false;
    }
    return true;
  };

  for (const Combo& combo : combos) {
    for (const std::string& value : values) {
      if (opt.progress) opt.progress(combo.name + (key.empty() ? "" : ", " + key + " = " + value), double(done) / total);
      std::vector<std::string> sets = combo.sets;
      if (!key.empty()) sets.push_back(key + "=" + value);
      StabilityRow row;
      row.combo = combo.name;
      row.key = key;
      row.value = value;
      std::string why;
      double lo = h_min, hi = h_max;
      ++row.runs;
      if (try_step(sets, h_max, why)) {
        row.h_stable = h_max;
      } else {
        row.failure = why;
        ++row.runs;
        if (!try_step(sets, h_min, why)) {
          row.h_unstable = h_min;
          row.failure = why;
        } else {
          for (int b = 0; b < bisections; ++b) {
            const double mid = std::sqrt(lo * hi);
            ++row.runs;
            if (try_step(sets, mid, why)) lo = mid;
            else {
              hi = mid;
              row.failure = why;
            }
          }
          row.h_stable = lo;
          row.h_unstable = hi;
        }
      }
      csv << csv_escape(row.combo) << ',' << row.key << ',' << csv_escape(row.value) << ',' << row.h_stable << ','
          << row.h_unstable << ',' << row.runs << ',' << csv_escape(row.failure) << '\n';
      csv.flush();
      rows.push_back(row);
      ++done;
    }
  }
  if (opt.progress) opt.progress("done", 1.0);
  return rows;
}

}  // namespace loom

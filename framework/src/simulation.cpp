#include "loom/clock.hpp"
#include "loom/simulation.hpp"
#include "scene_build.hpp"
#include "loom/memory_estimate.hpp"
#include "loom/bending.hpp"
#include "loom/fabric_library.hpp"

#include <omp.h>

#include <algorithm>
#include <chrono>
#include <csignal>
#include <cerrno>
#include <cmath>
#include <cstdlib>
#include <cstring>
#include <cstdio>
#include <filesystem>
#include <fstream>
#include <iostream>
#include <limits>
#include <sstream>

#include "loom/output.hpp"
#include "loom/pins.hpp"
#include "loom/restart.hpp"
#include "loom/run_output.hpp"
#include "loom/section_specs.hpp"
#include "loom/vtk_output.hpp"
#include "loom/threads.hpp"
#include "loom/thread_controller.hpp"
#include "loom/thread_start.hpp"
#include "loom/text.hpp"

namespace fs = std::filesystem;

namespace loom {

std::string resolve_path(const std::string& base_dir, const std::string& path) {
  if (path.empty() || fs::path(path).is_absolute() || base_dir.empty()) return path;
  return (fs::path(base_dir) / path).lexically_normal().string();
}

namespace {
bool g_notes = true;

// `threads: auto` (default) or a count; the policy lives in loom/threads.hpp. Returns whether
// the count is auto's own choice (then loom/thread_controller.hpp adapts it during the run).
bool configure_threads(const Params& t, Scene& sc) {
  int requested = 0;
  if (t.valid()) {
    if (t.is_scalar() && t.as_string() == "auto") {
      requested = 0;
    } else {
      const std::int64_t k = t.as_int();
      if (k < 0 || k > kMaxThreads)
        t.fail("must be 'auto' or a count in [0, " + std::to_string(kMaxThreads) + "] (0 = auto); got " +
               std::to_string(k) + ". Fix: threads: auto uses the cores this process may run on.");
      requested = static_cast<int>(k);
    }
  }
  bool capped = false;
  sc.threads = resolve_thread_count(requested, &capped);
  if (capped && g_notes && is_output_rank())
    std::cerr << "loom: note: threads: " << requested << " capped at " << sc.threads
              << ", the cores this process may use (more threads than cores only wait at barriers).\n";
  omp_set_num_threads(sc.threads);
  const char* env = std::getenv("OMP_NUM_THREADS");
  return requested == 0 && !(env && std::atoi(env) > 0) && sc.backend == "cpu";
}
}
void Simulation::set_notes(bool on) { g_notes = on; }

Simulation::Simulation() = default;
Simulation::~Simulation() = default;

Simulation::Simulation(const std::string& path, const std::vector<std::string>& overrides, PluginLoader& loader) {
  std::error_code ec;
  if (!fs::exists(path, ec) && !ec) throw InputError(path + ": scene file not found. Fix: check the path (scenes/ has examples).");
  Params root = Params::from_file(path);
  scene_build::apply_overrides(root, overrides);
  build(root, fs::path(path).parent_path().string(), loader);
}

std::unique_ptr<Simulation> Simulation::from_string(const std::string& yaml, const std::string& source_name,
                                                    const std::string& base_dir,
                                                    const std::vector<std::string>& overrides, PluginLoader& loader) {
  std::unique_ptr<Simulation> sim(new Simulation());
  Params root = Params::from_string(yaml, source_name);
  scene_build::apply_overrides(root, overrides);
  sim->build(root, base_dir, loader);
  return sim;
}

// The estimate of the run's peak memory against the machine's (loom/memory_estimate.hpp),
// from the vertex count and the combo the scene names; the sections themselves are parsed later.
void Simulation::check_memory(const Params& root, long long vertices) {
  memory_line_ = scene_build::memory_line(root, vertices);
}

void Simulation::build(const Params& scene, const std::string& base_dir, PluginLoader& loader) {
  // Every key the stages read is declared (loom/section_specs.hpp): an undeclared read throws.
  const Params root = with_section_spec(scene, "scene");
  if (!root.is_map()) root.fail("a scene file must be a YAML mapping with mesh, material, integrator, ... sections.");
  scene_ = std::make_unique<Scene>();
  Scene& sc = *scene_;
  sc.source = root.source();
  root.child("description");  // free text, allowed
  root.child("name");
  root.child("render");       // read by `loom render`, not by a run
  root.child("kawabata");     // read by scripts/kawabata.py (virtual KES-F tests), not by a run
  resolved_yaml_ = root.dump();
  base_dir_ = base_dir.empty() ? std::string(".") : base_dir;

  sc.backend = ParamReader(root, scene_section_spec()).text("backend");
  std::unique_ptr<AutoThreadStart> auto_threads;  // measures the load while the scene is set up
  if (configure_threads(root.child("threads"), sc) && usable_cores() > 1)
    auto_threads = std::make_unique<AutoThreadStart>();

  // The stages (scene_build.cpp), in the order their results are needed.
  sc.mesh = scene_build::mesh(root, base_dir, [&](long long vertices) { check_memory(root, vertices); });
  material_name_ = scene_build::material(root, sc, loader);
  scene_build::state(root, sc, material_name_);
  scene_build::selections(root, sc);
  scene_build::colliders(root, sc, base_dir);
  auto integ = scene_build::integrator(root, sc, loader, material_name_);
  integrator_name_ = integ.name;
  dt_ = integ.dt;
  substeps_ = integ.substeps;
  integrator_ = std::move(integ.integrator);
  solver_name_ = scene_build::solver(root, sc, loader, integrator_->needs(), integrator_name_, g_notes);
  scene_build::output_and_guards(root, frames_, output_, guard_);
  root.check_unused();

  integrator_->prepare(sc, dt_);
  prepared_ = true;
  if (sc.self_collision) {  // the state as built has passed the crossing check (SelfCollision::parse)
    checked_x_ = sc.state.x;
    state_check_pending_ = true;
  }
  if (auto_threads) {  // the count the steps start on (loom/thread_start.hpp)
    // A mesh below kParallelMinVertices starts on 1 thread, unless an iterative solver's row
    // loops (most of an implicit step) run in parallel at its size (loom/threads.hpp).
    long long serial_below = kParallelMinVertices;
    if (sc.solver && sc.solver->parallel_min_rows() > 0)
      serial_below = std::min<long long>(serial_below, sc.solver->parallel_min_rows());
    thread_ctl_ = auto_threads->finish(usable_cores(), static_cast<long long>(sc.state.x.size() / 3), serial_below);
    sc.threads = auto_threads->start().threads;
    omp_set_num_threads(sc.threads);
  }
}

std::vector<std::string> Simulation::describe() const {
  const Scene& sc = *scene_;
  std::vector<std::string> lines;
  lines.push_back("scene:      " + sc.source);
  lines.push_back("mesh:       " + sc.mesh.source + " (" + std::to_string(sc.mesh.num_vertices()) + " vertices, " +
                  std::to_string(sc.mesh.num_triangles()) + " triangles)");
  std::string m = "material:   " + material_name_;
  for (const auto& [k, v] : sc.material->describe()) m += ", " + k + " " + v;
  lines.push_back(m);
  lines.push_back("integrator: " + integrator_name_ + ", dt " + fmt(dt_) + " s, " + std::to_string(substeps_) +
                  " steps per frame (frame time " + fmt(dt_ * static_cast<double>(substeps_)) + " s)");
  if (!solver_name_.empty()) lines.push_back("solver:     " + solver_name_);
  lines.push_back("backend:    " + sc.backend + ", threads " + std::to_string(sc.threads) + " (of " +
                  std::to_string(usable_cores()) + " usable cores)");
  double mass = 0;
  for (double mi : sc.state.mass) mass += mi;
  std::string pl = "pins:       " + std::to_string(sc.state.pin_list.size()) + " vertices";
  for (const PinGroup& g : sc.pins.groups())
    pl += (&g == &sc.pins.groups().front() ? " (" : ", ") + g.name + ": " + std::to_string(g.vertices.size()) +
          (g.moving() ? " moving" : " fixed") + (&g == &sc.pins.groups().back() ? ")" : "");
  lines.push_back(pl + "; total mass " + fmt(mass) + " kg");
  if (!sc.colliders.empty()) {
    std::string c = "colliders:  ";
    for (std::size_t k = 0; k < sc.colliders.size(); ++k) c += (k ? ", " : "") + sc.colliders.colliders()[k].name;
    lines.push_back(c);
  }
  if (sc.self_collision)
    lines.push_back("self-collision: thickness " + fmt(sc.self_collision->options().thickness) + " m, friction " +
                    fmt(sc.self_collision->options().friction));
  lines.push_back("gravity:    [" + fmt(sc.gravity[0]) + ", " + fmt(sc.gravity[1]) + ", " + fmt(sc.gravity[2]) + "]");
  lines.push_back("frames:     " + std::to_string(frames_) + " (" + fmt(static_cast<double>(frames_) * substeps_ * dt_) + " s simulated)");
  if (!memory_line_.empty()) lines.push_back(memory_line_);
  lines.push_back("output:     " + (output_.dir.empty() ? std::string("none") : output_.dir));
  return lines;
}

void Simulation::check_state(bool check_strain) {
  const double vmax2 = guard_.max_velocity * guard_.max_velocity;
  // An integrator with its own copy of the state (the CUDA backend) checks it where it is; the
  // host copy is brought up to date only to report a divergence or to measure the strain.
  const Index checked = integrator_->first_unguarded_vertex(vmax2);  // -2: not checked there
  if (checked == -1 && !check_strain) return;
  integrator_->sync_to_host(*scene_);
  const State& st = scene_->state;
  const Index n = st.size();
  Index bad = checked >= 0 ? checked : std::numeric_limits<Index>::max();
  const double* x = st.x.data();
  const double* v = st.v.data();
  // NaN fails every comparison: !(v2 <= vmax2) catches NaN and Inf too.
  auto bad_at = [&](Index i) {
    const double a = x[3 * i] + x[3 * i + 1] + x[3 * i + 2];
    const double v2 = v[3 * i] * v[3 * i] + v[3 * i + 1] * v[3 * i + 1] + v[3 * i + 2] * v[3 * i + 2];
    return !(v2 <= vmax2) || !std::isfinite(a);
  };
  // (checked >= -1: the integrator's copy was checked by the same rule; no second pass here.)
  if (checked == -2 && (n < kParallelMinVertices || omp_get_max_threads() == 1)) {
    // No region for a small cloth: a region of one thread still ends with a futex wake (a
    // system call), about as much as the check itself.
    for (Index i = 0; i < n && bad == std::numeric_limits<Index>::max(); ++i)
      if (bad_at(i)) bad = i;
  } else if (checked == -2) {
#pragma omp parallel for reduction(min : bad) schedule(static)
    for (Index i = 0; i < n; ++i)
      if (bad_at(i)) bad = std::min(bad, i);
  }
  // Built only when needed (not on every step).
  auto when = [&] { return "step " + std::to_string(st.step) + " (t = " + fmt(st.time) + " s)"; };
  const char* fix = " Fix: reduce integrator.dt (or raise substeps), add damping, or choose a more stable "
                    "integrator (baraff_witkin); raise guard.max_velocity only if such speeds are real.";
  if (bad != std::numeric_limits<Index>::max()) {
    const double* xi = &x[3 * bad];
    const double* vi = &v[3 * bad];
    const double speed = std::sqrt(vi[0] * vi[0] + vi[1] * vi[1] + vi[2] * vi[2]);
    std::string what;
    if (!std::isfinite(xi[0]) || !std::isfinite(xi[1]) || !std::isfinite(xi[2]))
      what = "position (" + fmt(xi[0]) + ", " + fmt(xi[1]) + ", " + fmt(xi[2]) + ") is not finite";
    else if (!std::isfinite(speed))
      what = "velocity (" + fmt(vi[0]) + ", " + fmt(vi[1]) + ", " + fmt(vi[2]) + ") is not finite";
    else
      what = "speed " + fmt(speed) + " m/s exceeds guard.max_velocity = " + fmt(guard_.max_velocity) + " m/s";
    throw DivergenceError("diverged at " + when() + ": vertex " + std::to_string(bad) + ": " + what + "." + fix);
  }
  if (check_strain) {
    const double s = scene_->material->max_strain(st.x);
    if (!(s <= guard_.max_strain))
      throw DivergenceError("diverged at " + when() + ": the largest strain is " + fmt(s) + ", beyond guard.max_strain = " +
                            fmt(guard_.max_strain) + "." + fix);
  }
}

namespace {
volatile std::sig_atomic_t g_stop_requested = 0;
}
void Simulation::request_stop() { g_stop_requested = 1; }

void Simulation::accept_state() {
  state_check_pending_ = false;
  std::vector<double>().swap(checked_x_);
}

void Simulation::check_program_state() {
  state_check_pending_ = false;
  const bool changed = scene_->state.x != checked_x_;
  std::vector<double>().swap(checked_x_);
  if (changed && scene_->self_collision)
    SelfCollision::refuse_crossing_state(scene_->mesh, scene_->state.x, "", true);
}

void Simulation::step() {
  if (g_stop_requested)
    throw Interrupted("interrupted at step " + std::to_string(scene_->state.step) + " (t = " + fmt(scene_->state.time) + " s)");
  if (state_check_pending_) check_program_state();
  const auto t0 = Clock::now();
  if (scene_->self_collision) scene_->self_collision->begin_step(scene_->state);
  integrator_->step(*scene_, dt_);
  if (!scene_->colliders.empty() && !integrator_->handles_contacts())
    scene_->colliders.resolve_contacts(scene_->state, scene_->state.time, dt_);
  if (scene_->self_collision)  // after colliders: last word, keeping the colliders' too
    scene_->self_collision->resolve(scene_->state, dt_, &scene_->colliders);
  const double secs = seconds_since(t0);
  step_seconds_ += secs;
  step_seconds_total_ += secs;
  ++steps_in_frame_;
  if (thread_ctl_) {
    const int before = thread_ctl_->threads();
    thread_ctl_->record(secs);
    if (thread_ctl_->threads() != before) omp_set_num_threads(thread_ctl_->threads());
  }
  const StepStats s = integrator_->last_step();
  force_evals_ += s.force_evaluations;
  linear_iters_ += s.linear_iterations;
  retries_ += s.retries;
  self_contacts_in_frame_ += s.self_contacts;
  self_contacts_total_ += s.self_contacts;
  if (scene_->state.step % guard_.check_every == 0) check_state(false);
  if (on_step_) on_step_();
}

void Simulation::advance_frame() {
  for (int k = 0; k < substeps_; ++k) step();
  check_state(true);
}

Simulation::FrameStats Simulation::measure(int frame) const {
  const Scene& sc = *scene_;
  FrameStats fs;
  fs.frame = frame;
  fs.time = sc.state.time;
  fs.kinetic = kinetic_energy(sc.state);
  fs.gravitational = gravitational_energy(sc.state, sc.gravity.data());
  fs.elastic = sc.material->elastic_energy(sc.state.x);
  fs.max_strain = sc.material->max_strain(sc.state.x);
  fs.wall_ms_per_step = steps_in_frame_ > 0 ? 1e3 * step_seconds_ / steps_in_frame_ : 0.0;
  fs.force_evaluations = force_evals_;
  fs.linear_iterations = linear_iters_;
  if (sc.self_collision) {
    const SelfCollisionTotals& now = sc.self_collision->totals();
    const SelfCollisionTotals& then = self_collision_at_frame_;
    fs.self_collision_ms_per_step = steps_in_frame_ > 0 ? 1e3 * (now.seconds() - then.seconds()) / steps_in_frame_ : 0.0;
    fs.self_collision_impulses = now.impulses() - then.impulses();
    fs.self_collision_frozen = now.frozen - then.frozen;
    fs.self_collision_rebuilds = now.rebuilds - then.rebuilds;
    fs.self_collision_contacts = steps_in_frame_ > 0 ? static_cast<double>(self_contacts_in_frame_) / steps_in_frame_ : 0.0;
  }
  return fs;
}

// A run never mixes its files with another run's: the files of an earlier run of the same
// scene (same resolved scene.yaml) are cleared first; another scene's are refused unless
// output.overwrite (loom run --overwrite) says to replace them.
void Simulation::claim_output_dir(const std::string& scene_text) const {
  const auto files = run_files_in(output_.dir);
  if (files.empty()) return;
  std::ifstream in(fs::path(output_.dir) / "scene.yaml", std::ios::binary);
  const std::string previous((std::istreambuf_iterator<char>(in)), {});
  if (!output_.overwrite && previous != scene_text)
    throw InputError("output folder '" + output_.dir + "' holds the files of another run (" +
                     std::to_string(files.size()) + " files, e.g. " + fs::path(files.front()).filename().string() +
                     (previous.empty() ? ", without its scene.yaml" : ", of a different scene or --set") +
                     "). Fix: loom run ... --overwrite replaces them, or choose another folder with --out DIR.");
  // stats.csv first: a run killed while clearing never leaves more stats rows than frames.
  auto rank = [](const std::string& f) {
    const std::string name = fs::path(f).filename().string();
    return name == "restart.bin" ? -1 : name == "stats.csv" ? 0 : name == "run.pc2" ? 1 : name == "scene.yaml" ? 2 : 3;
  };
  std::vector<std::string> order = files;
  std::stable_sort(order.begin(), order.end(), [&](const std::string& a, const std::string& b) { return rank(a) < rank(b); });
  for (const auto& f : order) {
    std::error_code ec;
    fs::remove(f, ec);
    if (ec) throw InputError("cannot remove " + f + " from the earlier run: " + ec.message() + ".");
  }
}

namespace {
// stats.csv's columns of a scene with self_collision, after the pin columns (docs/OUTPUT.md).
constexpr const char* kSelfCollisionColumns =
    ",self_collision_ms_per_step,self_collision_impulses,self_collision_frozen,self_collision_contacts";
// Then the lists' rebuilds (added 2026-12-02: a run begun before resumes without the column).
constexpr const char* kSelfCollisionRebuildColumn = ",self_collision_rebuilds";
}  // namespace

void Simulation::run(const std::function<void(int, int)>& progress) {
  // The initial state passes the same guards as every step before anything is written.
  try {
    check_state(true);
  } catch (const DivergenceError& e) {
    throw InputError(std::string("the initial state (initial_velocity, initial_scale, pins) is out of bounds, nothing was written: ") + e.what());
  }
  const bool write = !output_.dir.empty() && is_output_rank();
  const bool resuming = resume_frame_ >= 0;
  const int first_frame = start_frame();
  std::ofstream stats;
  std::streamoff stats_complete = 0;  // bytes of stats.csv that hold complete rows
  bool stats_self_columns = scene_->self_collision != nullptr;  // the self_collision columns of stats.csv
  bool stats_rebuild_column = stats_self_columns;                // and the rebuilds' column after them
  std::unique_ptr<OutputLock> lock;
  std::error_code ec;
  const std::string abs_base = fs::absolute(base_dir_, ec).lexically_normal().string();
  const std::string scene_text = "# The scene as it ran (overrides applied), written by loom run.\n"
                                 "# Relative paths resolve against the original scene's folder:\n"
                                 "# loom-scene-dir: " + abs_base + "\n" + scene_file_line() + resolved_yaml_ + "\n";
  std::vector<double> reaction_work, reactions;
  if (write) {
    prepare_output_dir(output_.dir);
    lock = std::make_unique<OutputLock>(output_.dir);
    remove_stale_temporaries(output_.dir);
    if (resuming) {
      // Under the lock: the restart point must still be the one resume() read.
      if (read_restart(output_.dir).frame != resume_frame_)
        throw InputError("output folder '" + output_.dir + "' changed while resuming. Fix: run --resume again.");
      trim_run_for_resume(output_.dir, resume_frame_, output_.stats);
    } else {
      claim_output_dir(scene_text);
    }
    // Record exactly what ran (with --set overrides applied).
    if (output_.stats && resuming) {
      const std::string path = (fs::path(output_.dir) / "stats.csv").string();
      stats_complete = static_cast<std::streamoff>(fs::file_size(path));  // trimmed to complete rows
      // The rows continue the header's columns (a run begun by a Loom before the
      // self_collision columns goes on without them).
      std::ifstream head(path);
      std::string header;
      std::getline(head, header);
      stats_self_columns = stats_self_columns && header.find(kSelfCollisionColumns) != std::string::npos;
      stats_rebuild_column = stats_self_columns && header.find(kSelfCollisionRebuildColumn) != std::string::npos;
      stats.open(path, std::ios::app);
      if (!stats) throw InputError("cannot write " + path + ". Fix: check the folder's permissions.");
      stats.precision(10);
    } else if (output_.stats) {
      stats.open((fs::path(output_.dir) / "stats.csv").string(), std::ios::trunc);
      if (!stats) throw InputError("cannot write " + output_.dir + "/stats.csv. Fix: choose a writable --out folder.");
      stats << "frame,time,kinetic_energy,gravitational_energy,elastic_energy,total_energy,max_strain,"
               "wall_ms_per_step,force_evaluations,linear_iterations"
            << scene_->pins.csv_header() << (stats_self_columns ? kSelfCollisionColumns : "")
            << (stats_rebuild_column ? kSelfCollisionRebuildColumn : "") << '\n';
      stats.precision(10);
      stats.flush();
      if (!stats) throw OutputError("cannot write " + output_.dir + "/stats.csv (" + std::strerror(errno) + "; disk full?)");
      stats_complete = stats.tellp();
    }
  }
  const ObjOptions obj_options{output_.uvs, output_.normals, output_.lossless};
  std::optional<PointCacheWriter> pc2, vel_pc2;
  const std::string pc2_path = (fs::path(output_.dir) / "run.pc2").string();
  const std::string vel_pc2_path = (fs::path(output_.dir) / "velocity.pc2").string();
  const int points = static_cast<int>(scene_->mesh.num_vertices());
  if (write && output_.pc2 && resuming) {
    const int keep = first_frame / output_.every + 1;  // the samples of frames 0, every, ... <= first_frame
    pc2.emplace(pc2_path, points, keep);
    if (output_.velocities) vel_pc2.emplace(vel_pc2_path, points, keep);
  } else if (write && output_.pc2) {
    // The rest pose (topology, UVs, normals) that the point cache animates.
    write_file_atomic((fs::path(output_.dir) / "rest.obj").string(),
                      obj_text(scene_->mesh, scene_->state.x, "rest pose for run.pc2", {true, true, output_.lossless}));
    // PC2's sample rate is the frame step between samples.
    pc2.emplace(pc2_path, points, 0.0f, static_cast<float>(output_.every));
    if (output_.velocities) vel_pc2.emplace(vel_pc2_path, points, 0.0f, static_cast<float>(output_.every));
  }
  std::optional<VtkSeriesWriter> vtk;
  std::vector<double> gap_work;  // per-vertex collider gap for the ParaView frames
  if (write && output_.vtk) {
    vtk.emplace(output_.dir, scene_->mesh, output_.uvs);
    if (resuming) vtk->adopt_existing(first_frame);
  }
  RestartData pending;                 // the last complete frame's restart point
  bool pending_unwritten = false;      // ... not yet in restart.bin
  auto last_restart_write = Clock::now();
  auto write_pending = [&] {
    write_restart(output_.dir, pending);
    pending_unwritten = false;
    last_restart_write = Clock::now();
  };
  auto emit = [&](int frame) {
    if (!write) return;
    integrator_->sync_to_host(*scene_);  // (check_state(true) has done it after a frame; a no-op then)
    const FrameStats f = measure(frame);
    // No output ever carries a non-finite number: energies that overflow (positions near the
    // double range, absurd masses) stop the run as diverged before this frame is written.
    for (double q : {f.kinetic, f.gravitational, f.elastic, f.kinetic + f.gravitational + f.elastic, f.max_strain})
      if (!std::isfinite(q))
        throw DivergenceError("diverged at frame " + std::to_string(frame) + " (t = " + fmt(f.time) +
                              " s): the energies are not finite (kinetic " + fmt(f.kinetic) + ", gravitational " +
                              fmt(f.gravitational) + ", elastic " + fmt(f.elastic) + ", strain " + fmt(f.max_strain) +
                              "). Fix: check masses, scales and collider offsets for values near the double range.");
    // Frame files first, then the stats row: a killed run never has a row for a frame it did
    // not write.
    if (frame % output_.every == 0) {
      if (output_.obj) {
        char name[32];
        std::snprintf(name, sizeof(name), "frame_%05d.obj", frame);
        write_file_atomic((fs::path(output_.dir) / name).string(),
                          obj_text(scene_->mesh, scene_->state.x, "t = " + fmt(scene_->state.time) + " s", obj_options));
      }
      if (vtk) {
        // Per vertex, the signed distance to the nearest collider's offset surface (contact field).
        const auto& cs = scene_->colliders.colliders();
        if (!cs.empty()) {
          const std::size_t n = scene_->state.x.size() / 3;
          gap_work.assign(n, std::numeric_limits<double>::infinity());
          for (const Collider& c : cs) {
            const Collider::Frame fr = c.frame_at(scene_->state.time);
            for (std::size_t i = 0; i < n; ++i)
              gap_work[i] = std::min(gap_work[i], c.query(fr, &scene_->state.x[3 * i]).distance);
          }
        }
        vtk->write_frame(frame, scene_->state.time, scene_->state.x,
                         output_.velocities ? std::span<const double>(scene_->state.v) : std::span<const double>(),
                         gap_work);
      }
      if (pc2) pc2->append(scene_->state.x);
      if (vel_pc2) vel_pc2->append(scene_->state.v);
    }
    if (output_.stats) {
      stats << f.frame << ',' << f.time << ',' << f.kinetic << ',' << f.gravitational << ',' << f.elastic << ','
            << (f.kinetic + f.gravitational + f.elastic) << ',' << f.max_strain << ',' << f.wall_ms_per_step << ','
            << f.force_evaluations << ',' << f.linear_iterations;
      if (!scene_->pins.empty()) {  // reaction force of each pin group on the cloth (N)
        scene_->pins.reactions(scene_->state, *scene_->material, scene_->gravity, reaction_work, reactions);
        for (double r : reactions) stats << ',' << r;
      }
      if (stats_self_columns)
        stats << ',' << f.self_collision_ms_per_step << ',' << f.self_collision_impulses << ',' << f.self_collision_frozen
              << ',' << f.self_collision_contacts;
      if (stats_rebuild_column) stats << ',' << f.self_collision_rebuilds;
      stats << '\n';
      stats.flush();
      if (!stats) {
        // Cut the partial row off (truncation frees space, so it works on a full disk too):
        // stats.csv keeps only complete rows, one per frame written.
        const std::string path = (fs::path(output_.dir) / "stats.csv").string();
        const std::string why = std::strerror(errno);
        stats.close();
        std::error_code trunc_ec;
        if (stats_complete > 0) fs::resize_file(path, static_cast<std::uintmax_t>(stats_complete), trunc_ec);
        throw OutputError("cannot write " + path + " (" + why + "; disk full?); the frames written so far are kept" +
                                 (trunc_ec ? std::string(", but the last row may be incomplete") : std::string()) + ".");
      }
      stats_complete = stats.tellp();
    }
    // Last: the restart point of this frame, once everything before it is on disk. It is kept
    // in memory and written when restart_interval has passed since the last write (creating and
    // renaming a file per frame cost a short run up to half its time), after frame 0 and the
    // last frame, and when the run stops early (below).
    if (output_.restart) {
      pending.frame = frame;
      pending.frames = frames_;
      pending.step = scene_->state.step;
      pending.time = scene_->state.time;
      pending.force_evaluations = force_evals_;
      pending.linear_iterations = linear_iters_;
      pending.x = scene_->state.x;
      pending.v = scene_->state.v;
      pending.integrator_state = integrator_->restart_state();
      pending_unwritten = true;
      if (frame == first_frame || frame == frames_ || seconds_since(last_restart_write) >= output_.restart_interval)
        write_pending();
    }
  };
  if (write && !resuming) write_file_atomic((fs::path(output_.dir) / "scene.yaml").string(), scene_text);
  if (!resuming) emit(0);
  // `threads: auto` probes only while the steps left can repay a probe (loom/thread_controller.hpp)
  if (thread_ctl_) thread_ctl_->set_run_steps(thread_ctl_->steps() + static_cast<long>(frames_ - first_frame) * substeps_);
  try {
    for (int f = first_frame + 1; f <= frames_; ++f) {
      step_seconds_ = 0;
      steps_in_frame_ = 0;
      if (scene_->self_collision) self_collision_at_frame_ = scene_->self_collision->totals();
      self_contacts_in_frame_ = 0;
      advance_frame();
      emit(f);
      if (progress) progress(f, frames_);
    }
  } catch (const OutputError&) {
    throw;  // the disk refused a write: do not try another
  } catch (...) {
    // Stopped early (Ctrl-C, divergence, a failed solve, ...): the last complete frame's
    // restart point goes to disk, so that --resume continues from it.
    if (pending_unwritten) {
      try {
        write_pending();
      } catch (const std::exception&) {
        // The disk refused it: the older restart point stays, and the run's own error is the
        // one to report.
      }
    }
    throw;
  }
}

// "# loom-scene-file: PATH\n" (the scene file a run was made from, absolute) for scene.yaml:
// loom run --resume builds from the copy with that name, so that plugins resolving paths
// against their scene file (gnatv's material_file) find the same files.
std::string Simulation::scene_file_line() const {
  const std::string& src = scene_->source;
  if (src.empty() || src.front() == '<') return {};
  std::error_code ec;
  return "# loom-scene-file: " + fs::absolute(src, ec).lexically_normal().string() + "\n";
}

int Simulation::resume(int frames) {
  if (output_.dir.empty()) throw InputError("--resume needs the run's output folder.");
  const RestartData r = read_restart(output_.dir);
  frames_ = frames >= 0 ? frames : r.frames;
  State& st = scene_->state;
  const std::string where = output_.dir + "/restart.bin";
  if (r.x.size() != st.x.size())
    throw InputError(where + ": holds " + std::to_string(r.x.size() / 3) + " vertices, the scene has " +
                     std::to_string(st.x.size() / 3) + ". Fix: resume with the scene that made the run (its scene.yaml).");
  if (r.frame > frames_)
    throw InputError(where + ": the run is already at frame " + std::to_string(r.frame) + " of " + std::to_string(frames_) +
                     ". Fix: give --frames N with N > " + std::to_string(r.frame) + " to continue it further.");
  if (r.frame == frames_ && frames < 0)
    throw InputError(where + ": the run is complete (frame " + std::to_string(r.frame) + " of " + std::to_string(frames_) +
                     "): nothing to resume. Fix: give --frames N with N > " + std::to_string(r.frame) + " to continue it.");
  for (std::size_t i = 0; i < r.x.size(); ++i)
    if (!std::isfinite(r.x[i]) || !std::isfinite(r.v[i])) throw InputError(where + ": holds non-finite values. Fix: rerun with --overwrite.");
  if (scene_->self_collision) SelfCollision::refuse_crossing_state(scene_->mesh, r.x, where);  // as a start mesh
  st.x = r.x;
  if (state_check_pending_) checked_x_ = r.x;  // checked just above
  st.v = r.v;
  st.time = r.time;
  st.step = r.step;
  force_evals_ = r.force_evaluations;
  linear_iters_ = r.linear_iterations;
  // The integrator took the built state in prepare(); one that keeps x and v to itself between
  // steps (the CUDA backend) would go on from it. prepare() again takes the restart point's
  // state, then set_restart_state its carried state.
  state_changed();
  if (!integrator_->set_restart_state(r.integrator_state))
    throw InputError(where + ": its integrator state (" + std::to_string(r.integrator_state.size()) +
                     " numbers) does not fit integrator '" + integrator_name_ +
                     "'. Fix: resume with the scene that made the run, or rerun it with --overwrite.");
  resume_frame_ = r.frame;
  return r.frame;
}

}  // namespace loom

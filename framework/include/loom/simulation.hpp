// Simulation: parse and validate a scene file, build its combo from plugins, and run it.
#pragma once

#include <functional>
#include <optional>
#include <memory>
#include <stdexcept>
#include <string>
#include <vector>

#include "loom/integrator.hpp"
#include "loom/registry.hpp"
#include "loom/scene.hpp"

namespace loom {

class ThreadController;  // loom/thread_controller.hpp

/// Divergence guards, checked after every `check_every` steps.
struct GuardOptions {
  double max_velocity = 1e3;   ///< m/s; beyond this the run stops as diverged
  double max_strain = 10.0;    ///< relative; checked once per frame
  int check_every = 1;         ///< steps between NaN/velocity checks
};

struct OutputOptions {
  std::string dir;             ///< empty: no files
  bool obj = true;             ///< one OBJ per frame
  bool stats = true;           ///< stats.csv
  int every = 1;               ///< write every n-th frame
  bool overwrite = false;      ///< replace another run's files in dir (loom run --overwrite)
  bool pc2 = false;            ///< run.pc2 point cache (every written frame) beside rest.obj
  bool uvs = false;            ///< OBJ frames carry vt (when the mesh has UVs)
  bool normals = false;        ///< OBJ frames carry vn
  bool lossless = false;       ///< OBJ coordinates in full double precision
  bool vtk = false;            ///< ParaView: frame_NNNNN.vtu per written frame and run.pvd (loom/vtk_output.hpp)
  bool velocities = false;     ///< per-vertex velocities: a "velocity" array in the .vtu frames, velocity.pc2
  bool restart = true;         ///< restart.bin, for loom run --resume (loom/restart.hpp)
  /// Seconds of wall time between restart.bin writes: after a frame, it is written when this much
  /// has passed since the last write, and always after frame 0 and the run's last frame, and
  /// when a run stops early (Ctrl-C, divergence, a failed solve; the last complete frame is kept
  /// in memory). 0: after every frame. A killed run (kill -9, power loss) resumes from up to
  /// this much wall time back.
  double restart_interval = 1.0;
};

/// Thrown by Simulation::step when request_stop() was called (Ctrl-C): the frames written so
/// far are complete and kept.
class Interrupted : public std::runtime_error {
 public:
  using std::runtime_error::runtime_error;
};

/// A parsed, validated scene with its combo built. Construction throws InputError.
class Simulation {
 public:
  /// Parse `path` (YAML), apply `overrides` ("a.b.c=value"), load the plugins the scene
  /// names through `loader`, build mesh, state, material, integrator and solver.
  Simulation(const std::string& path, const std::vector<std::string>& overrides, PluginLoader& loader);
  /// Same from YAML text (source_name is used in messages; relative paths resolve against base_dir).
  static std::unique_ptr<Simulation> from_string(const std::string& yaml, const std::string& source_name,
                                                 const std::string& base_dir,
                                                 const std::vector<std::string>& overrides, PluginLoader& loader);
  ~Simulation();
  /// Print notes (ignored solver section, solver fallback) to stderr while building (default on).
  static void set_notes(bool on);

  /// The scene. Its state's x and v are those of the last sync_state() (or of a guard check,
  /// stats or output, which sync): call sync_state() after step() before reading them.
  Scene& scene() { return *scene_; }
  const Scene& scene() const { return *scene_; }
  /// Bring scene().state.x and .v up to date with the integrator's own copy (the CUDA backend
  /// keeps them on the device; on the CPU backend this does nothing).
  void sync_state() { integrator_->sync_to_host(*scene_); }
  /// Hand scene().state.x and .v to the integrator after the program changed them (call
  /// sync_state() before changing them): an integrator that keeps its own copy (the CUDA backend)
  /// takes them again (Integrator::prepare); on the CPU backends' default it changes nothing.
  void state_changed() { integrator_->prepare(*scene_, dt_); }
  Integrator& integrator() { return *integrator_; }
  double dt() const { return dt_; }
  int substeps() const { return substeps_; }
  int frames() const { return frames_; }
  void set_frames(int n) { frames_ = n; }
  const OutputOptions& output() const { return output_; }
  OutputOptions& output() { return output_; }
  const GuardOptions& guard() const { return guard_; }
  std::string integrator_name() const { return integrator_name_; }
  std::string material_name() const { return material_name_; }
  std::string solver_name() const { return solver_name_; }
  /// The scene as it ran (with --set overrides applied), as YAML text.
  const std::string& resolved_yaml() const { return resolved_yaml_; }
  /// Folder of the scene file (relative paths in the scene resolve against it).
  const std::string& base_dir() const { return base_dir_; }

  /// Totals since construction (for studies).
  long long force_evaluations() const { return force_evals_; }
  long long linear_iterations() const { return linear_iters_; }
  /// Step halvings after failed solves (StepStats::retries; baraff_witkin's on_solver_failure:
  /// halve_step) since construction or resume: not kept in the restart file.
  long long step_retries() const { return retries_; }
  /// Seconds spent inside Integrator::step since construction.
  double step_seconds_total() const { return step_seconds_total_; }
  /// StepStats::self_contacts summed over the steps since construction or resume.
  long long self_contacts_total() const { return self_contacts_total_; }

  /// Lines describing what was built (counts, plugins, backend), for `loom validate`.
  std::vector<std::string> describe() const;

  /// Ask a running simulation to stop at the next step boundary (async-signal-safe: call it
  /// from a SIGINT handler). step() then throws Interrupted.
  static void request_stop();
  /// Called after every step (progress reporting); keep it cheap.
  void set_step_callback(std::function<void()> cb) { on_step_ = std::move(cb); }

  /// One step of size dt with guards. Throws DivergenceError naming step, vertex and value.
  /// With self_collision, the first step checks a state that the program set itself (scene().state
  /// changed since the scene was built or resumed) for crossings, as the scene's own start and a
  /// resumed state are checked: a cloth that intersects itself throws InputError (self-collision
  /// keeps each pair on the side it starts on, so it cannot undo a crossing; docs/CONTACT.md).
  void step();
  /// Take scene().state as it is now for self-collision, without the first step's crossing
  /// check: for a program that starts from a crossing state on purpose (the benchmark of a
  /// tangled start), knowing that the crossing stays.
  void accept_state();
  /// One frame = substeps steps.
  void advance_frame();

  struct FrameStats {
    int frame = 0;
    double time = 0, kinetic = 0, gravitational = 0, elastic = 0, max_strain = 0;
    double wall_ms_per_step = 0;
    long long force_evaluations = 0;
    long long linear_iterations = 0;
    /// With self_collision, over the steps since the last frame: wall ms per step in
    /// self-collision (the after-step pass and an integrator's self-contact search), impulses
    /// (proximity and CCD), and vertices the fail-safe returned to their start of step.
    double self_collision_ms_per_step = 0;
    long long self_collision_impulses = 0;
    long long self_collision_frozen = 0;
    double self_collision_contacts = 0;  ///< per step: StepStats::self_contacts (baraff_witkin's)
    long long self_collision_rebuilds = 0;  ///< full rebuilds of the candidate lists (SelfCollisionTotals::rebuilds)
  };
  /// Energies and strain of the current state.
  FrameStats measure(int frame) const;

  /// Run all frames, writing outputs (OBJ frames atomically, stats.csv) to output().dir.
  /// `progress` is called after each frame with (frame, frames). Throws on divergence,
  /// after the frames written so far are on disk.
  void run(const std::function<void(int, int)>& progress = {});

  /// Continue the stopped run in output().dir (loom run --resume) from the last complete frame
  /// of its restart.bin: positions, velocities, time, step, counters and the integrator's
  /// carried state are restored, and run() then writes the frames after it. Returns that frame.
  /// frames >= 0: the run's new last frame (else the frames the run was started with).
  /// Throws InputError when the restart point does not fit this scene.
  int resume(int frames = -1);
  /// The frame the run starts from (0, or the frame resume() restored).
  int start_frame() const { return resume_frame_ < 0 ? 0 : resume_frame_; }

 private:
  Simulation();
  void build(const Params& root, const std::string& base_dir, PluginLoader& loader);
  void check_state(bool check_strain);
  void claim_output_dir(const std::string& scene_text) const;
  std::string scene_file_line() const;

  std::unique_ptr<Scene> scene_;
  std::unique_ptr<Integrator> integrator_;
  std::string integrator_name_, material_name_, solver_name_;
  std::string memory_line_;  ///< the memory estimate against the machine's, for describe()
  void check_memory(const Params& root, long long vertices);
  std::string resolved_yaml_, base_dir_;
  double dt_ = 1e-3;
  int substeps_ = 1;
  int frames_ = 1;
  bool prepared_ = false;
  int resume_frame_ = -1;
  /// With self_collision: the positions already checked for crossings (as built, or resumed),
  /// until the first step compares scene().state with them (then released).
  std::vector<double> checked_x_;
  bool state_check_pending_ = false;
  void check_program_state();
  OutputOptions output_;
  GuardOptions guard_;
  long long force_evals_ = 0, linear_iters_ = 0, retries_ = 0;
  double step_seconds_ = 0;
  double step_seconds_total_ = 0;
  long long steps_in_frame_ = 0;
  SelfCollisionTotals self_collision_at_frame_;  ///< self_collision->totals() when the frame began
  long long self_contacts_in_frame_ = 0;         ///< StepStats::self_contacts summed over the frame's steps
  long long self_contacts_total_ = 0;            ///< ... over every step since construction or resume
  std::function<void()> on_step_;
  std::unique_ptr<ThreadController> thread_ctl_;  ///< `threads: auto`'s step-time controller (null: fixed count)

 public:
  /// The step-time controller of `threads: auto` (null with a fixed count, OMP_NUM_THREADS or one core).
  const ThreadController* thread_controller() const { return thread_ctl_.get(); }
};

/// Resolve a path relative to the scene file's folder (absolute paths unchanged).
std::string resolve_path(const std::string& base_dir, const std::string& path);

}  // namespace loom

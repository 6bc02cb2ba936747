// The `loom` command line: run, validate, plugins.
#include <unistd.h>

#include <algorithm>
#include <csignal>
#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <iostream>
#include <memory>
#include <string>
#include <vector>

#include "loom/clock.hpp"
#include "loom/common.hpp"
#include "loom/output.hpp"
#include "loom/registry.hpp"
#include "loom/simulation.hpp"
#include "loom/stability.hpp"
#include "loom/study.hpp"
#include "loom/threads.hpp"
#include "loom/thread_controller.hpp"
#include "check_cmd.hpp"
#include "plot_cmd.hpp"
#include "render_cmd.hpp"
#include "resume_cmd.hpp"

namespace {

const char* kUsage = R"(loom: cloth simulation from a scene file

usage:
  loom run SCENE.yaml [--out DIR] [--frames N] [--set key=value]... [--quiet] [--render] [--overwrite]
      Simulate and write one OBJ per frame (frame_00000.obj, ...) and stats.csv to DIR
      (default: the scene's output.dir, else out/<scene name>). --render: then draw the
      frames as `loom render DIR` does. A folder holding another scene's run is refused
      unless --overwrite (a rerun of the same scene replaces its files). Ctrl-C stops at
      the next step; the frames written so far are kept.
  loom run --resume RUN_DIR [--frames N] [--quiet]
      Continue a stopped run (Ctrl-C, kill, a crash) from its last complete frame
      (RUN_DIR/restart.bin) as if it had never stopped; --frames N extends it to N frames.
  loom validate SCENE.yaml [--set key=value]...
      Check the scene and its combo without running; print what would be built.
  loom render RUN_DIR [--scene SCENE.yaml] [--out DIR] [--set render.key=value]...
      Draw the frames of a run to PNG images (DIR, default RUN_DIR/render) with the
      renderer plugin the scene's render section names (default: gl).
  loom view RUN_DIR [--scene SCENE.yaml] [--set render.key=value]...
      Play the frames of a run in a window (needs a display and a build with GLFW):
      drag rotates, scroll zooms, space plays/pauses, left/right step, Esc or q quits.
  loom study SCENE.yaml STUDY.yaml [--out DIR] [--stability]
      Work-precision study: run the study's combos over a ladder of steps against a
      verified RK4 reference; write DIR/study.csv (error, cost, status per combo, step and
      time), DIR/reference.txt and DIR/study.png (default DIR: out/study_<study name>).
      --stability: instead, the study's stability atlas: the largest stable step of each
      combo by bisection, over a swept key (stiffness, mass, ...): DIR/stability.csv.
  loom plot RUN_DIR [--out FILE.png]
      Plot RUN_DIR/stats.csv (energies, largest strain, solver iterations, time per step
      against simulated time) to FILE (default RUN_DIR/stats.png); needs python3-matplotlib.
  loom check RUN_DIR [--allow] [--list] [--distance] [--quiet]
      Count the intersecting non-adjacent triangle pairs of every frame of a run (exact
      test; touching counts). Exit 5 when any frame has some, unless --allow; --list
      prints the pairs (triangle indices, from 0). --distance: also each frame's closest
      approach of non-adjacent elements (vertex-triangle, edge-edge), in m and as a
      fraction of the run's self_collision thickness.
  loom plugins [--params NAME [--markdown]]
      List the plugins on the plugin path (kind, name, backend, version, description).
      --params NAME: the keys plugin NAME accepts (type, default, range, units, backends,
      help), the framework's keys of its section first; NAME may also be a framework section
      (scene, mesh, output, guard, self_collision, ...); --markdown: as the tables of docs/.
  loom --help | --version

options:
  --set key=value   override any scene key by its dotted path, e.g. --set integrator.dt=0.0005
                    (repeatable; the value is YAML: --set gravity=[0,0,-9.81])
  --out DIR         output folder
  --frames N        number of frames to simulate (overrides 'frames')
  --quiet           no progress bar or summary

environment:
  LOOM_PLUGIN_PATH  colon-separated folders searched first for plugin modules
  OMP_NUM_THREADS   threads for 'threads: auto' (capped at the usable cores; a count in
                    the scene takes precedence)

exit codes: 0 ok, 1 internal or output error (disk full), 2 bad input (scene, mesh, flags), 3 diverged,
            4 linear solver failed, 5 loom check found intersecting triangles,
            130 interrupted (Ctrl-C; frames written so far kept)
)";

struct Args {
  std::string command, scene, out, render_scene, study, resume;
  int frames = -1;
  bool quiet = false;
  bool stability = false;
  bool render = false;
  bool overwrite = false;
  bool allow = false, list = false, distance = false;
  std::vector<std::string> sets;
  std::string params;   // plugins --params NAME
  bool markdown = false;
};

[[noreturn]] void usage_error(const std::string& msg) {
  std::cerr << "loom: " << msg << "\n(run 'loom --help' for usage)\n";
  std::exit(loom::kExitBadInput);
}

Args parse_args(int argc, char** argv) {
  Args a;
  if (argc < 2) usage_error("missing command: one of run, validate, study, render, view, check, plot, plugins");
  a.command = argv[1];
  if (a.command == "--help" || a.command == "-h" || a.command == "help") {
    std::cout << kUsage;
    std::exit(0);
  }
  if (a.command == "--version") {
    std::cout << "loom " << LOOM_VERSION_STRING << " (plugin ABI " << loom::kPluginAbiVersion << ")\n";
    std::exit(0);
  }
  const std::vector<std::string> commands = {"run", "validate", "plugins", "render", "view", "study", "check", "plot"};
  if (std::find(commands.begin(), commands.end(), a.command) == commands.end()) {
    const std::string hint = loom::closest_match(a.command, commands);
    usage_error("unknown command '" + a.command + "'" + (hint.empty() ? "" : " (did you mean '" + hint + "'?)") +
                "; commands: run, validate, study, render, view, check, plot, plugins");
  }
  for (int i = 2; i < argc; ++i) {
    const std::string s = argv[i];
    auto value = [&](const char* flag) -> std::string {
      const std::string f = flag;
      if (s.size() > f.size() && s.compare(0, f.size() + 1, f + "=") == 0) return s.substr(f.size() + 1);
      if (i + 1 >= argc) usage_error(f + " needs a value");
      return argv[++i];
    };
    if (s == "--help" || s == "-h") {
      std::cout << kUsage;
      std::exit(0);
    } else if (s == "--out" || s.rfind("--out=", 0) == 0) {
      a.out = value("--out");
    } else if (s == "--frames" || s.rfind("--frames=", 0) == 0) {
      const std::string v = value("--frames");
      char* end = nullptr;
      const long n = std::strtol(v.c_str(), &end, 10);
      if (v.empty() || *end != '\0' || n < 0 || n > 100000000)
        usage_error("--frames needs a non-negative integer (got '" + v + "')");
      a.frames = static_cast<int>(n);
    } else if (s == "--set" || s.rfind("--set=", 0) == 0) {
      const std::string kv = value("--set");
      if (kv.find('=') == std::string::npos || kv[0] == '=')
        usage_error("--set needs key=value, e.g. --set integrator.dt=0.0005 (got '" + kv + "')");
      a.sets.push_back(kv);
    } else if ((a.command == "render" || a.command == "view") && (s == "--scene" || s.rfind("--scene=", 0) == 0)) {
      a.render_scene = value("--scene");
    } else if (a.command == "run" && s == "--render") {
      a.render = true;
    } else if (a.command == "run" && (s == "--resume" || s.rfind("--resume=", 0) == 0)) {
      a.resume = value("--resume");
    } else if (a.command == "run" && s == "--overwrite") {
      a.overwrite = true;
    } else if (a.command == "plugins" && (s == "--params" || s.rfind("--params=", 0) == 0)) {
      a.params = value("--params");
    } else if (a.command == "plugins" && s == "--markdown") {
      a.markdown = true;
    } else if (a.command == "check" && (s == "--allow" || s == "--list" || s == "--distance")) {
      (s == "--allow" ? a.allow : s == "--list" ? a.list : a.distance) = true;
    } else if (a.command == "study" && s == "--stability") {
      a.stability = true;
    } else if (s == "--quiet" || s == "-q") {
      a.quiet = true;
    } else if (!s.empty() && s[0] == '-') {
      const std::string hint = loom::closest_match(s, {"--out", "--frames", "--set", "--quiet", "--help", "--overwrite", "--render", "--resume"});
      usage_error("unknown option '" + s + "'" + (hint.empty() ? "" : " (did you mean '" + hint + "'?)"));
    } else if (a.scene.empty()) {
      a.scene = s;
    } else if (a.command == "study" && a.study.empty()) {
      a.study = s;
    } else {
      usage_error("unexpected argument '" + s + "' (one scene file per run)");
    }
  }
  if (a.command == "study" && (a.scene.empty() || a.study.empty()))
    usage_error("study needs a scene and a study file, e.g. loom study scenes/hanging_10x10.yaml studies/hanging_k2000.yaml");
  if (a.command == "render" && a.scene.empty()) usage_error("render needs the output folder of a run, e.g. loom render out/hanging_cloth");
  if (a.command == "check" && a.scene.empty()) usage_error("check needs the output folder of a run, e.g. loom check out/hanging_cloth");
  if (a.command == "run" && !a.resume.empty()) {
    if (!a.scene.empty()) usage_error("--resume takes the run's folder, not a scene: loom run --resume RUN_DIR (its scene.yaml is used)");
    if (!a.sets.empty() || !a.out.empty() || a.overwrite)
      usage_error("--resume continues a run exactly as it was started: --set, --out and --overwrite do not apply "
                  "(start a new run for other settings)");
    a.scene = a.resume;
  }
  if (a.command == "plot" && a.scene.empty()) usage_error("plot needs the output folder of a run, e.g. loom plot out/hanging_cloth");
  if (a.command == "view" && a.scene.empty()) usage_error("view needs the output folder of a run, e.g. loom view out/hanging_cloth");
  if (a.command != "plugins" && a.scene.empty()) usage_error(a.command + " needs a scene file, e.g. loom " + a.command + " scenes/hanging_cloth.yaml");
  if (a.command == "plugins" && !a.scene.empty()) usage_error("plugins takes no scene file");
  if (a.markdown && a.params.empty()) usage_error("--markdown goes with --params NAME, e.g. loom plugins --params gnatv --markdown");
  return a;
}

std::string stem(const std::string& path) {
  std::string s = path.substr(path.find_last_of('/') == std::string::npos ? 0 : path.find_last_of('/') + 1);
  const auto dot = s.rfind('.');
  return dot == std::string::npos ? s : s.substr(0, dot);
}

bool show_resume(bool quiet) { return !quiet && loom::is_output_rank(); }

int cmd_plugins(const Args& args) {
  loom::Registry registry;
  loom::PluginLoader loader(registry);
  std::vector<std::string> errors;
  loader.load_all(errors);
  if (!args.params.empty()) {
    for (const auto& e : errors) std::fprintf(stderr, "loom: warning: %s\n", e.c_str());
    std::fputs(loom::params_table(registry, args.params, args.markdown).c_str(), stdout);
    return 0;
  }
  std::printf("plugin path:\n");
  for (const auto& d : loader.search_path()) std::printf("  %s\n", d.c_str());
  std::printf("\n%-11s %-22s %-8s %-8s %s\n", "KIND", "NAME", "BACKEND", "VERSION", "DESCRIPTION");
  for (const auto& p : registry.list())
    std::printf("%-11s %-22s %-8s %-8s %s\n", loom::to_string(p.kind), p.name.c_str(), p.backend.c_str(),
                p.version.c_str(), p.description.c_str());
  for (const auto& e : errors) std::fprintf(stderr, "loom: warning: %s\n", e.c_str());
  return errors.empty() ? 0 : loom::kExitBadInput;
}

// Under mpirun, an error that only one rank sees must end every rank: exit at once, without
// the MPI_Finalize of the atexit handlers (which would wait for the other ranks, who wait in
// a collective for this one). mpirun then sees a rank that died without finalising and ends
// the job with this rank's message and exit code.
int finish(int code) {
  if (code == 0) return 0;
  int world = 1;
  for (const char* var : {"OMPI_COMM_WORLD_SIZE", "PMI_SIZE", "PMIX_SIZE", "MPI_LOCALNRANKS"})
    if (const char* v = std::getenv(var)) world = std::max(world, std::atoi(v));
  if (world > 1) {
    std::cout.flush();
    std::cerr.flush();
    std::fflush(nullptr);
    std::_Exit(code);
  }
  return code;
}

// `loom run`'s summary of self-collision over the steps of this run (SelfCollisionTotals):
// what it cost beside the whole step, and what it did.
void print_self_collision_summary(const loom::SelfCollisionTotals& t, long long steps, double step_seconds,
                                  long long self_contacts) {
  const double per = 1e3 / static_cast<double>(steps);
  std::string search;
  if (t.search_seconds > 0) {
    char b[160];
    std::snprintf(b, sizeof b, "; the integrator's self-contact search %.3g ms, %.4g contacts per step in its solve",
                  per * t.search_seconds, static_cast<double>(self_contacts) / static_cast<double>(steps));
    search = b;
  }
  std::printf("loom: self-collision: %.3g ms per step, %.0f %% of the step time (after-step pass %.3g ms: broad "
              "phase %.3g, proximity %.3g, CCD and fail-safe %.3g%s); %lld impulses (%lld proximity, %lld CCD), "
              "%lld vertices frozen by the fail-safe%s; candidate lists rebuilt %lld times, %lld vertices "
              "refreshed\n",
              per * t.seconds(), step_seconds > 0 ? 100.0 * t.seconds() / step_seconds : 0.0, per * t.resolve_seconds,
              per * t.broad_seconds, per * t.narrow_seconds, per * t.response_seconds, search.c_str(), t.impulses(),
              t.proximity, t.ccd_collisions, t.frozen,
              t.frozen > 0 ? " (each held at its start of step for one step; docs/CONTACT.md)" : "", t.rebuilds,
              t.refreshed);
}

// The fix for a dt above the estimated stable step (loom validate's warning, a divergence).
std::string step_limit_fix(const loom::StepLimit& lim) {
  char buf[256];
  std::snprintf(buf, sizeof buf,
                "Fix: set integrator.dt <= %.3g (with integrator.frame_time the frames keep their spacing), lower "
                "the stiffness, or use baraff_witkin.",
                0.9 * lim.h_max);
  return buf;
}

// After `loom run SCENE` diverged: the stable-step estimate of the scene's initial state (what
// `loom validate` prints), so that the message says whether dt was above it. Explicit
// integrators only (the estimate has no meaning for the others, and their scenes, e.g. with a
// PETSc solver under mpirun, are not built a second time); built from a fresh copy of the
// scene (for --resume, the scene.yaml of the run), since the run's state is the diverged one.
// Nothing is printed when that fails.
void print_step_estimate(const Args& args, const std::string& integrator) {
  if (args.command != "run" || !loom::is_output_rank()) return;
  if (loom::stable_step_factor(integrator) == 0.0) return;
  try {
    loom::Registry registry;
    loom::PluginLoader loader(registry);
    const std::unique_ptr<loom::Simulation> owned =
        args.resume.empty() ? std::make_unique<loom::Simulation>(args.scene, args.sets, loader)
                            : loom::cli::load_run_scene(args.resume, loader);
    loom::Simulation& fresh = *owned;
    const auto lim = loom::estimate_step_limit(fresh.scene(), fresh.integrator_name());
    if (!lim) return;
    const double dt = fresh.dt();
    char buf[640];
    if (dt > lim->h_max)
      std::snprintf(buf, sizeof buf,
                    "loom: dt = %.3g s exceeds the largest stable step of %s estimated at the initial state, %.3g s "
                    "(loom validate prints it before a run). %s",
                    dt, fresh.integrator_name().c_str(), lim->h_max, step_limit_fix(*lim).c_str());
    else
      std::snprintf(buf, sizeof buf,
                    "loom: dt = %.3g s is within the largest stable step of %s estimated at the initial state, %.3g s: "
                    "a later state went unstable (a stiffer stretch, contact, fast motion: a smaller step or more "
                    "damping), or the guard's bound is below motion that is real.",
                    dt, fresh.integrator_name().c_str(), lim->h_max);
    std::cerr << buf << "\n";
  } catch (const std::exception&) {
  }
}

}  // namespace

int main(int argc, char** argv) {
  const Args args = parse_args(argc, argv);
  std::string integrator_name;  // of the run, for the message after a divergence
  try {
    if (args.command == "plugins") return cmd_plugins(args);
    if (args.command == "render") {
      loom::cli::RenderArgs r{args.scene, args.render_scene, args.out, args.sets, args.quiet};
      return loom::cli::render_command(r);
    }
    if (args.command == "plot") return loom::cli::plot_command(args.scene, args.out, args.quiet);
    if (args.command == "check") return loom::cli::check_command({args.scene, args.allow, args.list, args.quiet, args.distance});
    if (args.command == "view") {
      loom::cli::RenderArgs r{args.scene, args.render_scene, args.out, args.sets, args.quiet};
      return loom::cli::view_command(r);
    }
    if (args.command == "study") {
      loom::StudyOptions opt;
      opt.scene = args.scene;
      opt.study = args.study;
      opt.out_dir = args.out.empty() ? "out/study_" + stem(args.study) : args.out;
      const bool tty = ::isatty(STDOUT_FILENO) && !args.quiet;
      const auto t0 = loom::Clock::now();
      opt.progress = [&](const std::string& what, double frac) {
        const double el = loom::seconds_since(t0);
        if (tty) {
          const int width = 30, filled = static_cast<int>(width * frac);
          std::printf("\r\033[K[%.*s%*s] %3d%%  %.0f s  %s", filled, "##############################", width - filled, "",
                      static_cast<int>(100 * frac), el, what.c_str());
          std::fflush(stdout);
        } else if (!args.quiet) {
          std::printf("[%3d%%] %.0f s  %s\n", static_cast<int>(100 * frac), el, what.c_str());
        }
      };
      if (args.stability) {
        const auto rows = loom::run_stability(opt);
        if (tty) std::printf("\n");
        if (!args.quiet) {
          std::printf("%-28s %-22s %-12s %-12s %s\n", "COMBO", "VALUE", "H_STABLE", "H_UNSTABLE", "FAILURE");
          for (const auto& r : rows)
            std::printf("%-28s %-22s %-12.4g %-12.4g %s\n", r.combo.c_str(), r.value.c_str(), r.h_stable, r.h_unstable,
                        r.failure.c_str());
          std::printf("loom: wrote %s/stability.csv\n", opt.out_dir.c_str());
        }
        loom::cli::plot_stability(opt.out_dir, args.quiet);
        return 0;
      }
      const auto result = loom::run_study(opt);
      const auto& rows = result.rows;
      if (tty) std::printf("\n");
      int bad = 0;
      for (const auto& r : rows) bad += r.status != "ok";
      if (!args.quiet) loom::cli::print_study_table(rows);
      if (!args.quiet)
        std::printf("loom: study done in %.1f s: %zu rows (%d not ok: diverged/failed/timeout); wrote %s/study.csv\n",
                    loom::seconds_since(t0), rows.size(), bad,
                    opt.out_dir.c_str());
      if (!args.quiet)
        std::printf("loom: the reference changes by %.3g (RMS, x cloth size) when its step is halved: smaller errors "
                    "are not resolved (%s/reference.txt)\n", result.reference.largest_rms_change, opt.out_dir.c_str());
      loom::cli::plot_study(opt.out_dir, args.quiet);
      return 0;
    }
    loom::Registry registry;
    loom::PluginLoader loader(registry);
    std::unique_ptr<loom::Simulation> owned =
        args.resume.empty() ? std::make_unique<loom::Simulation>(args.scene, args.sets, loader)
                            : loom::cli::load_for_resume(args.resume, args.frames, loader);
    loom::Simulation& sim = *owned;
    integrator_name = sim.integrator_name();
    if (args.frames >= 0 && args.resume.empty()) sim.set_frames(args.frames);
    if (args.command == "validate") {
      for (const auto& line : sim.describe()) std::cout << line << "\n";
      bool step_warning = false;
      if (const auto lim = loom::estimate_step_limit(sim.scene(), sim.integrator_name())) {
        char buf[512];
        std::snprintf(buf, sizeof buf,
                      "stability:  largest stable step about %.3g s (sqrt(lambda_max) h = %.3g for %s; lambda_max of "
                      "M^-1 K at the initial state = %.4g 1/s^2, %d power iterations)",
                      lim->h_max, lim->factor, sim.integrator_name().c_str(), lim->lambda_max, lim->iterations);
        std::cout << buf << "\n";
        if (sim.dt() > lim->h_max) {
          step_warning = true;
          std::snprintf(buf, sizeof buf,
                        "loom: warning: dt = %.3g s exceeds the estimated stable step %.3g s: this run will most likely "
                        "diverge. %s",
                        sim.dt(), lim->h_max, step_limit_fix(*lim).c_str());
          std::cerr << buf << "\n";
        }
      }
      std::cout << (step_warning ? "ok: the scene is valid (see the warning above)\n" : "ok: the scene is valid\n");
      return 0;
    }
    if (!args.out.empty()) sim.output().dir = args.out;
    if (sim.output().dir.empty()) sim.output().dir = "out/" + stem(args.scene);
    if (!args.resume.empty() && show_resume(args.quiet))
      std::printf("loom: resuming %s at frame %d of %d (t = %.6g s)\n", args.resume.c_str(), sim.start_frame(),
                  sim.frames(), sim.scene().state.time);
    sim.output().overwrite = args.overwrite;
    const bool show = !args.quiet && loom::is_output_rank();
    const bool tty = show && ::isatty(STDOUT_FILENO);
    const auto t0 = loom::Clock::now();
    // Progress: on a terminal one line redrawn at most every 0.5 s; elsewhere (a log) one line
    // every 5 s. Steps per second, simulated time, and the time left.
    const long long total_steps = static_cast<long long>(sim.frames() - sim.start_frame()) * sim.substeps();
    const long long first_step = sim.scene().state.step;
    auto last_print = t0;
    auto report = [&](bool final_line) {
      const auto now = loom::Clock::now();
      const double since = loom::seconds_between(last_print, now);
      if (!final_line && since < (tty ? 0.5 : 5.0)) return;
      last_print = now;
      const double el = loom::seconds_between(t0, now);
      const long long done = sim.scene().state.step - first_step;
      const double rate = el > 0 ? done / el : 0.0;
      const double eta = rate > 0 ? (total_steps - done) / rate : 0.0;
      const int pct = total_steps > 0 ? static_cast<int>(100.0 * done / total_steps) : 100;
      char line[256];
      std::snprintf(line, sizeof line, "%3d%%  step %lld/%lld  t = %.4g s  %.4g steps/s  %.1f s elapsed  ETA %.1f s", pct,
                    done, total_steps, sim.scene().state.time, rate, el, eta);
      if (tty) std::printf("\r\033[K%s", line);
      else std::printf("loom: %s\n", line);
      std::fflush(stdout);
    };
    if (show) sim.set_step_callback([&] { report(false); });
    auto progress = [&](int, int) {};
    std::signal(SIGINT, [](int) { loom::Simulation::request_stop(); });
    std::signal(SIGTERM, [](int) { loom::Simulation::request_stop(); });
    try {
      sim.run(progress);
    } catch (const loom::Interrupted& e) {
      if (tty) std::printf("\n");
      std::fprintf(stderr, "loom: %s; the frames written before it are complete and kept in %s%s\n", e.what(),
                   sim.output().dir.c_str(),
                   sim.output().restart ? (" (continue it with: loom run --resume " + sim.output().dir + ")").c_str() : "");
      return finish(130);
    }
    if (tty) std::printf("\n");
    if (show) {
      sim.sync_state();  // run() ended on a frame's check, which synced; this keeps the summary right regardless
      const auto& st = sim;
      const double el = loom::seconds_since(t0);
      const auto f = st.measure(st.frames());
      std::printf("loom: summary: %lld steps in %.3g s (%.3g ms per step in the integrator); largest strain %.4g; "
                  "final energy %.6g J (kinetic %.4g, elastic %.4g); %lld force evaluations, %lld linear iterations\n",
                  static_cast<long long>(st.scene().state.step - first_step), el,
                  st.scene().state.step > first_step ? 1e3 * st.step_seconds_total() / (st.scene().state.step - first_step) : 0.0, f.max_strain,
                  f.kinetic + f.gravitational + f.elastic, f.kinetic, f.elastic, st.force_evaluations(), st.linear_iterations());
      if (const auto* sc = st.scene().self_collision.get(); sc && st.scene().state.step > first_step)
        print_self_collision_summary(sc->totals(), st.scene().state.step - first_step, st.step_seconds_total(),
                                     st.self_contacts_total());
      if (st.step_retries() > 0)
        std::printf("loom: %lld step halving%s after failed linear solves (integrator.on_solver_failure: halve_step): "
                    "those steps were solved again as two halves\n",
                    st.step_retries(), st.step_retries() == 1 ? "" : "s");
      if (const auto* tc = st.thread_controller()) {
        char load[128] = "not measured (short set-up)";
        if (tc->start_load() >= 0) std::snprintf(load, sizeof load, "%.2f cores", tc->start_load());
        if (tc->start_runnable() >= 0) {  // the runnable count was read: the fallback, or the check of the load
          const std::size_t n = std::strlen(load);
          std::snprintf(load + n, sizeof load - n, ", %d other%s runnable%s", tc->start_runnable(),
                        tc->start_runnable() == 1 ? "" : "s", tc->start_unconfirmed() ? ": not confirmed" : "");
        }
        // Where the step time went, per count (for comparing with a fixed count's run).
        std::string on;
        for (int n = 1; n <= loom::usable_cores(); ++n)
          if (const long k = tc->steps_on(n); k > 0) {
            char b[96];
            std::snprintf(b, sizeof b, "%s%ld steps on %d (%.3g s)", on.empty() ? "" : ", ", k, n, tc->seconds_on(n));
            on += b;
          }
        std::printf("loom: threads auto: ended on %d (started on %d, others' load at start %s; %d probes, "
                    "%d held back by load, %d by short steps, %d switches, probes cost %.3g s; %s; samples of "
                    "at least %d step%s)\n", tc->chosen(), tc->initial(), load, tc->probes(), tc->gated_probes(),
                    tc->small_step_holds(), tc->switches(), tc->probe_loss(), on.empty() ? "no steps" : on.c_str(),
                    tc->sample_steps(), tc->sample_steps() == 1 ? "" : "s");
      }
    }
    if (args.render && loom::is_output_rank()) {
      if (!args.quiet)
        std::printf("loom: %d frames (%lld steps) simulated; rendering\n", sim.frames(),
                    static_cast<long long>(sim.scene().state.step));
      loom::cli::RenderArgs r{sim.output().dir, "", "", {}, args.quiet};
      return loom::cli::render_command(r);
    }
    if (!args.quiet && loom::is_output_rank()) {
      const double el = loom::seconds_since(t0);
      std::printf("loom: %d frames (%lld steps, %.4g s simulated) in %.3g s; wrote %s\n", sim.frames() - sim.start_frame(),
                  static_cast<long long>(sim.scene().state.step), sim.scene().state.time, el, sim.output().dir.c_str());
    }
    return 0;
  } catch (const loom::InputError& e) {
    std::cerr << "loom: error: " << e.what() << "\n";
    return finish(loom::kExitBadInput);
  } catch (const loom::DivergenceError& e) {
    std::cerr << "loom: " << e.what() << "\n(frames written before the divergence are kept)\n";
    print_step_estimate(args, integrator_name);
    return finish(loom::kExitDiverged);
  } catch (const loom::SolverError& e) {
    std::cerr << "loom: linear solver failed: " << e.what() << "\n";
    return finish(loom::kExitSolverFailed);
  } catch (const loom::OutputError& e) {
    std::cerr << "loom: output error: " << e.what() << "\n";
    return finish(loom::kExitInternal);
  } catch (const std::exception& e) {
    std::cerr << "loom: internal error: " << e.what() << "\n";
    return finish(loom::kExitInternal);
  }
}

#include "plot_cmd.hpp"

#include <unistd.h>

#include <cstdio>
#include <filesystem>
#include <fstream>

#include "loom/common.hpp"
#include "loom/spawn.hpp"

namespace fs = std::filesystem;

namespace loom::cli {

namespace {

// scripts/plot_*.py exit with this code when matplotlib cannot be imported.
constexpr int kNoMatplotlib = 3;

const char* kInstallFix = "Fix: apt-get install python3-matplotlib (scripts/setup.sh installs it)";

}  // namespace

std::string find_script(const std::string& name) {
  std::vector<std::string> candidates = {std::string(LOOM_SOURCE_SCRIPTS_DIR) + "/" + name};
  char buf[4096];
  const ssize_t n = ::readlink("/proc/self/exe", buf, sizeof(buf) - 1);
  if (n > 0) {
    buf[n] = 0;
    candidates.push_back((fs::path(buf).parent_path().parent_path() / "share/loom/scripts" / name).string());
  }
  for (const auto& c : candidates)
    if (fs::exists(c)) return c;
  return {};
}

int plot_command(const std::string& run_dir, const std::string& out_png, bool quiet) {
  const fs::path stats = fs::path(run_dir) / "stats.csv";
  if (!fs::is_directory(run_dir))
    throw InputError(run_dir + ": not a folder. Fix: give the output folder of 'loom run' (it holds stats.csv).");
  if (!fs::is_regular_file(stats))
    throw InputError(stats.string() + ": not found. Fix: run 'loom run SCENE --out " + run_dir +
                     "' first (with output.stats: true, the default).");
  {
    std::ifstream in(stats);
    std::string header, row;
    std::getline(in, header);
    if (header.rfind("frame,time,", 0) != 0)
      throw InputError(stats.string() + ":1: not a Loom stats.csv (it starts with 'frame,time,...'). Fix: give a run folder.");
    if (!std::getline(in, row) || row.empty())
      throw InputError(stats.string() + ": has no rows yet. Fix: plot once the run has written a frame.");
  }
  const std::string png = out_png.empty() ? (fs::path(run_dir) / "stats.png").string() : out_png;
  const std::string script = find_script("plot_run.py");
  if (script.empty()) throw InputError("scripts/plot_run.py is missing from this installation. Fix: reinstall Loom.");
  if (!program_on_path("python3"))
    throw InputError(std::string("loom plot needs python3 with matplotlib, and python3 is not on the PATH. ") + kInstallFix + ".");
  const SpawnResult r = run_program({"python3", script, stats.string(), png}, /*quiet=*/false);
  if (r.started && r.exit_code == kNoMatplotlib)
    throw InputError(std::string("loom plot needs matplotlib, which python3 cannot import. ") + kInstallFix + ".");
  if (!r.ok()) throw InputError("plotting " + stats.string() + " failed: " + r.error + ".");
  if (!quiet) std::printf("loom: wrote %s\n", png.c_str());
  return 0;
}

namespace {

// scripts/SCRIPT on DIR/CSV -> DIR/PNG; without python3 + matplotlib a note says so (the CSV is
// the result, the plot a convenience).
void plot_csv(const std::string& dir, const char* csv_name, const char* png_name, const char* script_name,
              const char* what, bool quiet) {
  const std::string csv = (fs::path(dir) / csv_name).string();
  const std::string png = (fs::path(dir) / png_name).string();
  const std::string script = find_script(script_name);
  SpawnResult r;
  if (!script.empty() && program_on_path("python3")) r = run_program({"python3", script, csv, png}, /*quiet=*/false);
  if (r.ok()) {
    if (!quiet) std::printf("loom: wrote %s\n", png.c_str());
    return;
  }
  const std::string missing = std::string("python3 or scripts/") + script_name + " not found";
  std::fprintf(stderr, "loom: note: no %s plot (%s). %s.\n", what,
               r.started && r.exit_code == kNoMatplotlib ? "python3 cannot import matplotlib"
               : r.started                               ? r.error.c_str()
                                                         : missing.c_str(),
               kInstallFix);
}

}  // namespace

void plot_stability(const std::string& dir, bool quiet) {
  plot_csv(dir, "stability.csv", "stability.png", "plot_stability.py", "stability", quiet);
}

void plot_study(const std::string& dir, bool quiet) {
  plot_csv(dir, "study.csv", "study.png", "plot_study.py", "study", quiet);
}

void print_study_table(const std::vector<StudyRow>& rows) {
  std::printf("%-26s %-10s %-7s %-9s %-10s %-6s %-11s %-12s %s\n", "COMBO", "H", "TIME", "STATUS", "RMS_ERROR", "ORDER",
              "E_DRIFT", "WALL/SIM_S", "LIN_ITERS");
  for (const StudyRow& r : rows) {
    std::printf("%-26s %-10.4g %-7.4g %-9s %-10.3g %-6.2f %-11.3g %-12.4g %lld\n", r.combo.c_str(), r.h, r.time,
                r.status.c_str(), r.rms_error, r.observed_order, r.energy_drift, r.wall_per_sim_second,
                r.linear_iterations);
  }
}

}  // namespace loom::cli

// Shared by the CLI tests: run the built `loom` (through a shell, with the test plugins on
// LOOM_PLUGIN_PATH unless told otherwise), make a fresh scratch folder, wait for a file.
#pragma once

#include <sys/wait.h>

#include <array>
#include <chrono>
#include <cstdio>
#include <filesystem>
#include <fstream>
#include <string>
#include <thread>

namespace loom_cli_test {

struct Result {
  int code = -1;
  std::string out;  // stdout and stderr together
};

/// Any shell command line (tests only: fixed strings), stdout and stderr together.
inline Result run_loom_shell(const std::string& command_line) {
  const std::string cmd = "(" + command_line + ") 2>&1";
  Result r;
  FILE* p = popen(cmd.c_str(), "r");
  std::array<char, 4096> buf{};
  while (fgets(buf.data(), buf.size(), p)) r.out += buf.data();
  const int status = pclose(p);
  r.code = WIFEXITED(status) ? WEXITSTATUS(status) : -1;
  return r;
}

inline Result run_loom(const std::string& args, bool test_plugins = true) {
  std::string cmd;
  if (test_plugins) cmd += "LOOM_PLUGIN_PATH=" LOOM_TEST_PLUGIN_DIR " ";
  return run_loom_shell(cmd + std::string(LOOM_EXE) + " " + args);
}

/// An empty folder <tmp>/<prefix><name>, removed first if it exists.
inline std::filesystem::path scratch_dir(const std::string& prefix, const std::string& name) {
  const std::filesystem::path d = std::filesystem::temp_directory_path() / (prefix + name);
  std::filesystem::remove_all(d);
  std::filesystem::create_directories(d);
  return d;
}

/// Wait (polling every 5 ms) until path exists, at most `timeout`; whether it does. For tests that
/// signal a running loom once it has written something.
inline bool wait_for_path(const std::filesystem::path& path, std::chrono::milliseconds timeout) {
  const auto end = std::chrono::steady_clock::now() + timeout;
  while (!std::filesystem::exists(path)) {
    if (std::chrono::steady_clock::now() >= end) return false;
    std::this_thread::sleep_for(std::chrono::milliseconds(5));
  }
  return true;
}

/// DIR/scene.yaml, returned: a 6 x 5 grid (30 vertices, 40 triangles) falling under gravity,
/// pinned at its top edge, with the test plugins (no internal forces, explicit Euler), `frames`
/// frames, then the YAML `extra`.
inline std::string falling_grid_scene(const std::filesystem::path& dir, int frames, const std::string& extra = "") {
  const std::string text = "mesh:\n  grid: {nx: 6, ny: 5, width: 1.0, height: 0.8}\nmaterial:\n  type: test_gravity_only\n"
                           "integrator:\n  type: test_explicit_euler\n  dt: 0.01\n  substeps: 2\npins: [top_edge]\n"
                           "frames: " + std::to_string(frames) + "\n" + extra;
  std::ofstream(dir / "scene.yaml") << text;
  return (dir / "scene.yaml").string();
}

}  // namespace loom_cli_test

// Shared by the CLI tests: run the built `loom` (through a shell, with the test plugins on
// LOOM_PLUGIN_PATH unless told otherwise) and make a fresh scratch folder.
#pragma once

#include <sys/wait.h>

#include <array>
#include <cstdio>
#include <filesystem>
#include <string>

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

}  // namespace loom_cli_test

// Running external programs (python3 for plots, ffmpeg for videos) without a shell.
//
// Arguments go to the program as an argument vector (posix_spawnp), so user strings such as
// folder and file names are never interpreted by a shell: quotes, `;`, `$(...)` are inert.
#pragma once

#include <string>
#include <vector>

namespace loom {

struct SpawnResult {
  bool started = false;   ///< false: the program was not found or could not be started
  int exit_code = -1;     ///< its exit status when it exited normally; -1 when killed by a signal
  std::string error;      ///< why it did not start or did not exit with 0, for messages

  bool ok() const { return started && exit_code == 0; }
};

/// Run argv[0] (searched on PATH) with the arguments argv[1..], wait for it, and return its
/// status. quiet: its stdout and stderr go to /dev/null. Never uses a shell.
SpawnResult run_program(const std::vector<std::string>& argv, bool quiet = true);

/// Whether `name` is an executable file on PATH (or an executable path when it contains '/').
bool program_on_path(const std::string& name);

}  // namespace loom

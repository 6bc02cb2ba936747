#pragma once

#include <string>

namespace loom::cli {

struct CheckArgs {
  std::string run_dir;  ///< output folder of `loom run` (frame_*.obj)
  bool allow = false;   ///< exit 0 even when frames have intersecting pairs
  bool list = false;    ///< print the intersecting triangle pairs of each frame
  bool quiet = false;   ///< only the summary line
};

/// `loom check RUN_DIR`: the number of intersecting non-adjacent triangle pairs of every
/// frame (exact test, loom/intersection_check.hpp). Returns 0 when no frame has any (or with
/// --allow), kExitIntersections otherwise. Throws InputError on bad input.
int check_command(const CheckArgs& args);

}  // namespace loom::cli

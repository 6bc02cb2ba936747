#pragma once

#include <string>

namespace loom::cli {

struct CheckArgs {
  std::string run_dir;  ///< output folder of `loom run` (frame_*.obj)
  bool allow = false;   ///< exit 0 even when frames have intersecting pairs
  bool list = false;    ///< print the intersecting triangle pairs of each frame
  bool quiet = false;   ///< only the summary line
  bool distance = false;  ///< also the closest approach of non-adjacent elements per frame
};

/// `loom check RUN_DIR`: the number of intersecting non-adjacent triangle pairs of every
/// frame (exact test, loom/intersection_check.hpp); with --distance also each frame's closest
/// approach of non-adjacent elements (loom::closest_approach), as a fraction of the run's
/// self_collision thickness when its scene.yaml has one. Returns 0 when no frame has any
/// intersecting pair (or with --allow), kExitIntersections otherwise. Throws InputError on bad input.
int check_command(const CheckArgs& args);

}  // namespace loom::cli

// What `loom run --resume` does to a run folder before continuing it.
#pragma once

#include <string>

namespace loom {

/// Cut a stopped run's folder back to its last complete frame `last_frame` (the frame of its
/// restart.bin): stats.csv keeps its header and the rows of frames <= last_frame (rewritten
/// atomically); frame_*.obj and frame_*.vtu files of later frames are removed. The point
/// caches and run.pvd are cut by their writers. Throws InputError when stats.csv lacks a row
/// the restart point says was written.
void trim_run_for_resume(const std::string& dir, int last_frame, bool stats);

}  // namespace loom

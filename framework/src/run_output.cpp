#include "loom/run_output.hpp"

#include <cstdlib>
#include <filesystem>
#include <fstream>
#include <vector>

#include "loom/common.hpp"
#include "loom/output.hpp"

namespace fs = std::filesystem;

namespace loom {

void trim_run_for_resume(const std::string& dir, int last_frame, bool stats) {
  if (stats) {
    const std::string path = (fs::path(dir) / "stats.csv").string();
    std::ifstream in(path);
    if (!in)
      throw InputError(path + ": missing, but the run being resumed wrote it. Fix: rerun the scene with --overwrite.");
    std::string line, kept;
    int last_row = -1;
    bool header = true;
    while (std::getline(in, line)) {
      if (header) {
        kept += line + '\n';
        header = false;
        continue;
      }
      if (line.empty()) continue;
      char* end = nullptr;
      const long frame = std::strtol(line.c_str(), &end, 10);
      if (end == line.c_str() || *end != ',') break;  // a torn last row of a killed run
      if (frame > last_frame) break;
      kept += line + '\n';
      last_row = static_cast<int>(frame);
    }
    if (last_row != last_frame)
      throw InputError(path + ": ends at frame " + std::to_string(last_row) + ", but restart.bin is at frame " +
                       std::to_string(last_frame) + ". Fix: rerun the scene with --overwrite.");
    write_file_atomic(path, kept);
  }
  std::error_code ec;
  for (const auto& e : fs::directory_iterator(dir, ec)) {
    const std::string name = e.path().filename().string();
    const std::string ext = e.path().extension().string();
    if (name.rfind("frame_", 0) != 0 || (ext != ".obj" && ext != ".vtu")) continue;
    const int frame = std::atoi(name.c_str() + 6);
    if (frame > last_frame) {
      std::error_code rm;
      fs::remove(e.path(), rm);
      if (rm) throw InputError("cannot remove " + e.path().string() + ": " + rm.message() + ".");
    }
  }
}

}  // namespace loom

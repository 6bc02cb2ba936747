// `loom check RUN_DIR`: exact self-intersection count of every frame a run wrote.
#include "check_cmd.hpp"

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <filesystem>
#include <fstream>
#include <vector>

#include "loom/common.hpp"
#include "loom/intersection_check.hpp"
#include "loom/mesh.hpp"

namespace fs = std::filesystem;

namespace loom::cli {

namespace {

// The 'v' lines of a frame (the topology is the first frame's).
void read_positions(const fs::path& path, std::vector<double>& x) {
  std::ifstream in(path);
  if (!in) throw InputError(path.string() + ": cannot open frame");
  x.clear();
  std::string line;
  int lineno = 0;
  while (std::getline(in, line)) {
    ++lineno;
    if (line.size() < 2 || line[0] != 'v' || line[1] != ' ') continue;
    // strtod, not >>: it reads "nan" and "inf", which are then reported as such.
    const char* p = line.c_str() + 2;
    double c[3];
    for (double& v : c) {
      char* end = nullptr;
      v = std::strtod(p, &end);
      if (end == p)
        throw InputError(path.string() + ":" + std::to_string(lineno) + ": bad vertex line. Fix: 'v x y z'.");
      p = end;
    }
    if (!std::isfinite(c[0]) || !std::isfinite(c[1]) || !std::isfinite(c[2]))
      throw InputError(path.string() + ":" + std::to_string(lineno) +
                       ": NaN or Inf coordinate: the frame is not a valid state. Fix: re-run the scene.");
    x.insert(x.end(), c, c + 3);
  }
}

}  // namespace

int check_command(const CheckArgs& args) {
  const fs::path run_dir = args.run_dir;
  if (!fs::is_directory(run_dir))
    throw InputError(args.run_dir + ": not a folder. Fix: give the output folder of 'loom run' (it holds frame_*.obj).");
  std::vector<fs::path> frames;
  for (const auto& e : fs::directory_iterator(run_dir)) {
    const std::string f = e.path().filename().string();
    if (f.rfind("frame_", 0) == 0 && e.path().extension() == ".obj") frames.push_back(e.path());
  }
  std::sort(frames.begin(), frames.end());
  if (frames.empty())
    throw InputError(args.run_dir + ": no frame_*.obj files. Fix: run 'loom run SCENE --out " + args.run_dir +
                     "' first.");
  const Mesh mesh = read_obj(frames.front().string(), 0.0);
  std::vector<double> x;
  std::vector<std::array<Index, 2>> pairs;
  std::size_t bad_frames = 0, worst = 0;
  std::string worst_name;
  if (!args.quiet) std::printf("%-24s %s\n", "FRAME", "INTERSECTING_PAIRS");
  for (const auto& f : frames) {
    read_positions(f, x);
    if (x.size() != mesh.positions.size())
      throw InputError(f.string() + ": has " + std::to_string(x.size() / 3) + " vertices, the first frame has " +
                       std::to_string(mesh.num_vertices()) + ". Fix: check the frames of one run only.");
    const std::size_t n = count_intersecting_pairs(mesh, x, args.list ? &pairs : nullptr);
    if (n > 0) ++bad_frames;
    if (n > worst) {
      worst = n;
      worst_name = f.filename().string();
    }
    if (!args.quiet) std::printf("%-24s %zu\n", f.filename().string().c_str(), n);
    if (args.list)
      for (const auto& p : pairs) std::printf("  triangles %d %d\n", p[0], p[1]);
  }
  if (bad_frames == 0) {
    std::printf("loom check: no intersecting triangle pairs in %zu frames (%d triangles)\n", frames.size(),
                mesh.num_triangles());
    return kExitOk;
  }
  std::printf("loom check: %zu of %zu frames have intersecting triangle pairs (most: %zu in %s)\n", bad_frames,
              frames.size(), worst, worst_name.c_str());
  return args.allow ? kExitOk : kExitIntersections;
}

}  // namespace loom::cli

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
#include "loom/params.hpp"

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

// The self_collision thickness of the run's scene.yaml (written by loom run), 0 when the file or
// the key is absent or not a positive number.
double run_thickness(const fs::path& run_dir) {
  const fs::path p = run_dir / "scene.yaml";
  if (!fs::exists(p)) return 0;
  try {
    const Params scene = Params::from_file(p.string());
    const Params sc = scene.child("self_collision");
    if (!sc.valid() || !sc.is_map()) return 0;
    const Params th = sc.child("thickness");
    if (!th.valid() || !th.is_scalar()) return 0;
    const double t = th.as_double();
    return std::isfinite(t) && t > 0 ? t : 0;
  } catch (const InputError&) {
    return 0;  // a scene.yaml that does not parse: the distances are still reported, in m
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
  // --distance: pairs are looked for below the larger of the mean edge length (of the first
  // frame) and 4 thicknesses; the thickness from the run's scene.yaml, when it has self_collision.
  double thickness = 0, within = 0;
  ClosestApproach closest;
  std::string closest_name;
  if (args.distance) {
    thickness = run_thickness(run_dir);
    double sum = 0;
    const auto edges = mesh.edges();
    for (const auto& e : edges) {
      const double* a = &mesh.positions[3 * static_cast<std::size_t>(e[0])];
      const double* b = &mesh.positions[3 * static_cast<std::size_t>(e[1])];
      sum += std::sqrt((b[0] - a[0]) * (b[0] - a[0]) + (b[1] - a[1]) * (b[1] - a[1]) + (b[2] - a[2]) * (b[2] - a[2]));
    }
    within = std::max(edges.empty() ? 1.0 : sum / static_cast<double>(edges.size()), 4 * thickness);
    if (!(within > 0)) within = 1.0;
  }
  if (!args.quiet) {
    if (args.distance) std::printf("%-24s %-18s %-14s%s\n", "FRAME", "INTERSECTING_PAIRS", "CLOSEST_M", thickness > 0 ? " CLOSEST/THICKNESS" : "");
    else std::printf("%-24s %s\n", "FRAME", "INTERSECTING_PAIRS");
  }
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
    ClosestApproach c;
    if (args.distance) {
      c = closest_approach(mesh, x, within);
      if (c.distance < closest.distance) {
        closest = c;
        closest_name = f.filename().string();
      }
    }
    if (!args.quiet) {
      std::printf(args.distance ? "%-24s %-18zu" : "%-24s %zu", f.filename().string().c_str(), n);
      if (args.distance) {
        if (std::isfinite(c.distance)) std::printf(" %-14.6g", c.distance);
        else std::printf(" >%-13.6g", within);
        if (thickness > 0) {
          if (std::isfinite(c.distance)) std::printf(" %.4g", c.distance / thickness);
          else std::printf(" >%.4g", within / thickness);
        }
      }
      std::printf("\n");
    }
    if (args.list)
      for (const auto& p : pairs) std::printf("  triangles %d %d\n", p[0], p[1]);
  }
  if (args.distance) {
    if (!std::isfinite(closest.distance)) {
      std::printf("loom check: no two non-adjacent elements closer than %.6g m in any frame\n", within);
    } else {
      std::printf("loom check: closest approach %.6g m", closest.distance);
      if (thickness > 0) std::printf(" (%.4g of the thickness %.6g m)", closest.distance / thickness, thickness);
      if (closest.vertex_triangle)
        std::printf(" in %s: vertex %d and triangle (%d, %d, %d)\n", closest_name.c_str(), closest.v[0], closest.v[1],
                    closest.v[2], closest.v[3]);
      else
        std::printf(" in %s: edges (%d, %d) and (%d, %d)\n", closest_name.c_str(), closest.v[0], closest.v[1],
                    closest.v[2], closest.v[3]);
    }
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

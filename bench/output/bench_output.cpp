// Cost of writing one frame in each output format, at 128^2 and 512^2 vertices (a cloth
// deformed from its rest grid so that the numbers have full digits), text and disk together
// (the files go to $TMPDIR, renamed into place as a run does). Compare with a frame's
// simulation (substeps x the step time of docs/BENCHMARKS.md).
//   build/bin/bench_output --benchmark_repetitions=3 --benchmark_report_aggregates_only=true
#include <benchmark/benchmark.h>

#include <unistd.h>

#include <cmath>
#include <filesystem>
#include <map>
#include <string>
#include <vector>

#include "loom/mesh.hpp"
#include "loom/output.hpp"
#include "loom/restart.hpp"
#include "loom/vtk_output.hpp"

namespace fs = std::filesystem;
using namespace loom;

namespace {

struct Frame {
  Mesh mesh;
  std::vector<double> x, v;
  std::string dir;
};

struct Cache : std::map<int, Frame> {
  ~Cache() {
    for (auto& [n, f] : *this) fs::remove_all(f.dir);
  }
};

const Frame& frame(int n) {
  static Cache cache;
  auto it = cache.find(n);
  if (it != cache.end()) return it->second;
  Frame f;
  f.mesh = make_grid(n, n, 1.0, 1.0);
  f.x = f.mesh.positions;
  f.v.assign(f.x.size(), 0.0);
  for (std::size_t i = 0; i < f.x.size(); i += 3) {
    f.x[i + 2] = 0.05 * std::sin(7.0 * f.x[i]) * std::cos(5.0 * f.x[i + 1]);
    f.v[i + 1] = -0.3 * f.x[i] + 0.1;
    f.v[i + 2] = 0.2 * std::sin(3.0 * f.x[i + 1]);
  }
  f.dir = (fs::temp_directory_path() / ("loom_bench_output_" + std::to_string(::getpid()))).string();
  fs::create_directories(f.dir);
  return cache.emplace(n, std::move(f)).first->second;
}

void BM_Obj(benchmark::State& state, ObjOptions o) {
  const Frame& f = frame(static_cast<int>(state.range(0)));
  const std::string path = f.dir + "/frame.obj";
  for (auto _ : state) write_file_atomic(path, obj_text(f.mesh, f.x, "t = 1 s", o));
  state.counters["MB"] = double(fs::file_size(path)) / 1e6;
}

void BM_Pc2(benchmark::State& state) {
  const Frame& f = frame(static_cast<int>(state.range(0)));
  PointCacheWriter w(f.dir + "/run.pc2", static_cast<int>(f.mesh.num_vertices()));
  for (auto _ : state) w.append(f.x);
}

void BM_Vtu(benchmark::State& state) {
  const Frame& f = frame(static_cast<int>(state.range(0)));
  VtkSeriesWriter w(f.dir, f.mesh);
  const bool velocities = state.range(1) != 0;
  const std::string path = f.dir + "/frame.vtu";
  for (auto _ : state)
    write_file_atomic(path, w.vtu_text(1.0, f.x, velocities ? std::span<const double>(f.v) : std::span<const double>()));
  state.counters["MB"] = double(fs::file_size(path)) / 1e6;
}

void BM_Restart(benchmark::State& state) {
  const Frame& f = frame(static_cast<int>(state.range(0)));
  RestartData r;
  r.x = f.x;
  r.v = f.v;
  for (auto _ : state) write_restart(f.dir, r);
}

}  // namespace

BENCHMARK_CAPTURE(BM_Obj, default, ObjOptions{})->Arg(128)->Arg(512)->Unit(benchmark::kMillisecond);
BENCHMARK_CAPTURE(BM_Obj, lossless, ObjOptions{false, false, true})->Arg(128)->Arg(512)->Unit(benchmark::kMillisecond);
BENCHMARK_CAPTURE(BM_Obj, uvs_normals, ObjOptions{true, true, false})->Arg(128)->Arg(512)->Unit(benchmark::kMillisecond);
BENCHMARK(BM_Pc2)->Arg(128)->Arg(512)->Unit(benchmark::kMillisecond);
BENCHMARK(BM_Vtu)->Args({128, 0})->Args({128, 1})->Args({512, 0})->Args({512, 1})->Unit(benchmark::kMillisecond);
BENCHMARK(BM_Restart)->Arg(128)->Arg(512)->Unit(benchmark::kMillisecond);

BENCHMARK_MAIN();

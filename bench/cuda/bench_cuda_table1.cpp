// Kang & Cho 2011 Table 1 on the GPU (issue 17): HO (velocity variant), RK4 and symplectic Euler steps of the
// CUDA backend on the six Table 1 grids (kang_cho_table1 stencil, hanging, k = 2000), double
// and float, beside the paper's GTX 590 frame rates; and a Baraff-Witkin step of the hanging
// wool (gnatv, cusparse_pcg) at 32^2, 64^2, 128^2, 256^2 and 512^2. Built by nvcc against the real module
// (bench/cuda/CMakeLists.txt: target table1_gpu, with -DLOOM_GPU_TESTS=ON); it needs a GPU.
//
// The state stays on the device (host_sync_every far beyond the run); every iteration is one
// step followed by a device synchronisation, so a step's time includes its launch latency.
// Counters: fps (steps per second), paper_fps, ratio = fps / paper_fps, bytes (modelled bytes
// a step moves to and from device memory, below), GB/s = bytes x fps, bw_frac = GB/s / the
// device's copy bandwidth measured in the same run (BM_DeviceCopy: a 2 x 256 MB device-to-
// device copy, best of 10; it reads and writes, 16 bytes per double).
//
// Modelled traffic (T = scalar bytes, S springs, N vertices; every array element touched once
// per kernel, gathers of x/v assumed cached):
//   HO   spring kernel: i, j (8), l0, kx, kv (3T), x, v of both ends (counted per vertex), the
//        impulse written (3T); vertex kernel: incidence (4 + 2 x 5 per spring), impulses read
//        (2 x 3T per spring), w (T), x and v read and written (12T):
//        S (18 + 12T) + N (4 + 13T) + N 6T (the spring kernel's reads of x and v)
//   RK4  4 force passes of S (18 + 12T) + N (4 + 9T) (springs as above, v also read, f written)
//        + 4 stage passes over w, f, x, v, xs, vs, ax, av (read and written): 4 N 40T
//   SE   1 force pass as in RK4, S (18 + 12T) + N (4 + 9T), + 1 vertex pass: w (T), f (3T), x and v
//        read and written (12T): N 16T
//
//   bash .gpu/run.sh table1_gpu --benchmark_repetitions=3 --benchmark_report_aggregates_only=true
#include <benchmark/benchmark.h>

#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstdlib>
#include <filesystem>
#include <fstream>
#include <memory>
#include <sstream>
#include <stdexcept>
#include <string>
#include <vector>

#include "common/table1.hpp"
#include "cuda_integrators.hpp"
#include "device.hpp"
#include "device_pcg.hpp"
#include "gnatv_material.hpp"
#include "loom/mesh.hpp"
#include "loom/params.hpp"
#include "loom/scene.hpp"
#include "mass_spring.hpp"
#include "seam.hpp"

using namespace loom;
namespace lc = loom::cuda;

namespace {

/// The repository's data and materials: $LOOM_SOURCE_ROOT, else the working directory when it
/// holds data/ (the GPU check runs from the repository root), else the build's source dir.
std::string source_root() {
  if (const char* e = std::getenv("LOOM_SOURCE_ROOT")) return e;
  if (std::filesystem::exists("data/table1_kang_cho2011.csv")) return ".";
  return LOOM_SOURCE_DIR;
}

using Row = loom_bench::Table1Row;

const std::vector<Row>& rows() {
  static const std::vector<Row> r =
      loom_bench::read_table1(source_root(), " (set LOOM_SOURCE_ROOT to the repository)");
  return r;
}

/// Device-to-device copy bandwidth (bytes read + written per second), best of 10.
double copy_bandwidth() {
  static double best = 0;
  if (best > 0) return best;
  const std::size_t m = 32u << 20;  // 32 Mi doubles = 256 MB per array
  lc::DVec<double> a(m, 1.0), b(m, 0.0);
  lc::seam_synchronize();
  for (int it = 0; it < 11; ++it) {
    const auto t0 = std::chrono::steady_clock::now();
    thrust::copy(thrust::device, a.begin(), a.end(), b.begin());
    lc::seam_synchronize();
    const double s = std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
    if (it > 0) best = std::max(best, 16.0 * m / s);
  }
  return best;
}

std::unique_ptr<Scene> table1_scene(int n) {
  auto sc = std::make_unique<Scene>();
  loom_bench::table1_cloth(*sc, n, "table1_gpu");
  return sc;
}

double ho_bytes(double T, double N, double S) { return S * (18 + 12 * T) + N * (4 + 13 * T) + N * 6 * T; }
double rk4_bytes(double T, double N, double S) { return 4 * (S * (18 + 12 * T) + N * (4 + 9 * T)) + 4 * N * 40 * T; }
double se_bytes(double T, double N, double S) { return S * (18 + 12 * T) + N * (4 + 9 * T) + N * 16 * T; }

void set_counters(benchmark::State& st, const Row& r, double springs, double bytes) {
  loom_bench::set_table1_counters(st, r, bytes, copy_bandwidth());
  st.counters["springs"] = springs;
}

constexpr int kNoSync = 1 << 30;  // never copy the state back during the run

void BM_DeviceCopy(benchmark::State& st) {
  const std::size_t m = 32u << 20;
  lc::DVec<double> a(m, 1.0), b(m, 0.0);
  for (auto _ : st) {
    thrust::copy(thrust::device, a.begin(), a.end(), b.begin());
    lc::seam_synchronize();
  }
  st.counters["GB/s"] = benchmark::Counter(16.0 * m * st.iterations() * 1e-9, benchmark::Counter::kIsRate);
  st.counters["best_GB/s"] = copy_bandwidth() * 1e-9;
}

enum StepKind { kHo = 0, kRk4 = 1, kSe = 2 };

template <int Kind>
void BM_Step(benchmark::State& st) {
  const Row& r = rows()[st.range(0)];
  const bool fl = st.range(1) != 0;
  const lc::Precision prec = fl ? lc::Precision::Float : lc::Precision::Double;
  auto sc = table1_scene(r.n);
  const double S = static_cast<double>(sc->material->springs()->size());
  auto integ = Kind == kRk4  ? lc::make_cuda_rk4(prec, kNoSync)
               : Kind == kSe ? lc::make_cuda_symplectic_euler(prec, kNoSync)
                             : lc::make_cuda_ho(lc::HoVariantD::Velocity, prec, kNoSync);
  const double h = 1e-6;
  integ->prepare(*sc, h);
  for (int k = 0; k < 3; ++k) integ->step(*sc, h);  // warm-up
  lc::seam_synchronize();
  for (auto _ : st) {
    integ->step(*sc, h);
    lc::seam_synchronize();
  }
  const double T = fl ? 4 : 8, N = static_cast<double>(sc->state.size());
  set_counters(st, r, S, Kind == kRk4 ? rk4_bytes(T, N, S) : Kind == kSe ? se_bytes(T, N, S) : ho_bytes(T, N, S));
}

void rows_args(benchmark::internal::Benchmark* b) {
  for (int r = 0; r < static_cast<int>(rows().size()); ++r)
    for (int f : {0, 1}) b->Args({r, f});
  b->ArgNames({"row", "float"})->Unit(benchmark::kMicrosecond)->UseRealTime();
}

// Baraff-Witkin, hanging wool (as bench/baraff_witkin: 10 m, top corners pinned, h = 0.01,
// Kang-Cho damping 0.01), cusparse_pcg at 1e-5; the CPU's numbers are bw_step/wool<n>/* of
// bench_baraff_witkin.
void BM_CudaBwWool(benchmark::State& st) {
  const int n = static_cast<int>(st.range(0));
  const bool fl = st.range(1) != 0;
  auto sc = std::make_unique<Scene>();
  sc->source = "table1_gpu";
  sc->mesh = make_grid(n, n, 10.0, 10.0, GridPlane::XY);
  sc->material = std::make_unique<gnatv::GnatvMaterial>(
      Params::from_string("material_file: " + source_root() + "/materials/wool.yaml\n", "<bench>"), sc->mesh);
  State& s = sc->state;
  s.resize(sc->mesh.num_vertices());
  s.x = sc->mesh.positions;
  sc->material->compute_masses(s.mass);
  s.pin((n - 1) * n);
  s.pin(n * n - 1);
  s.update_inverse_masses();
  sc->gravity = {0, -9.81, 0};
  lc::PcgOptions po;
  po.tolerance = 1e-5;
  // Block-Jacobi PCG needs more than the default 1000 iterations from 512^2 on (767 at 256^2
  // on an H200, 2026-11-30): a cap that no size here reaches, so the benchmark times the solve.
  po.max_iterations = 20000;
  sc->solver = std::make_unique<lc::CusparsePcg>(po);
  lc::BwOptionsD o;
  o.kang_cho_damping = 0.01;
  o.host_sync_every = kNoSync;
  auto bw = lc::make_cuda_baraff_witkin(o, fl ? lc::Precision::Float : lc::Precision::Double);
  const double h = 0.01;
  long iterations = 0, steps = 0;
  try {  // a failed solve is reported as this benchmark's error, and the others still run
    bw->prepare(*sc, h);
    for (int k = 0; k < 3; ++k) bw->step(*sc, h);
    for (auto _ : st) {
      bw->step(*sc, h);
      lc::seam_synchronize();
      iterations += bw->last_step().linear_iterations;
      ++steps;
    }
  } catch (const std::exception& e) {
    st.SkipWithError(e.what());
    return;
  }
  st.counters["iters"] = static_cast<double>(iterations) / std::max(1L, steps);
  st.counters["vertices"] = n * n;
}

}  // namespace

BENCHMARK(BM_DeviceCopy)->Unit(benchmark::kMicrosecond)->UseRealTime();
BENCHMARK(BM_Step<kHo>)->Name("BM_CudaHoStep")->Apply(rows_args);
BENCHMARK(BM_Step<kRk4>)->Name("BM_CudaRk4Step")->Apply(rows_args);
BENCHMARK(BM_Step<kSe>)->Name("BM_CudaSeStep")->Apply(rows_args);
BENCHMARK(BM_CudaBwWool)
    ->ArgsProduct({{32, 64, 128, 256, 512}, {0, 1}})
    ->ArgNames({"n", "float"})
    ->Unit(benchmark::kMillisecond)
    ->UseRealTime();

BENCHMARK_MAIN();

// HO, symplectic Euler and RK4 steps on the Kang & Cho 2011 Table 1 grids (kang_cho_table1
// stencil), double and float, 1 and 2 threads, beside the paper's GTX 590 frame rates (one step
// per frame). SE and RK4 run the fused spring path (loom/explicit_springs.hpp) that the plugins
// take for spring materials. *_shuffled: the same cloth with its vertices numbered in a random
// order, HO with reorder none (gathers all over memory) and rcm (loom/vertex_order.hpp).
//
// Counters: fps (steps per second), paper_fps, ratio = fps / paper_fps, bytes (modelled bytes a
// step moves to and from memory), GB/s = bytes x fps, bw_frac = GB/s / triad bandwidth of this
// machine with the same thread count (measured at start-up, best of 5, 3 x 128 MB arrays).
//
//   OMP_PROC_BIND=close OMP_PLACES=cores build/bin/table1 --benchmark_repetitions=3
//     --benchmark_report_aggregates_only=true --benchmark_min_time=0.3
#include <benchmark/benchmark.h>

#include <omp.h>

#include <algorithm>
#include <array>
#include <chrono>
#include <cmath>
#include <fstream>
#include <map>
#include <numeric>
#include <random>
#include <memory>
#include <sstream>
#include <stdexcept>
#include <string>
#include <type_traits>
#include <vector>

#include "common/table1.hpp"
#include "ho_integrator.hpp"
#include "loom/explicit_springs.hpp"
#include "loom/vertex_order.hpp"
#include "loom/kernels/spring.hpp"
#include "loom/kernels/sqrt_recip_avx512.hpp"
#include "loom/mesh.hpp"
#include "loom/params.hpp"
#include "mass_spring.hpp"
#include "rk4_integrator.hpp"

using namespace loom;

namespace {

using Row = loom_bench::Table1Row;

const std::vector<Row>& rows() {
  static const std::vector<Row> r = loom_bench::read_table1(LOOM_SOURCE_DIR);
  return r;
}

// STREAM-like triad a = b + s c, 24 bytes per element, best of 5.
double triad_bandwidth(int threads) {
  static std::map<int, double> cache;
  if (cache.count(threads)) return cache[threads];
  const std::size_t m = 16u << 20;   // 16 Mi doubles = 128 MB per array
  std::vector<double> a(m), b(m, 1.0), c(m, 2.0);
  omp_set_num_threads(threads);
  double best = 0;
  for (int it = 0; it < 6; ++it) {
    const auto t0 = std::chrono::steady_clock::now();
#pragma omp parallel for schedule(static)
    for (std::size_t q = 0; q < m; ++q) a[q] = b[q] + 3.0 * c[q];
    const double s = std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
    if (it > 0) best = std::max(best, 24.0 * m / s);
  }
  benchmark::DoNotOptimize(a.data());
  return cache[threads] = best;
}

// Block sizes of the grouped sweeps' A/B rows (*_block64, *_block128, *_block256).
constexpr Index kGroupBlocks[3] = {64, 128, 256};

// One Table 1 cloth: 336 x 336 etc., hanging (plane xy), top corners pinned, k = 2000,
// density 0.1, HO velocity variant. Built once per size.
struct Cloth {
  int n = 0;
  Scene scene;
  std::vector<double> x0;
  HoIntegrator ho{HoVariant::Velocity};
  HoIntegrator ho_direct{HoVariant::Velocity, false};   // per-spring constants (no tables)
  HoIntegrator ho_table{HoVariant::Velocity};           // parameter tables on the window (the old default)
  HoIntegrator ho_nomerge{HoVariant::Velocity};         // every spring (merge_springs: false; twin segments)
  double h = 1e-6;
  // float copies
  HoSprings<float> fs;
  std::vector<float> fx, fv, fw, fdv, fx0;
  // the fused spring path (symplectic Euler, RK4)
  SpringSweep<double> sweep;          // grouped and windowed when it pays (the plugins' default)
  SpringSweep<float> fsweep;
  SpringSweep<double> sweep_plain;    // one spring at a time (build(..., false))
  SpringSweep<double> sweep_nomerge;  // the default sweep without merging duplicate springs (twin segments)
  SpringSweep<float> fsweep_plain;
  // the grouped sweeps with blocks of 64 (the default), 128 and 256 vertices (kGroupBlocks), for
  // A/B runs of the block size
  SpringSweep<double> sweep_blk[3];
  SpringLayout ho_blk_layout[3];
  HoSprings<double> ho_blk[3];
  Index springs() const { return ho.springs().size(); }
};

Cloth& cloth(int n, const std::string& stencil = "kang_cho_table1") {
  static std::unique_ptr<Cloth> c;
  static std::string c_stencil;
  if (c && c->n == n && c_stencil == stencil) return *c;
  c.reset();
  c = std::make_unique<Cloth>();
  c->n = n;
  c_stencil = stencil;
  Scene& sc = c->scene;
  loom_bench::table1_cloth(sc, n, "table1", stencil);
  c->x0 = sc.state.x;
  c->ho.prepare(sc, c->h);
  c->ho_direct.prepare(sc, c->h);
  c->ho_table.set_tables_on_window(true);
  c->ho_table.prepare(sc, c->h);
  c->ho_nomerge.set_merge_springs(false);
  c->ho_nomerge.prepare(sc, c->h);
  const HoSprings<double>& d = c->ho.springs();
  convert_ho_springs(d, c->fs);
  c->fx.assign(sc.state.x.begin(), sc.state.x.end());
  c->fx0 = c->fx;
  c->fv.assign(sc.state.x.size(), 0.f);
  c->fdv.assign(sc.state.x.size(), 0.f);
  c->fw.assign(sc.state.inv_mass.begin(), sc.state.inv_mass.end());
  update_ho_coefficients(c->fs, HoVariant::Velocity, c->fw.data(), static_cast<float>(c->h));
  c->sweep.build(sc.state.size(), *sc.material->springs());
  c->fsweep.convert_from(c->sweep);
  c->sweep_plain.build(sc.state.size(), *sc.material->springs(), false);
  c->sweep_nomerge.merge_duplicates = false;
  c->sweep_nomerge.build(sc.state.size(), *sc.material->springs());
  c->fsweep_plain.convert_from(c->sweep_plain);
  for (int b = 0; b < 3; ++b) {
    c->sweep_blk[b].build(sc.state.size(), *sc.material->springs(), true, kGroupBlocks[b]);
    build_ho_springs(sc.state.size(), *sc.material->springs(), c->ho_blk_layout[b], c->ho_blk[b], true,
                     kGroupBlocks[b], ho_merge_mode(HoVariant::Velocity, true));
    update_ho_coefficients(c->ho_blk[b], HoVariant::Velocity, sc.state.inv_mass.data(), c->h);
  }
  return *c;
}

// Modelled memory traffic of one step (T = scalar bytes, N vertices).
//
// The spring sweeps' bytes are counted from the sweep's own structure (what the code reads and
// writes, docs/plugins/integrators.md "table1's byte model"): per interior spring its streamed
// constants (cst bytes: l0, kx, kv for HO, k, l0 (and c) for the force sweep, or HO's 2-byte
// table id), plus its two endpoint indices (8 bytes) on the plain sweep only (the grouped sweep
// reads segments instead: sizeof(SpringSegment) per segment, SpringBlock and block_need per
// block); per cross spring its indices and constants; per vertex x and v read and written
// (12 T), the inverse mass (T) and the deferred flag (1 byte), plus the 3n accumulator read and
// written (6 T) when there is no window; with the window only the deferred vertices (those cross
// springs touch) use the accumulator: written at hand-off, read and cleared at finalisation
// (12 T). Not counted: the small parameter tables and the window itself (cache resident).
template <class Sw>
double sweep_spring_bytes(const Sw& s, Index cross, double cst) {
  const double S = s.size(), C = cross;
  double b = (S - C) * (cst + (s.grouped ? 0.0 : 8.0)) + C * (8.0 + cst);
  if (s.grouped)
    b += static_cast<double>(sizeof(SpringSegment)) * static_cast<double>(s.segs.size()) +
         static_cast<double>(sizeof(SpringBlock) + sizeof(Index)) * static_cast<double>(s.blocks.size());
  return b;
}
template <class Sw>
double sweep_bytes(const Sw& s, Index cross, double T, double N, double cst) {
  const bool win = s.grouped && s.win_cap > 0;
  return sweep_spring_bytes(s, cross, cst) + N * (13.0 * T + 1.0 + (win ? 0.0 : 6.0 * T)) +
         (win ? 12.0 * T * static_cast<double>(s.deferred.size()) : 0.0);
}
template <class T>
double ho_bytes(const HoSprings<T>& s, const SpringLayout& layout, double N) {
  const double t = sizeof(T);
  return sweep_bytes(s, layout.num_cross(), t, N, s.table ? 2.0 : 3.0 * t);
}
template <class T>
double se_bytes(const SpringSweep<T>& s) {
  const double t = sizeof(T);
  return sweep_bytes(s, s.layout.num_cross(), t, s.n, (s.damped() ? 3.0 : 2.0) * t);
}
double rk4_bytes(double T, double N, double S) {
  // 4 force passes (springs: i, j, k, l0; x, v read, f written) + 4 stage passes over x0, v0,
  // xs, vs, f, accumulators
  return 4 * ((8 + 2 * T) * S + N * 9 * T) + 4 * N * 3 * T * 7;
}
template <class T>
double rk4_fused_bytes(const SpringSweep<T>& s) {
  // 4 passes; each: the sweep's spring data (sweep_spring_bytes) and per vertex x0, v0 read, xs,
  // vs and the two accumulators read and written, f read and written, inverse mass
  const double t = sizeof(T), N = s.n;
  const double springs = sweep_spring_bytes(s, s.layout.num_cross(), (s.damped() ? 3.0 : 2.0) * t);
  return 4 * (springs + N * (6 * t + 12 * t + 12 * t + 6 * t + t));
}

void set_counters(benchmark::State& st, const Row& r, int threads, double bytes) {
  loom_bench::set_table1_counters(st, r, bytes, triad_bandwidth(threads));
  st.counters["paper_springs"] = r.springs;
}

// The HO rows' start: the row and thread count from the arguments, the triad measured for that
// count, the row's cloth at rest at its start positions.
struct HoRun {
  const Row& r;
  int threads;
  Cloth& c;
};
HoRun start_ho_run(benchmark::State& st, const std::string& stencil = "kang_cho_table1") {
  const Row& r = rows()[st.range(0)];
  const int threads = static_cast<int>(st.range(1));
  triad_bandwidth(threads);
  Cloth& c = cloth(r.n, stencil);
  omp_set_num_threads(threads);
  c.scene.state.x = c.x0;
  std::fill(c.scene.state.v.begin(), c.scene.state.v.end(), 0.0);
  return {r, threads, c};
}

void BM_HoStep_double(benchmark::State& st) {
  auto [r, threads, c] = start_ho_run(st);
  for (auto _ : st) c.ho.step(c.scene, c.h);
  set_counters(st, r, threads, ho_bytes(c.ho.springs(), c.ho.layout(), c.scene.state.size()));
  st.counters["springs"] = c.springs();
  st.counters["table"] = c.ho.springs().table ? static_cast<double>(c.ho.springs().t_l0.size()) : 0.0;
}

// The "every grid neighbour within radius sqrt(5)" stencil: 10n^2 - 22n + 10 springs, 0.25%
// fewer than the paper's counts (printed beside them: springs vs paper_springs).
void BM_HoStep_double_sqrt5(benchmark::State& st) {
  auto [r, threads, c] = start_ho_run(st, "radius_sqrt5");
  for (auto _ : st) c.ho.step(c.scene, c.h);
  set_counters(st, r, threads, ho_bytes(c.ho.springs(), c.ho.layout(), c.scene.state.size()));
  st.counters["springs"] = c.springs();
}

// Every spring stepped on its own (merge_springs: false): duplicates paired as twin segments,
// the default until 2026-12-01.
void BM_HoStep_double_nomerge(benchmark::State& st) {
  auto [r, threads, c] = start_ho_run(st);
  for (auto _ : st) c.ho_nomerge.step(c.scene, c.h);
  set_counters(st, r, threads, ho_bytes(c.ho_nomerge.springs(), c.ho_nomerge.layout(), c.scene.state.size()));
  st.counters["springs"] = static_cast<double>(c.ho_nomerge.springs().size());
}

void BM_HoStep_double_direct(benchmark::State& st) {
  auto [r, threads, c] = start_ho_run(st);
  for (auto _ : st) c.ho_direct.step(c.scene, c.h);
  set_counters(st, r, threads, ho_bytes(c.ho_direct.springs(), c.ho_direct.layout(), c.scene.state.size()));
}

// The parameter tables kept on the windowed sweep (HoIntegrator::set_tables_on_window): 2 bytes
// per spring and a table gather per spring, the default before per-spring streams.
void BM_HoStep_double_table(benchmark::State& st) {
  auto [r, threads, c] = start_ho_run(st);
  for (auto _ : st) c.ho_table.step(c.scene, c.h);
  set_counters(st, r, threads, ho_bytes(c.ho_table.springs(), c.ho_table.layout(), c.scene.state.size()));
  st.counters["table"] = c.ho_table.springs().table ? static_cast<double>(c.ho_table.springs().t_l0.size()) : 0.0;
}

// A/B of the windowed grouped sweep (ho_window.hpp): the HO step on raw arrays (the plugin's
// step without pins and clock), window on (the default) and off (the plain grouped sweep, what
// the step ran before). Same springs, same cloth, interleave them with --benchmark_repetitions.
// blk >= 0: the springs grouped with blocks of kGroupBlocks[blk] vertices.
void ho_window_bench(benchmark::State& st, bool window, int blk = -1, bool fuse = true, bool twins = true) {
  const Row& r = rows()[st.range(0)];
  const int threads = static_cast<int>(st.range(1));
  triad_bandwidth(threads);
  Cloth& c = cloth(r.n);
  omp_set_num_threads(threads);
  // the twin rows compare twin segments with their segments on their own: the unmerged springs
  const HoIntegrator& ho = twins ? c.ho : c.ho_nomerge;
  HoSprings<double> s = blk >= 0 ? c.ho_blk[blk] : ho.springs();
  const SpringLayout& layout = blk >= 0 ? c.ho_blk_layout[blk] : ho.layout();
  if (!window) s.win_cap = 0;
  s.fuse = fuse;
  s.twins = twins;
  st.counters["window"] = static_cast<double>(s.win_cap);
  // the grouped structure: segments, springs left over after whole groups of 4 (the vector
  // loops' scalar remainders), segments with stride 2, and segments without one shared id
  // and the unit-stride segments with disjoint lower and upper ranges (one pass when fused)
  double tail = 0, step2 = 0, mixed = 0, disjoint = 0, twin_springs = 0;
  for (std::size_t g = 0; g < s.segs.size(); ++g) {
    twin_springs += s.segs[g].twin ? 2.0 * s.segs[g].len : 0.0;   // springs in twin pairs
    tail += static_cast<double>(s.segs[g].len % 4);
    step2 += s.segs[g].step == 2 ? 1 : 0;
    disjoint += s.segs[g].step == 1 && s.segs[g].off >= s.segs[g].len ? 1 : 0;
  }
  st.counters["disjoint_segs"] = disjoint;
  st.counters["segs"] = static_cast<double>(s.segs.size());
  st.counters["tail_springs"] = tail;
  st.counters["step2_segs"] = step2;
  st.counters["twin_springs"] = twin_springs;
  // with the parameter tables: segments whose springs do not share one id, or kx and kv
  double kmixed = 0, l0_float_delta_ok = 0;
  const HoSprings<double>& t = c.ho_table.springs();
  if (t.table)
    for (const auto& G : t.segs) {
      bool same = true, fits = true, one = true;
      const double base = t.t_l0[t.id[G.begin]];
      for (Index r = 0; r < G.len; ++r) {
        const std::size_t id = t.id[G.begin + r], id0 = t.id[G.begin];
        one = one && id == id0;
        same = same && t.t_kx[id] == t.t_kx[id0] && t.t_kv[id] == t.t_kv[id0];
        const double d = t.t_l0[id] - base;
        fits = fits && static_cast<double>(static_cast<float>(d)) == d && base + d == t.t_l0[id];
      }
      mixed += one ? 0 : 1;
      kmixed += same ? 0 : 1;
      l0_float_delta_ok += fits ? 1 : 0;
    }
  st.counters["mixed_segs"] = mixed;
  st.counters["k_mixed_segs"] = kmixed;
  st.counters["l0_delta_ok_segs"] = l0_float_delta_ok;
  std::vector<double> x = c.x0, v(x.size(), 0.0), dv(x.size(), 0.0);
  const std::array<double, 3> g{0.0, -9.81, 0.0};
  for (auto _ : st)
    ho_step_arrays<double, HoVariant::Velocity>(layout, s, x.data(), v.data(), dv.data(), nullptr,
                                                c.scene.state.inv_mass.data(), c.h, g);
  set_counters(st, r, threads, ho_bytes(s, layout, c.scene.state.size()));
}
void BM_HoStep_double_window(benchmark::State& st) { ho_window_bench(st, true); }
void BM_HoStep_double_nowindow(benchmark::State& st) { ho_window_bench(st, false); }
void BM_HoStep_double_block64(benchmark::State& st) { ho_window_bench(st, true, 0); }
void BM_HoStep_double_block128(benchmark::State& st) { ho_window_bench(st, true, 1); }
void BM_HoStep_double_block256(benchmark::State& st) { ho_window_bench(st, true, 2); }
// The windowed sweep with two passes (impulses, then scatter) for every segment (issue 16's A/B).
void BM_HoStep_double_unfused(benchmark::State& st) { ho_window_bench(st, true, -1, false); }
// The windowed sweep with each segment of a twin pair on its own (HoSprings::twins = false).
void BM_HoStep_double_notwin(benchmark::State& st) { ho_window_bench(st, true, -1, true, false); }

void BM_HoStep_float(benchmark::State& st) {
  const Row& r = rows()[st.range(0)];
  const int threads = static_cast<int>(st.range(1));
  triad_bandwidth(threads);
  Cloth& c = cloth(r.n);
  omp_set_num_threads(threads);
  c.fx = c.fx0;
  std::fill(c.fv.begin(), c.fv.end(), 0.f);
  const std::array<float, 3> g{0.f, -9.81f, 0.f};
  for (auto _ : st)
    ho_step_arrays<float, HoVariant::Velocity>(c.ho.layout(), c.fs, c.fx.data(), c.fv.data(), c.fdv.data(),
                                               nullptr, c.fw.data(), static_cast<float>(c.h), g);
  set_counters(st, r, threads, ho_bytes(c.fs, c.ho.layout(), c.scene.state.size()));
}

void BM_Rk4Step_double(benchmark::State& st) {
  const Row& r = rows()[st.range(0)];
  const int threads = static_cast<int>(st.range(1));
  triad_bandwidth(threads);
  Cloth& c = cloth(r.n);
  omp_set_num_threads(threads);
  c.scene.state.x = c.x0;
  std::fill(c.scene.state.v.begin(), c.scene.state.v.end(), 0.0);
  Rk4Integrator rk;
  rk.prepare(c.scene, c.h);
  for (auto _ : st) rk.step(c.scene, c.h);   // the plugin: the fused spring path
  set_counters(st, r, threads, rk4_fused_bytes(c.sweep));
}

// RK4 in float through rk4_step_arrays (a force pass, then a stage loop: two regions per stage).
void BM_Rk4Step_float(benchmark::State& st) {
  const Row& r = rows()[st.range(0)];
  const int threads = static_cast<int>(st.range(1));
  triad_bandwidth(threads);
  Cloth& c = cloth(r.n);
  omp_set_num_threads(threads);
  const std::size_t m = c.fx.size();
  const Index n = static_cast<Index>(m / 3);
  std::vector<float> x = c.fx0, v(m, 0.f), xs(m), vs(m), f(m), ax(m), av(m);
  const std::array<float, 3> g{0.f, -9.81f, 0.f};
  const SpringLayout& layout = c.ho.layout();
  const Index* I = c.fs.i.data();
  const Index* J = c.fs.j.data();
  const float* K = c.fs.k.data();
  const float* L0 = c.fs.l0.data();
  auto force = [&](const float* X, const float*, float* F) {
    layout.for_each([F](Index v0, Index v1) { std::fill(F + 3 * static_cast<std::size_t>(v0), F + 3 * static_cast<std::size_t>(v1), 0.f); },
                    [=](Index s) {
                      const Index a = I[s], b = J[s];
                      float fi[3];
                      kernels::spring_force(X + 3 * a, X + 3 * b, K[s], L0[s], fi);
                      for (int e = 0; e < 3; ++e) {
                        F[3 * a + e] += fi[e];
                        F[3 * b + e] -= fi[e];
                      }
                    });
  };
  for (auto _ : st)
    rk4_step_arrays<float>(n, x.data(), v.data(), c.fw.data(), g, static_cast<float>(c.h), xs.data(), vs.data(),
                           f.data(), ax.data(), av.data(), force);
  set_counters(st, r, threads, rk4_bytes(4, n, c.springs()));
}

// kind 0: the default sweep (grouped and windowed, loom/spring_groups.hpp), 1: plain (one spring
// at a time, what the step ran before), 2: blocked (plain order, forces of 128 springs by one loop),
// 3 + b: grouped and windowed with blocks of kGroupBlocks[b] vertices; 6: the default sweep with
// two passes (forces, then scatter) for every segment (SpringSweep::fuse = false); 7: the default
// sweep without merging duplicate springs and with each segment of a twin pair on its own
// (SpringSweep::merge_duplicates = false, twins = false); 8: the default sweep with each vertex
// finalised on its own (SpringSweep::block_finalise = false); 9: the sweep without merging
// duplicate springs, their segments paired as twins (the default until 2026-12-01).
template <class T>
void se_bench(benchmark::State& st, bool /*is_float*/, int kind = 0) {
  const Row& r = rows()[st.range(0)];
  const int threads = static_cast<int>(st.range(1));
  triad_bandwidth(threads);
  Cloth& c = cloth(r.n);
  omp_set_num_threads(threads);
  const std::size_t m = c.scene.state.x.size();
  std::vector<T> x(c.x0.begin(), c.x0.end()), v(m, T(0)), f(m, T(0));
  std::vector<T> w(c.scene.state.inv_mass.begin(), c.scene.state.inv_mass.end());
  const T g[3] = {T(0), T(-9.81), T(0)};
  SpringSweep<T>* sw = nullptr;
  if constexpr (std::is_same_v<T, float>) sw = kind == 0 ? &c.fsweep : &c.fsweep_plain;
  else if (kind == 7 || kind == 9) sw = &c.sweep_nomerge;
  else sw = kind == 0 || kind >= 6 ? &c.sweep : (kind >= 3 ? &c.sweep_blk[kind - 3] : &c.sweep_plain);
  sw->blocked = kind == 2;
  sw->fuse = kind != 6;
  sw->twins = kind != 7;
  sw->block_finalise = kind != 8;
  st.counters["window"] = static_cast<double>(sw->win_cap);
  st.counters["segs"] = static_cast<double>(sw->segs.size());
  st.counters["sweep_springs"] = static_cast<double>(sw->size());
  for (auto _ : st) se_step_springs<T>(*sw, x.data(), v.data(), w.data(), f.data(), static_cast<T>(c.h), g);
  sw->blocked = false;
  sw->fuse = true;
  sw->twins = true;
  sw->block_finalise = true;
  benchmark::DoNotOptimize(x.data());
  set_counters(st, r, threads, se_bytes(*sw));
}
void BM_SeStep_double(benchmark::State& st) { se_bench<double>(st, false); }
void BM_SeStep_float(benchmark::State& st) { se_bench<float>(st, true); }
void BM_SeStep_double_plain(benchmark::State& st) { se_bench<double>(st, false, 1); }
void BM_SeStep_float_plain(benchmark::State& st) { se_bench<float>(st, true, 1); }
// The blocked sweep (forces of 128 springs by one `omp simd` loop, then scattered).
void BM_SeStep_double_blocked(benchmark::State& st) { se_bench<double>(st, false, 2); }
void BM_SeStep_float_blocked(benchmark::State& st) { se_bench<float>(st, true, 2); }
void BM_SeStep_double_block64(benchmark::State& st) { se_bench<double>(st, false, 3); }
void BM_SeStep_double_block128(benchmark::State& st) { se_bench<double>(st, false, 4); }
void BM_SeStep_double_block256(benchmark::State& st) { se_bench<double>(st, false, 5); }
void BM_SeStep_double_unfused(benchmark::State& st) { se_bench<double>(st, false, 6); }
void BM_SeStep_double_notwin(benchmark::State& st) { se_bench<double>(st, false, 7); }
void BM_SeStep_double_scalarfin(benchmark::State& st) { se_bench<double>(st, false, 8); }
void BM_SeStep_double_nomerge(benchmark::State& st) { se_bench<double>(st, false, 9); }

template <class T>
void rk4_fused_bench(benchmark::State& st, bool /*is_float*/, bool plain = false, bool nomerge = false) {
  const Row& r = rows()[st.range(0)];
  const int threads = static_cast<int>(st.range(1));
  triad_bandwidth(threads);
  Cloth& c = cloth(r.n);
  omp_set_num_threads(threads);
  const std::size_t m = c.scene.state.x.size();
  std::vector<T> x(c.x0.begin(), c.x0.end()), v(m, T(0)), f(m, T(0)), xs(m), vs(m), ax(m), av(m);
  std::vector<T> w(c.scene.state.inv_mass.begin(), c.scene.state.inv_mass.end());
  const std::array<T, 3> g{T(0), T(-9.81), T(0)};
  const SpringSweep<T>* sw = nullptr;
  if constexpr (std::is_same_v<T, float>) sw = plain ? &c.fsweep_plain : &c.fsweep;
  else sw = plain ? &c.sweep_plain : (nomerge ? &c.sweep_nomerge : &c.sweep);
  for (auto _ : st)
    rk4_step_springs<T>(*sw, x.data(), v.data(), w.data(), g, static_cast<T>(c.h), xs.data(), vs.data(), f.data(),
                        ax.data(), av.data(), [](int) {});
  benchmark::DoNotOptimize(x.data());
  set_counters(st, r, threads, rk4_fused_bytes(*sw));
}
void BM_Rk4Fused_double(benchmark::State& st) { rk4_fused_bench<double>(st, false); }
void BM_Rk4Fused_float(benchmark::State& st) { rk4_fused_bench<float>(st, true); }
// RK4's fused stages on the plain sweep (what they ran before the grouped, windowed sweep)
void BM_Rk4Fused_double_plain(benchmark::State& st) { rk4_fused_bench<double>(st, false, true); }
// ... and on the default sweep without merging duplicate springs (twin segments instead)
void BM_Rk4Fused_double_nomerge(benchmark::State& st) { rk4_fused_bench<double>(st, false, false, true); }

// The Table 1 cloth with its vertices numbered in a random order (fixed seed): HO with the
// mesh's order (reorder: none) and with the RCM order (reorder: rcm, which also copies x and v
// into the internal order and back every step; counted in the bytes).
struct Shuffled {
  int n = 0;
  Scene scene;
  std::vector<double> x0;
};
Shuffled& shuffled(int n) {
  static std::unique_ptr<Shuffled> c;
  if (c && c->n == n) return *c;
  c.reset();
  c = std::make_unique<Shuffled>();
  c->n = n;
  Cloth& base = cloth(n);
  const Index N = base.scene.state.size();
  std::vector<Index> pi(static_cast<std::size_t>(N));   // grid vertex g -> user vertex pi[g]
  std::iota(pi.begin(), pi.end(), 0);
  std::shuffle(pi.begin(), pi.end(), std::mt19937(12345));
  Scene& sc = c->scene;
  sc.source = "table1 shuffled";
  SpringSet set = *base.scene.material->springs();
  for (Index& a : set.i) a = pi[a];
  for (Index& b : set.j) b = pi[b];
  std::vector<double> mass(static_cast<std::size_t>(N));
  for (Index q = 0; q < N; ++q) mass[pi[q]] = base.scene.state.mass[q];
  struct SetMaterial final : Material {
    SpringSet s;
    std::vector<double> m;
    std::string name() const override { return "springs"; }
    void compute_masses(std::span<double> out) const override { std::copy(m.begin(), m.end(), out.begin()); }
    void compute_forces(std::span<const double>, std::span<const double>, std::span<double>) const override {
      throw std::logic_error("not used");
    }
    double elastic_energy(std::span<const double>) const override { return 0; }
    double max_strain(std::span<const double>) const override { return 0; }
    const SpringSet* springs() const override { return &s; }
  };
  auto mat = std::make_unique<SetMaterial>();
  mat->s = std::move(set);
  mat->m = mass;
  sc.material = std::move(mat);
  sc.state.resize(N);
  for (Index q = 0; q < N; ++q)
    for (int e = 0; e < 3; ++e) sc.state.x[3 * pi[q] + e] = base.x0[3 * q + e];
  sc.state.mass = mass;
  for (Index q = 0; q < N; ++q)
    if (base.scene.state.pinned[q]) sc.state.pin(pi[q]);
  sc.state.update_inverse_masses();
  sc.gravity = {0, -9.81, 0};
  c->x0 = sc.state.x;
  return *c;
}

void ho_shuffled(benchmark::State& st, HoReorder mode) {
  const Row& r = rows()[st.range(0)];
  const int threads = static_cast<int>(st.range(1));
  triad_bandwidth(threads);
  Shuffled& c = shuffled(r.n);
  omp_set_num_threads(threads);
  c.scene.state.x = c.x0;
  std::fill(c.scene.state.v.begin(), c.scene.state.v.end(), 0.0);
  HoIntegrator ho(HoVariant::Velocity, true, true, mode);
  const double h = 1e-6;
  ho.prepare(c.scene, h);
  for (auto _ : st) ho.step(c.scene, h);
  const double N = c.scene.state.size();
  // reorder: 2 x (read 48 + write 48) bytes per vertex for the copies in and out
  set_counters(st, r, threads, ho_bytes(ho.springs(), ho.layout(), N) + (ho.reordered() ? 192 * N : 0));
  st.counters["reordered"] = ho.reordered() ? 1 : 0;
  st.counters["span"] = mean_spring_span(ho.springs().i, ho.springs().j);
}
void BM_HoStep_shuffled_none(benchmark::State& st) { ho_shuffled(st, HoReorder::None); }
void BM_HoStep_shuffled_rcm(benchmark::State& st) { ho_shuffled(st, HoReorder::Rcm); }

// Issue 16: a floor for the symplectic Euler step on this machine. The Table 1 cloth's merged
// springs are exactly five grid offsets, (1,0), (0,1), (1,1), (-1,1) and (2,0) (561,794 springs
// at 336^2, the rows' `sweep_springs`); here their undamped step runs with the state kept in
// structure-of-arrays form for good (no window, no interleaved copies in or out) on the grid's
// own row-major numbering, every spring run a whole grid row with unit stride, the horizontal
// springs summed into their vertices in one pass, each row finalised as soon as it is complete,
// threads on contiguous bands of rows (the band's first row after the others, with the springs
// that reach it from the band before). Not a Loom code path: what the step could reach with a
// layout built for this one grid and no user-facing interleaved state. Its bytes are what it
// reads and writes: k and l0 per spring (16 B); x, v read and written, the inverse mass and a
// pin flag per vertex (the SE rows' per-vertex model, without their segment tables).
// BM_HoFloor_double: the harmonic-oscillation step the same way (velocity variant, the impulse of
// kernels::ho_spring_velocity with the constants of two interior vertices, three constants per
// spring streamed as in the sweep: 24 B). BM_SeFloor_double_aos: the SE floor with the user's
// interleaved x and v (x0 y0 z0 x1 ...) read
// into the structure of arrays before the step and written back after it, each a pass over all
// vertices (no window): an upper bound on what converting the layout costs a step.
template <bool Ho>
void step_floor(benchmark::State& st, bool aos) {
  const Row& r = rows()[st.range(0)];
  const int threads = static_cast<int>(st.range(1));
  triad_bandwidth(threads);
  omp_set_num_threads(threads);
  const Index n = r.n, N = n * n;
  if (n > 400 || n < 5) {  // the row buffers below hold 400 columns
    st.SkipWithError("the floor's row buffers hold grids of 5 to 400 columns");
    return;
  }
  const double dx = 1.0 / static_cast<double>(n - 1), h = 1e-6, g = -9.81, k = 2000.0;  // h as the SE rows
  std::vector<double> X(N), Y(N), Z(N, 0.0), VX(N, 0.0), VY(N, 0.0), VZ(N, 0.0), FX(N), FY(N), FZ(N), W(N);
  std::vector<std::uint8_t> pin(N, 0);
  for (Index i = 0; i < N; ++i) {
    X[i] = dx * static_cast<double>(i % n);
    Y[i] = -dx * static_cast<double>(i / n);
    W[i] = 1.0 / (0.1 / static_cast<double>(N));
  }
  pin[0] = pin[n - 1] = 1;
  W[0] = W[n - 1] = 0;
  // Offsets and column ranges [c0, c1) of the lower endpoint (rows 0..n-2 for the vertical ones).
  struct Off {
    Index off, c0, c1;
    bool vertical;
  };
  const Off offs[5] = {{1, 0, n - 1, false}, {2, 0, n - 2, false}, {n, 0, n, true}, {n + 1, 0, n - 1, true},
                       {n - 1, 1, n, true}};
  // HO: the impulse constants of a spring between two interior vertices (kernels/ho.hpp), every
  // spring its own copy as in the sweep; the impulse s n, s = kx (l - l0) + kv (n . (v_j - v_i)).
  const kernels::HoCoeffs<double> co = kernels::ho_coefficients<double>(k, 0.0, W[n + 1], W[n + 1], h);
  // whether vertex i is the lower endpoint of a spring of offset o
  const auto has_spring = [&](int o, Index i) {
    const Index c = i % n;
    return c >= offs[o].c0 && c < offs[o].c1 && !(offs[o].vertical && i / n >= n - 1);
  };
  std::vector<double> K[5], L[5], KV[5];
  double springs = 0;
  for (int o = 0; o < 5; ++o) {
    K[o].assign(N, Ho ? co.kx : k);
    if (Ho) KV[o].assign(N, co.kv);
    L[o].assign(N, 0.0);
    for (Index i = 0; i < N; ++i) {
      if (!has_spring(o, i)) continue;
      const Index j = i + offs[o].off;
      L[o][i] = std::sqrt((X[j] - X[i]) * (X[j] - X[i]) + (Y[j] - Y[i]) * (Y[j] - Y[i]));
      springs += 1;
    }
  }
  const int nt = threads;
  std::vector<double> border(static_cast<std::size_t>(nt) * 3 * static_cast<std::size_t>(n), 0.0);
  const auto spring_row = [&](Index row, double* __restrict bx, double* __restrict by, double* __restrict bz) {
    double* __restrict fx = FX.data();
    double* __restrict fy = FY.data();
    double* __restrict fz = FZ.data();
    const double* __restrict x = X.data();
    const double* __restrict y = Y.data();
    const double* __restrict z = Z.data();
    const double* __restrict vx = VX.data();
    const double* __restrict vy = VY.data();
    const double* __restrict vz = VZ.data();
    // The factor of d = x_q - x_p in the spring's force (SE) or impulse per unit inverse mass (HO).
    const auto scale = [&](Index p, Index q, double d0, double d1, double d2, double kx, double l0, double kvel) {
      const double l2 = d0 * d0 + d1 * d1 + d2 * d2;
      if constexpr (Ho) {
        const double l = std::sqrt(l2), inv = 1.0 / (l + std::numeric_limits<double>::min());
        const double ddot = (d0 * (vx[q] - vx[p]) + d1 * (vy[q] - vy[p]) + d2 * (vz[q] - vz[p])) * inv;
        return (kx * (l - l0) + kvel * ddot) * inv;
      } else {
        return kx * (1.0 - l0 / std::sqrt(l2 + std::numeric_limits<double>::min()));
      }
    };
    const Index a = row * n;
    // horizontal springs (offsets 1 and 2): forces into a row buffer, then one pass per vertex
    alignas(64) double g1[3][400], g2[3][400];
    for (int o = 0; o < 2; ++o) {
      double(*G)[400] = o == 0 ? g1 : g2;
      const Index off = offs[o].off, len = offs[o].c1;
      const double* __restrict kk = K[o].data() + a;
      const double* __restrict ll = L[o].data() + a;
      const double* __restrict kv = Ho ? KV[o].data() + a : kk;
#pragma omp simd
      for (Index c = 0; c < len; ++c) {
        const Index p = a + c, q = p + off;
        const double d0 = x[q] - x[p], d1 = y[q] - y[p], d2 = z[q] - z[p];
        const double sc = scale(p, q, d0, d1, d2, kk[c], ll[c], kv[c]);
        G[0][c] = sc * d0;
        G[1][c] = sc * d1;
        G[2][c] = sc * d2;
      }
    }
    for (int e = 0; e < 3; ++e) {
      double* __restrict f = e == 0 ? fx : (e == 1 ? fy : fz);
      f[a] += g1[e][0] + g2[e][0];
      f[a + 1] += g1[e][1] - g1[e][0] + g2[e][1];
#pragma omp simd
      for (Index c = 2; c < n - 2; ++c) f[a + c] += g1[e][c] - g1[e][c - 1] + g2[e][c] - g2[e][c - 2];
      f[a + n - 2] += g1[e][n - 2] - g1[e][n - 3] - g2[e][n - 4];
      f[a + n - 1] += -g1[e][n - 2] - g2[e][n - 3];
    }
    if (row == n - 1) return;
    // vertical and diagonal springs: disjoint ranges (rows row and row + 1), fused force and scatter;
    // bx, by, bz: where row + 1's share goes (the band's last row: the next band's buffer)
    for (int o = 2; o < 5; ++o) {
      const Index off = offs[o].off, c0 = offs[o].c0, c1 = offs[o].c1;
      const double* __restrict kk = K[o].data() + a;
      const double* __restrict ll = L[o].data() + a;
      const double* __restrict kv = Ho ? KV[o].data() + a : kk;
      const Index shift = off - n;  // column of the upper endpoint = c + shift
#pragma omp simd
      for (Index c = c0; c < c1; ++c) {
        const Index p = a + c, q = p + off;
        const double d0 = x[q] - x[p], d1 = y[q] - y[p], d2 = z[q] - z[p];
        const double sc = scale(p, q, d0, d1, d2, kk[c], ll[c], kv[c]);
        fx[p] += sc * d0;
        fy[p] += sc * d1;
        fz[p] += sc * d2;
        bx[c + shift] -= sc * d0;
        by[c + shift] -= sc * d1;
        bz[c + shift] -= sc * d2;
      }
    }
  };
  const auto finalise_row = [&](Index row) {
    const Index a = row * n;
#pragma omp simd
    for (Index c = 0; c < n; ++c) {
      const Index i = a + c;
      const double fr = pin[i] ? 0.0 : 1.0;
      if constexpr (Ho) {  // F: impulses per unit inverse mass
        VX[i] += W[i] * FX[i];
        VY[i] += W[i] * FY[i] + h * fr * g;
        VZ[i] += W[i] * FZ[i];
      } else {
        VX[i] += h * W[i] * FX[i];
        VY[i] += h * (W[i] * FY[i] + fr * g);
        VZ[i] += h * W[i] * FZ[i];
      }
      X[i] += h * VX[i];
      Y[i] += h * VY[i];
      Z[i] += h * VZ[i];
      FX[i] = FY[i] = FZ[i] = 0.0;
    }
  };
  const auto step = [&] {
#pragma omp parallel num_threads(nt)
    {
      const int t = omp_get_thread_num();
      const Index r0 = n * t / nt, r1 = n * (t + 1) / nt;
      double* nb = border.data() + static_cast<std::size_t>((t + 1) % nt) * 3 * static_cast<std::size_t>(n);
      for (Index row = r0; row < r1; ++row) {
        const bool last = row == r1 - 1 && t + 1 < nt;
        const Index up = (row + 1) * n;
        spring_row(row, last ? nb : FX.data() + up, last ? nb + n : FY.data() + up, last ? nb + 2 * n : FZ.data() + up);
        if (row > r0 || t == 0) finalise_row(row);
      }
#pragma omp barrier
      if (t > 0) {
        double* mb = border.data() + static_cast<std::size_t>(t) * 3 * static_cast<std::size_t>(n);
        const Index a = r0 * n;
        for (Index c = 0; c < n; ++c) {
          FX[a + c] += mb[c];
          FY[a + c] += mb[n + c];
          FZ[a + c] += mb[2 * n + c];
          mb[c] = mb[n + c] = mb[2 * n + c] = 0.0;
        }
        finalise_row(r0);
      }
    }
  };
  // The floor computes the step: 20 steps from a rippled state against a plain loop over the
  // springs (forces summed per spring, then v += h (w f + g), x += h v); counter check_dx, the
  // largest difference of a position (m), a few roundings of the positions (about 1) at most.
  {
    std::mt19937_64 rng(5);
    std::uniform_real_distribution<double> u(-0.2 * dx, 0.2 * dx);
    for (Index i = 0; i < N; ++i)
      if (!pin[i]) Z[i] = u(rng);
    std::vector<double> x(3 * N), v(3 * N, 0.0), f(3 * N);
    for (Index i = 0; i < N; ++i) x[3 * i] = X[i], x[3 * i + 1] = Y[i], x[3 * i + 2] = Z[i];
    for (int it = 0; it < 20; ++it) {
      step();
      std::fill(f.begin(), f.end(), 0.0);
      for (int o = 0; o < 5; ++o)
        for (Index i = 0; i < N; ++i) {
          if (!has_spring(o, i)) continue;
          const Index j = i + offs[o].off;
          double d[3], l2 = 0;
          for (int e = 0; e < 3; ++e) d[e] = x[3 * j + e] - x[3 * i + e], l2 += d[e] * d[e];
          const double l = std::sqrt(l2);
          double gi[3];
          if (Ho) {  // kernels::ho_spring_velocity's impulse
            double nn[3], ddot = 0;
            for (int e = 0; e < 3; ++e) nn[e] = d[e] / l, ddot += nn[e] * (v[3 * j + e] - v[3 * i + e]);
            for (int e = 0; e < 3; ++e) gi[e] = (co.kx * (l - L[o][i]) + co.kv * ddot) * nn[e];
          } else {
            for (int e = 0; e < 3; ++e) gi[e] = k * (l - L[o][i]) * d[e] / l;
          }
          for (int e = 0; e < 3; ++e) f[3 * i + e] += gi[e], f[3 * j + e] -= gi[e];
        }
      for (Index i = 0; i < 3 * N; ++i) {
        const double grav = i % 3 == 1 && !pin[i / 3] ? g : 0.0;
        v[i] += Ho ? W[i / 3] * f[i] + h * grav : h * (W[i / 3] * f[i] + grav);
        x[i] += h * v[i];
      }
    }
    double worst = 0;
    for (Index i = 0; i < N; ++i)
      worst = std::max({worst, std::abs(X[i] - x[3 * i]), std::abs(Y[i] - x[3 * i + 1]), std::abs(Z[i] - x[3 * i + 2])});
    st.counters["check_dx"] = worst;
    if (!(worst < 1e-12)) st.SkipWithError(("the floor's step differs from the plain loop's by " + std::to_string(worst) + " m").c_str());
  }
  std::vector<double> ux(3 * N), uv(3 * N);  // the user's interleaved x and v (BM_SeFloor_double_aos)
  for (Index i = 0; i < N; ++i) ux[3 * i] = X[i], ux[3 * i + 1] = Y[i], ux[3 * i + 2] = Z[i];
  for (auto _ : st) {
    if (aos) {
#pragma omp parallel for schedule(static) num_threads(nt)
      for (Index i = 0; i < N; ++i) {
        X[i] = ux[3 * i], Y[i] = ux[3 * i + 1], Z[i] = ux[3 * i + 2];
        VX[i] = uv[3 * i], VY[i] = uv[3 * i + 1], VZ[i] = uv[3 * i + 2];
      }
    }
    step();
    if (aos) {
#pragma omp parallel for schedule(static) num_threads(nt)
      for (Index i = 0; i < N; ++i) {
        ux[3 * i] = X[i], ux[3 * i + 1] = Y[i], ux[3 * i + 2] = Z[i];
        uv[3 * i] = VX[i], uv[3 * i + 1] = VY[i], uv[3 * i + 2] = VZ[i];
      }
    }
  }
  benchmark::DoNotOptimize(X.data());
  benchmark::DoNotOptimize(ux.data());
  st.counters["sweep_springs"] = springs;
  set_counters(st, r, threads, (Ho ? 24.0 : 16.0) * springs + 105.0 * static_cast<double>(N));
}
void BM_SeFloor_double(benchmark::State& st) { step_floor<false>(st, false); }
void BM_SeFloor_double_aos(benchmark::State& st) { step_floor<false>(st, true); }
void BM_HoFloor_double(benchmark::State& st) { step_floor<true>(st, false); }

// The machine's memory bandwidth: STREAM-like triad, 3 x 128 MB, 24 bytes per element.
void BM_Triad(benchmark::State& st) {
  const int threads = static_cast<int>(st.range(0));
  const std::size_t m = 16u << 20;
  std::vector<double> a(m), b(m, 1.0), c(m, 2.0);
  omp_set_num_threads(threads);
  for (auto _ : st) {
#pragma omp parallel for schedule(static)
    for (std::size_t q = 0; q < m; ++q) a[q] = b[q] + 3.0 * c[q];
    benchmark::DoNotOptimize(a.data());
  }
  st.counters["GB/s"] = benchmark::Counter(24.0 * m * st.iterations() * 1e-9, benchmark::Counter::kIsRate);
}

void rows_args(benchmark::internal::Benchmark* b) {
  for (int r = 0; r < static_cast<int>(rows().size()); ++r)
    for (int t : {1, 2}) b->Args({r, t});
  b->ArgNames({"row", "threads"})->Unit(benchmark::kMillisecond)->UseRealTime();
}

}  // namespace

#if defined(__AVX512F__)
// Issue 16, candidate 2 (docs/benchmarks/ho.md): HO's l = sqrt(l2), 1 / (l + min) on 4096
// squared lengths of the Table 1 range (L1 resident), one thread's CPU time; kind 0: the divider
// (vsqrtpd, vdivpd through an `omp simd` loop), 1: kernels::sqrt_recip_cr_pd (the same bits,
// FMAs and an exact rounding test; lanes out of its range by the divider). Time / 4096 = ns
// per spring of that part of the impulse loop, in isolation.
void sqrt_recip_bench(benchmark::State& st, int kind) {
  constexpr std::size_t n = 4096;
  std::vector<double> a(n), s(n), q(n);
  std::mt19937_64 rng(3);
  std::uniform_real_distribution<double> U(0.5, 2.0);
  for (double& e : a) e = 9e-6 * U(rng);
  const double tiny = std::numeric_limits<double>::min();
  for (auto _ : st) {
    if (kind == 0) {
#pragma omp simd
      for (std::size_t i = 0; i < n; ++i) {
        const double l = std::sqrt(a[i]);
        s[i] = l;
        q[i] = 1.0 / (l + tiny);
      }
    } else {
      for (std::size_t i = 0; i < n; i += 8) {
        __m512d sv, qv;
        const __mmask8 left = kernels::sqrt_recip_cr_pd(_mm512_loadu_pd(a.data() + i), sv, qv);
        _mm512_storeu_pd(s.data() + i, sv);
        _mm512_storeu_pd(q.data() + i, qv);
        if (left)
          for (int l = 0; l < 8; ++l)
            if (left >> l & 1) {
              s[i + l] = std::sqrt(a[i + l]);
              q[i + l] = 1.0 / (s[i + l] + tiny);
            }
      }
    }
    benchmark::DoNotOptimize(s.data());
    benchmark::DoNotOptimize(q.data());
    benchmark::ClobberMemory();
  }
  st.SetItemsProcessed(static_cast<std::int64_t>(st.iterations()) * static_cast<std::int64_t>(n));
}
void BM_SqrtRecip_divider(benchmark::State& st) { sqrt_recip_bench(st, 0); }
void BM_SqrtRecip_cr(benchmark::State& st) { sqrt_recip_bench(st, 1); }
BENCHMARK(BM_SqrtRecip_divider)->Unit(benchmark::kMicrosecond);
BENCHMARK(BM_SqrtRecip_cr)->Unit(benchmark::kMicrosecond);
#endif

BENCHMARK(BM_Triad)->Arg(1)->Arg(2)->Unit(benchmark::kMillisecond)->UseRealTime();
BENCHMARK(BM_HoStep_double)->Apply(rows_args);
BENCHMARK(BM_HoStep_double_sqrt5)->Apply(rows_args);
BENCHMARK(BM_HoStep_double_nomerge)->Apply(rows_args);
BENCHMARK(BM_HoStep_double_direct)->Apply(rows_args);
BENCHMARK(BM_HoStep_double_table)->Apply(rows_args);
BENCHMARK(BM_HoStep_double_window)->Apply(rows_args);
BENCHMARK(BM_HoStep_double_nowindow)->Apply(rows_args);
BENCHMARK(BM_HoStep_double_block64)->Apply(rows_args);
BENCHMARK(BM_HoStep_double_block128)->Apply(rows_args);
BENCHMARK(BM_HoStep_double_block256)->Apply(rows_args);
BENCHMARK(BM_HoStep_double_unfused)->Apply(rows_args);
BENCHMARK(BM_HoStep_double_notwin)->Apply(rows_args);
BENCHMARK(BM_HoStep_float)->Apply(rows_args);
BENCHMARK(BM_Rk4Step_double)->Apply(rows_args);
BENCHMARK(BM_Rk4Step_float)->Apply(rows_args);
BENCHMARK(BM_SeStep_double)->Apply(rows_args);
BENCHMARK(BM_SeStep_float)->Apply(rows_args);
BENCHMARK(BM_SeStep_double_plain)->Apply(rows_args);
BENCHMARK(BM_SeStep_float_plain)->Apply(rows_args);
BENCHMARK(BM_SeStep_double_blocked)->Apply(rows_args);
BENCHMARK(BM_SeStep_float_blocked)->Apply(rows_args);
BENCHMARK(BM_SeStep_double_block64)->Apply(rows_args);
BENCHMARK(BM_SeStep_double_block128)->Apply(rows_args);
BENCHMARK(BM_SeStep_double_block256)->Apply(rows_args);
BENCHMARK(BM_SeStep_double_unfused)->Apply(rows_args);
BENCHMARK(BM_SeStep_double_notwin)->Apply(rows_args);
BENCHMARK(BM_SeStep_double_scalarfin)->Apply(rows_args);
BENCHMARK(BM_SeStep_double_nomerge)->Apply(rows_args);
BENCHMARK(BM_SeFloor_double)->Apply(rows_args);
BENCHMARK(BM_SeFloor_double_aos)->Apply(rows_args);
BENCHMARK(BM_HoFloor_double)->Apply(rows_args);
BENCHMARK(BM_Rk4Fused_double)->Apply(rows_args);
BENCHMARK(BM_Rk4Fused_float)->Apply(rows_args);
BENCHMARK(BM_Rk4Fused_double_plain)->Apply(rows_args);
BENCHMARK(BM_Rk4Fused_double_nomerge)->Apply(rows_args);
BENCHMARK(BM_HoStep_shuffled_none)->Apply(rows_args);
BENCHMARK(BM_HoStep_shuffled_rcm)->Apply(rows_args);

BENCHMARK_MAIN();

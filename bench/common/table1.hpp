// Kang & Cho 2011 Table 1 for the benchmarks that set it beside the paper (bench_integrators,
// bench_cuda, table1_gpu): the paper's rows (data/table1_kang_cho2011.csv), the hanging cloth
// of its grids and the counters a case reports beside the paper.
#pragma once

#include <benchmark/benchmark.h>

#include <cmath>
#include <fstream>
#include <memory>
#include <sstream>
#include <stdexcept>
#include <string>
#include <vector>

#include "loom/mesh.hpp"
#include "loom/params.hpp"
#include "loom/scene.hpp"
#include "mass_spring.hpp"

namespace loom_bench {

/// One row of Table 1: the grid's side n (the paper gives n^2 vertices), the paper's spring
/// count and its GTX 590 frame rate.
struct Table1Row {
  int n;
  long springs;
  double fps;
};

/// The rows of `root`/data/table1_kang_cho2011.csv; a missing or empty file throws, naming
/// the file followed by `fix`.
inline std::vector<Table1Row> read_table1(const std::string& root, const std::string& fix = "") {
  const std::string path = root + "/data/table1_kang_cho2011.csv";
  std::vector<Table1Row> rows;
  std::ifstream in(path);
  std::string line;
  while (std::getline(in, line)) {
    if (line.empty() || line[0] == '#' || line[0] == 'v') continue;
    std::stringstream ss(line);
    std::string a, b, c;
    std::getline(ss, a, ',');
    std::getline(ss, b, ',');
    std::getline(ss, c, ',');
    rows.push_back({static_cast<int>(std::lround(std::sqrt(std::stod(a)))), std::stol(b), std::stod(c)});
  }
  if (rows.empty()) throw std::runtime_error(path + " is missing or empty" + fix);
  return rows;
}

/// A Table 1 cloth in `sc`: an n x n grid, 1 m square, hanging in the xy plane, mass-spring
/// with `stencil`, k = 2000, density 0.1, at rest, its two top corners pinned, gravity -9.81 y.
inline void table1_cloth(loom::Scene& sc, int n, const std::string& source,
                         const std::string& stencil = "kang_cho_table1") {
  using namespace loom;
  sc.source = source;
  sc.mesh = make_grid(n, n, 1.0, 1.0, GridPlane::XY);
  sc.material = std::make_unique<mass_spring::MassSpringMaterial>(
      Params::from_string("stencil: " + stencil + "\nstiffness: 2000\ndensity: 0.1\n"), sc.mesh);
  State& st = sc.state;
  st.resize(sc.mesh.num_vertices());
  st.x = sc.mesh.positions;
  sc.material->compute_masses(st.mass);
  const GridInfo& g = *sc.mesh.grid;
  st.pin(g.index(0, g.ny - 1));
  st.pin(g.index(g.nx - 1, g.ny - 1));
  st.update_inverse_masses();
  sc.gravity = {0, -9.81, 0};
}

/// The counters of a Table 1 case: fps (steps per second), the paper's fps and the ratio,
/// `bytes` (the modelled bytes a step moves), GB/s = bytes x fps and its fraction bw_frac of
/// `bandwidth` (bytes per second measured on this machine), and the vertex count.
inline void set_table1_counters(benchmark::State& st, const Table1Row& r, double bytes, double bandwidth) {
  const double it = static_cast<double>(st.iterations());
  st.counters["fps"] = benchmark::Counter(it, benchmark::Counter::kIsRate);
  st.counters["paper_fps"] = r.fps;
  st.counters["ratio"] = benchmark::Counter(it / r.fps, benchmark::Counter::kIsRate);
  st.counters["bytes"] = bytes;
  st.counters["GB/s"] = benchmark::Counter(it * bytes * 1e-9, benchmark::Counter::kIsRate);
  st.counters["bw_frac"] = benchmark::Counter(it * bytes / bandwidth, benchmark::Counter::kIsRate);
  st.counters["vertices"] = static_cast<double>(r.n) * r.n;
}

}  // namespace loom_bench

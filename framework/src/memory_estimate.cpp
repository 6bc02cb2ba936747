#include "loom/memory_estimate.hpp"

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <fstream>
#include <sstream>
#include <string>

namespace loom {

namespace {

// Peak resident bytes per vertex: the slope of /usr/bin/time's maximum resident size between
// the 128^2 and 256^2 grids of the shipped scenes, one frame of one step (2026-11-28, g++ 12
// -O2; docs/BENCHMARKS.md "Memory per vertex" has the runs). Rounded up by about 10 %.
constexpr double kBase = 8.0 * 1024 * 1024;   // executable, plugins, runtime (intercept measured 5-8 MiB)
constexpr double kSymplecticEuler = 1400;     // measured 1270 (mass_spring, fused spring sweep), 382 (gnatv)
constexpr double kRk4 = 1500;                 // measured 1362 (mass_spring, fused spring sweep)
constexpr double kHarmonic = 1900;            // measured 1723
constexpr double kBaraffWitkin = 2600;        // measured 2328 with eigen_pcg (block Jacobi)
constexpr double kSaAmg = 5300;               // measured 7.0 KB with sa_amg (float copies), so 4.8 KB more
constexpr double kDirectPerLog2 = 480;        // eigen_ldlt 453, 431, 447 x log2(V) at 64^2, 128^2, 256^2
constexpr double kBending = 1600;             // measured 1450 more with hinge bending
constexpr double kSelfCollision = 4700;       // measured 4.2 KB more (BVH and candidate lists)
constexpr double kOther = 1500;               // an integrator Loom does not know: as much as HO

bool is_direct(const std::string& solver) {
  return solver == "eigen_ldlt" || solver == "cholmod" || solver == "petsc";
}

}  // namespace

MemoryEstimate estimate_run_memory(const MemoryCombo& c) {
  const double v = static_cast<double>(std::max<std::int64_t>(c.vertices, 1));
  double per = kOther;
  std::string basis;
  if (c.integrator == "symplectic_euler") per = kSymplecticEuler;
  else if (c.integrator == "rk4") per = kRk4;
  else if (c.integrator == "harmonic_oscillation") per = kHarmonic;
  else if (c.integrator == "baraff_witkin") {
    per = kBaraffWitkin;
    if (is_direct(c.solver)) per = kDirectPerLog2 * std::max(1.0, std::log2(v));  // fill grows like V log V
    else if (c.sa_amg) per += kSaAmg;
  }
  std::string parts = c.integrator.empty() ? std::string("an unknown integrator") : c.integrator;
  if (!c.solver.empty()) parts += " + " + c.solver;
  if (c.sa_amg && c.integrator == "baraff_witkin" && !is_direct(c.solver)) parts += " (sa_amg)";
  if (c.bending) {
    per += kBending;
    parts += ", bending";
  }
  if (c.self_collision) {
    per += kSelfCollision;
    parts += ", self-collision";
  }
  char buf[64];
  std::snprintf(buf, sizeof buf, "%.0f bytes per vertex: ", per);
  basis = buf + parts;
  return {kBase + per * v, basis};
}

namespace {

std::optional<double> read_number(const std::string& path) {
  std::ifstream in(path);
  std::string s;
  if (!(in >> s) || s == "max") return std::nullopt;
  try {
    const double v = std::stod(s);
    if (v > 0 && std::isfinite(v)) return v;
  } catch (...) {
  }
  return std::nullopt;
}

}  // namespace

std::optional<double> machine_memory_bytes() {
  std::optional<double> total;
  std::ifstream in("/proc/meminfo");
  std::string line;
  while (std::getline(in, line)) {
    if (line.rfind("MemTotal:", 0) == 0) {
      std::istringstream ls(line.substr(9));
      double kib = 0;
      if (ls >> kib && kib > 0) total = kib * 1024.0;
      break;
    }
  }
  for (const char* p : {"/sys/fs/cgroup/memory.max", "/sys/fs/cgroup/memory/memory.limit_in_bytes"}) {
    if (const auto lim = read_number(p)) {
      if (*lim < 1e18 && (!total || *lim < *total)) total = *lim;  // v1 reports "no limit" as ~2^63
    }
  }
  return total;
}

std::string format_bytes(double bytes) {
  const char* unit[] = {"bytes", "KiB", "MiB", "GiB", "TiB", "PiB"};
  int k = 0;
  while (bytes >= 1024.0 && k < 5) {
    bytes /= 1024.0;
    ++k;
  }
  char buf[64];
  std::snprintf(buf, sizeof buf, k == 0 ? "%.0f %s" : "%.3g %s", bytes, unit[k]);
  return buf;
}

}  // namespace loom

// harmonic_oscillation's step against an independent, one-spring-at-a-time reference of the
// formulation it had before the impulses were summed unweighted (issue 16): per spring,
// Delta v_i = +w_i s n and Delta v_j = -w_j s n added to each endpoint separately (and
// Delta x likewise for analytic_position), then every vertex finalised. The reference is
// written here in long double from the closed form; only the per-parameter-set constants come
// from kernels::ho_coefficients / kang_cho_coefficients (checked against exact solutions in
// test_ho.cpp). Two non-grid meshes with a parameter set per spring: a jittered annulus numbered
// ring by ring (the grouped, windowed sweep runs) and a random point cloud numbered at random
// (the plain sweep runs); every storage, every variant.
#include <gtest/gtest.h>

#include <omp.h>

#include <algorithm>
#include <array>
#include <cmath>
#include <numeric>
#include <random>
#include <vector>

#include "ho_integrator.hpp"
#include "loom/kernels/ho.hpp"
#include "test_spring_material.hpp"

using namespace loom;
using loom::testing::make_scene;
using loom::testing::TestSpringMaterial;

namespace {

struct Net {
  std::vector<double> x, v, m;
  SpringSet s;
  std::vector<Index> pins;
};

// Rest length from the initial positions times a factor in [0.9, 1.1] (every spring its own
// l0), stiffness by class, dampers on some springs (damped = false: none).
void add_spring(Net& n, std::mt19937& rng, Index a, Index b, double k, bool damped, SpringClass cl) {
  std::uniform_real_distribution<double> F(0.9, 1.1), C(0.0, 1.0);
  double l2 = 0;
  for (int e = 0; e < 3; ++e) l2 += (n.x[3 * a + e] - n.x[3 * b + e]) * (n.x[3 * a + e] - n.x[3 * b + e]);
  const double c = damped && C(rng) < 0.5 ? 0.02 * C(rng) : 0.0;
  // alternate the endpoint order: the step must not depend on it
  if ((a + b) % 2) std::swap(a, b);
  n.s.add(a, b, std::sqrt(l2) * F(rng), k * F(rng), c, cl);
}

// An annulus of R rings of C vertices (numbered ring by ring), jittered radially and
// angularly, bent out of plane: ring, radial, both diagonal and two bend springs per vertex.
Net annulus(int R, int C, bool damped, unsigned seed) {
  std::mt19937 rng(seed);
  std::uniform_real_distribution<double> J(-1, 1), M(0.5e-3, 2e-3), V(-0.05, 0.05);
  Net n;
  const double pi = 3.14159265358979323846;
  for (int r = 0; r < R; ++r)
    for (int c = 0; c < C; ++c) {
      const double rad = 0.2 + 0.01 * r + 0.002 * J(rng), ang = 2 * pi * (c + 0.2 * J(rng)) / C;
      n.x.insert(n.x.end(), {rad * std::cos(ang), rad * std::sin(ang), 0.01 * std::sin(3 * ang + 0.5 * r)});
      n.v.insert(n.v.end(), {V(rng), V(rng), V(rng)});
      n.m.push_back(M(rng));
    }
  auto id = [C](int r, int c) { return static_cast<Index>(r * C + (c + C) % C); };
  for (int r = 0; r < R; ++r)
    for (int c = 0; c < C; ++c) {
      add_spring(n, rng, id(r, c), id(r, c + 1), 2000, damped, SpringClass::Structural);
      add_spring(n, rng, id(r, c), id(r, c + 2), 50, damped, SpringClass::Bend);
      if (r + 1 < R) {
        add_spring(n, rng, id(r, c), id(r + 1, c), 2000, damped, SpringClass::Structural);
        add_spring(n, rng, id(r, c), id(r + 1, c + 1), 500, damped, SpringClass::Shear);
        add_spring(n, rng, id(r, c), id(r + 1, c - 1), 500, damped, SpringClass::Shear);
      }
      if (r + 2 < R) add_spring(n, rng, id(r, c), id(r + 2, c), 50, damped, SpringClass::Bend);
    }
  n.pins = {id(R - 1, 0), id(R - 1, C / 2)};
  for (Index p : n.pins) n.v[3 * p] = n.v[3 * p + 1] = n.v[3 * p + 2] = 0;   // fixed pins
  return n;
}

// N random points in the unit disc, numbered at random; each joined to its 7 nearest neighbours.
Net cloud(int N, bool damped, unsigned seed) {
  std::mt19937 rng(seed);
  std::uniform_real_distribution<double> U(-1, 1), M(0.5e-3, 2e-3), V(-0.05, 0.05);
  Net n;
  while (static_cast<int>(n.m.size()) < N) {
    const double a = U(rng), b = U(rng);
    if (a * a + b * b > 1) continue;
    n.x.insert(n.x.end(), {a, b, 0.02 * U(rng)});
    n.v.insert(n.v.end(), {V(rng), V(rng), V(rng)});
    n.m.push_back(M(rng));
  }
  std::vector<std::pair<Index, Index>> pairs;
  for (Index q = 0; q < N; ++q) {
    std::vector<std::pair<double, Index>> d;
    for (Index o = 0; o < N; ++o)
      if (o != q) {
        double l2 = 0;
        for (int e = 0; e < 3; ++e) l2 += (n.x[3 * q + e] - n.x[3 * o + e]) * (n.x[3 * q + e] - n.x[3 * o + e]);
        d.push_back({l2, o});
      }
    std::partial_sort(d.begin(), d.begin() + 7, d.end());
    for (int t = 0; t < 7; ++t) pairs.push_back({std::min(q, d[t].second), std::max(q, d[t].second)});
  }
  std::sort(pairs.begin(), pairs.end());
  pairs.erase(std::unique(pairs.begin(), pairs.end()), pairs.end());
  std::shuffle(pairs.begin(), pairs.end(), rng);
  for (const auto& [a, b] : pairs) add_spring(n, rng, a, b, 1000, damped, SpringClass::Edge);
  n.pins = {0, 1};
  for (Index p : n.pins) n.v[3 * p] = n.v[3 * p + 1] = n.v[3 * p + 2] = 0;
  return n;
}

// `steps` steps of the previous formulation, one spring at a time, in long double.
void reference(const Net& n, HoVariant var, double h, const std::array<double, 3>& g, int steps,
               std::vector<long double>& x, std::vector<long double>& v) {
  const std::size_t N = n.m.size();
  std::vector<double> w(N);
  for (std::size_t q = 0; q < N; ++q) w[q] = 1.0 / n.m[q];
  for (Index p : n.pins) w[p] = 0;
  x.assign(n.x.begin(), n.x.end());
  v.assign(n.v.begin(), n.v.end());
  std::vector<long double> dv(3 * N), dx(3 * N);
  for (int st = 0; st < steps; ++st) {
    std::fill(dv.begin(), dv.end(), 0.0L);
    std::fill(dx.begin(), dx.end(), 0.0L);
    for (Index q = 0; q < n.s.size(); ++q) {
      const Index a = n.s.i[q], b = n.s.j[q];
      const double k = n.s.stiffness[q], c = n.s.damping[q], l0 = n.s.rest_length[q];
      long double kx, kv, ex = 0, ev = 0;
      if (var == HoVariant::KangCho2011) {
        const auto r = kernels::kang_cho_coefficients<double>(k, w[a], w[b], h);
        kx = r.kx;
        kv = r.ka;
      } else {
        const auto r = kernels::ho_coefficients<double>(k, c, w[a], w[b], h);
        kx = r.kx;
        kv = r.kv;
        ex = r.ex;
        ev = r.ev;
      }
      long double d[3], l2 = 0;
      for (int e = 0; e < 3; ++e) {
        d[e] = x[3 * b + e] - x[3 * a + e];
        l2 += d[e] * d[e];
      }
      const long double l = std::sqrt(l2), delta = l - l0;
      long double nn[3], rate = 0;
      for (int e = 0; e < 3; ++e) {
        nn[e] = d[e] / l;
        rate += nn[e] * (v[3 * b + e] - v[3 * a + e]);
      }
      const long double s = kx * delta + kv * (var == HoVariant::KangCho2011 ? std::abs(rate) : rate);
      const long double p = ex * delta + ev * rate;
      for (int e = 0; e < 3; ++e) {
        dv[3 * a + e] += w[a] * s * nn[e];
        dv[3 * b + e] -= w[b] * s * nn[e];
        dx[3 * a + e] += w[a] * p * nn[e];
        dx[3 * b + e] -= w[b] * p * nn[e];
      }
    }
    for (std::size_t q = 0; q < N; ++q) {
      const long double f = w[q] > 0 ? 1.0L : 0.0L;
      for (int e = 0; e < 3; ++e) {
        long double& xe = x[3 * q + e];
        long double& ve = v[3 * q + e];
        if (var == HoVariant::AnalyticPosition) {
          xe += h * ve + f * h * h / 2 * g[e] + dx[3 * q + e];
          ve += dv[3 * q + e] + f * h * g[e];
        } else {
          ve += dv[3 * q + e] + f * h * g[e];
          xe += h * ve;
        }
      }
    }
  }
}

enum class Store { Auto, Direct, Tables };

// Runs the plugin and compares with the reference: positions to 1e-13 of the mesh's size,
// velocity changes to 1e-11 of the largest one. Returns whether the grouped windowed sweep ran.
constexpr double kH = 2e-4;
constexpr int kSteps = 8;
constexpr std::array<double, 3> kG{0.3, -9.81, 0.2};

bool check(const Net& n, HoVariant var, Store store, bool expect_window, const std::vector<long double>& xr,
           const std::vector<long double>& vr) {
  const double h = kH;
  const int steps = kSteps;
  const std::array<double, 3> g = kG;
  auto scene = make_scene(n.x, n.v, n.m, n.pins, g, std::make_unique<TestSpringMaterial>(n.s, n.m));
  HoIntegrator ho(var, store != Store::Direct, true, HoReorder::None);
  ho.set_tables_on_window(store == Store::Tables);
  ho.prepare(*scene, h);
  const bool window = ho.springs().grouped && ho.springs().win_cap > 0;
  EXPECT_EQ(window, expect_window);
  EXPECT_EQ(ho.springs().table, store == Store::Tables || (store == Store::Auto && !window));
  if (ho.springs().table) {
    EXPECT_GT(ho.springs().t_l0.size(), 1000u);   // a parameter set per spring
  }
  EXPECT_GE(ho.springs().size(), kHoSerialSprings);   // the parallel path when threads > 1
  for (int st = 0; st < steps; ++st) ho.step(*scene, h);
  double ex = 0, ev = 0, dvmax = 0;
  for (std::size_t q = 0; q < xr.size(); ++q) {
    ex = std::max(ex, static_cast<double>(std::abs(scene->state.x[q] - xr[q])));
    ev = std::max(ev, static_cast<double>(std::abs(scene->state.v[q] - vr[q])));
    dvmax = std::max(dvmax, static_cast<double>(std::abs(vr[q] - n.v[q])));
  }
  EXPECT_GT(dvmax, 1e-3);   // the springs did act
  EXPECT_LE(ex, 1e-13) << to_string(var) << " storage " << static_cast<int>(store);
  EXPECT_LE(ev, 1e-11 * dvmax) << to_string(var) << " storage " << static_cast<int>(store);
  return window;
}

}  // namespace

TEST(HoReference, StepEqualsPerSpringFormulationOnIrregularMeshes) {
  const int threads = omp_get_max_threads();
  for (bool damped : {true, false}) {
    const Net ring = annulus(16, 256, damped, 11);
    const Net pts = cloud(2400, damped, 12);
    for (HoVariant var : {HoVariant::Velocity, HoVariant::AnalyticPosition, HoVariant::KangCho2011}) {
      if (damped && var == HoVariant::KangCho2011) continue;   // the published formula has no dampers
      std::vector<long double> xr, vr, xp, vp;
      reference(ring, var, kH, kG, kSteps, xr, vr);
      reference(pts, var, kH, kG, kSteps, xp, vp);
      for (Store st : {Store::Auto, Store::Direct, Store::Tables}) {
        // the default storage on 2 threads (parts in parallel, then the cross springs), the others
        // on one (a parallel region per step waits at barriers on a loaded machine)
        omp_set_num_threads(st == Store::Auto ? 2 : 1);
        check(ring, var, st, true, xr, vr);
        check(pts, var, st, false, xp, vp);
      }
    }
  }
  omp_set_num_threads(threads);
}

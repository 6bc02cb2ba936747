// harmonic_oscillation: isolated springs against exact solutions, hard cases, conservation,
// pins, refusal of materials without springs.
#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <limits>
#include <numeric>
#include <random>
#include <string>
#include <vector>

#include "exact_spring.hpp"
#include "ho_integrator.hpp"
#include "loom/kernels/ho.hpp"
#include "loom/params.hpp"
#include "test_spring_material.hpp"

#include <omp.h>

using namespace loom;
using loom::testing::exact_axial;
using loom::testing::make_scene;
using loom::testing::TestSpringMaterial;

namespace {

constexpr double kPi = 3.14159265358979323846;

enum class Masses { Equal, OneToFive, Pinned };
const char* name(Masses m) { return m == Masses::Equal ? "equal" : m == Masses::OneToFive ? "1:5" : "pinned"; }

// Isolated spring i=0, j=1 along axis n, k = 2000, l0 = 1.
struct SpringCase {
  Masses masses;
  double rate_sign;    // sign of the initial stretch rate
  double theta;        // omega h
  double zeta;         // damping ratio (0 = undamped)
  bool gravity = false;
  HoVariant variant = HoVariant::Velocity;

  double k = 2000, l0 = 1, d0 = 0.1;
  double mi = 1, mj = 1;
  double wi = 1, wj = 1, W = 2, omega = 0, beta = 0, c = 0, h = 0, rate0 = 0;
  double n[3] = {1.0 / 3, 2.0 / 3, -2.0 / 3};
  double xi0[3] = {0.3, -0.2, 0.1};
  double vc[3] = {0.2, -0.1, 0.4};   // common translation velocity (free cases)
  std::array<double, 3> g{0, 0, 0};

  std::unique_ptr<Scene> build() {
    mj = masses == Masses::OneToFive ? 5.0 : 1.0;
    wi = 1 / mi;
    wj = masses == Masses::Pinned ? 0.0 : 1 / mj;
    W = wi + wj;
    omega = std::sqrt(k * W);
    beta = zeta * omega;
    c = 2 * beta / W;
    h = theta / omega;
    rate0 = rate_sign * 0.7 * omega * d0;
    if (masses == Masses::Pinned)
      for (double& e : vc) e = 0;
    if (gravity) g = {0.3, -9.81, 1.1};
    std::vector<double> x(6), v(6);
    for (int e = 0; e < 3; ++e) {
      x[e] = xi0[e];
      x[3 + e] = xi0[e] + (l0 + d0) * n[e];
      v[e] = vc[e] - (wi / W) * rate0 * n[e];
      v[3 + e] = vc[e] + (wj / W) * rate0 * n[e];
    }
    SpringSet s;
    s.add(0, 1, l0, k, c, SpringClass::Structural);
    std::vector<double> m{mi, mj};
    auto mat = std::make_unique<TestSpringMaterial>(s, m);
    std::vector<Index> pins;
    if (masses == Masses::Pinned) pins.push_back(1);
    return make_scene(x, v, m, pins, gravity ? g : std::array<double, 3>{0, 0, 0}, std::move(mat));
  }
  std::string label() const {
    return std::string(name(masses)) + " rate" + (rate_sign > 0 ? "+" : "-") + " theta=" + std::to_string(theta) +
           " zeta=" + std::to_string(zeta);
  }
};

double norm3(const double* a) { return std::sqrt(a[0] * a[0] + a[1] * a[1] + a[2] * a[2]); }

// One step of the velocity variant: Delta v of both particles equals the exact solution.
void check_one_step_velocity(SpringCase sc, double tol, bool table = true) {
  auto scene = sc.build();
  HoIntegrator ho(HoVariant::Velocity, table);
  ho.prepare(*scene, sc.h);
  const std::vector<double> v0 = scene->state.v;
  ho.step(*scene, sc.h);
  const auto ex = exact_axial(sc.d0, sc.rate0, (long double)sc.k * sc.W, sc.beta, sc.h);
  const long double drate = ex.rate - (long double)sc.rate0;
  double dvi[3], dvj[3], err_i[3], err_j[3];
  for (int e = 0; e < 3; ++e) {
    dvi[e] = static_cast<double>(-(sc.wi / sc.W) * drate * sc.n[e]);
    dvj[e] = static_cast<double>(+(sc.wj / sc.W) * drate * sc.n[e]);
    err_i[e] = (scene->state.v[e] - v0[e]) - dvi[e];
    err_j[e] = (scene->state.v[3 + e] - v0[3 + e]) - dvj[e];
  }
  const double scale = std::max(norm3(dvi), norm3(dvj));
  ASSERT_GT(scale, 0) << sc.label();
  // v_new - v_old is formed from v ~ 1, so allow the rounding of v on top of the relative tolerance
  const double vround = 4e-16 * (norm3(v0.data()) + norm3(v0.data() + 3) + scale);
  EXPECT_LE(norm3(err_i), tol * scale + vround) << sc.label() << " rel " << norm3(err_i) / scale;
  EXPECT_LE(norm3(err_j), tol * scale + vround) << sc.label() << " rel " << norm3(err_j) / scale;
  // positions: x += h v_new (pinned j does not move at all)
  if (sc.masses == Masses::Pinned) {
    for (int e = 0; e < 3; ++e) EXPECT_EQ(scene->state.v[3 + e], 0.0);
  }
}

// One HO step on raw arrays in the variant var (dx: analytic_position's position accumulator).
void ho_step_variant(HoVariant var, const SpringLayout& layout, const HoSprings<double>& sp, std::vector<double>& X,
                     std::vector<double>& V, std::vector<double>& dv, std::vector<double>& dx, const double* w, double h,
                     const std::array<double, 3>& g) {
  switch (var) {
    case HoVariant::Velocity:
      ho_step_arrays<double, HoVariant::Velocity>(layout, sp, X.data(), V.data(), dv.data(), nullptr, w, h, g);
      break;
    case HoVariant::AnalyticPosition:
      ho_step_arrays<double, HoVariant::AnalyticPosition>(layout, sp, X.data(), V.data(), dv.data(), dx.data(), w, h, g);
      break;
    case HoVariant::KangCho2011:
      ho_step_arrays<double, HoVariant::KangCho2011>(layout, sp, X.data(), V.data(), dv.data(), nullptr, w, h, g);
      break;
  }
}

}  // namespace

TEST(HoOneStep, VelocityChangeIsExactUndamped) {
  for (Masses m : {Masses::Equal, Masses::OneToFive, Masses::Pinned})
    for (double sgn : {1.0, -1.0})
      for (double th : {0.05, 0.5, 2.0, 7.0}) {
        SpringCase c{m, sgn, th, 0.0};
        check_one_step_velocity(c, 1e-12, true);
        check_one_step_velocity(c, 1e-12, false);
      }
}

TEST(HoOneStep, VelocityChangeIsExactDamped) {
  for (Masses m : {Masses::Equal, Masses::OneToFive, Masses::Pinned})
    for (double sgn : {1.0, -1.0})
      for (double th : {0.05, 0.5, 2.0, 7.0})
        for (double z : {0.05, 1.0, 4.0}) {
          SpringCase c{m, sgn, th, z};
          check_one_step_velocity(c, 1e-12, true);
          check_one_step_velocity(c, 1e-12, false);
        }
}

// HO-A reproduces the exact trajectory (both particles, every step) for any h.
TEST(HoAnalyticPosition, ExactTrajectoryAnyStep) {
  double worst = 0;
  for (Masses m : {Masses::Equal, Masses::OneToFive, Masses::Pinned})
    for (double z : {0.0, 0.05, 1.0, 4.0})
      for (double th : {0.06, 1.26, 6.3})
        for (bool grav : {false, true}) {
          if (grav && (z != 0.05 || m == Masses::Pinned)) continue;   // a pin breaks the uniform field's symmetry
          SpringCase sc{m, -1.0, th, z, grav};
          auto scene = sc.build();
          HoIntegrator ho(HoVariant::AnalyticPosition, th != 1.26);   // both parameter storages
          ho.prepare(*scene, sc.h);
          const double T = 1.0;
          const int steps = std::max(3, static_cast<int>(std::lround(T / sc.h)));
          const double A0 = std::hypot(sc.d0, sc.rate0 / sc.omega);
          double cm0[3], vcm[3];
          const double M = sc.masses == Masses::Pinned ? 0 : sc.mi + sc.mj;
          for (int e = 0; e < 3; ++e) {
            if (M > 0) {
              cm0[e] = (sc.mi * scene->state.x[e] + sc.mj * scene->state.x[3 + e]) / M;
              vcm[e] = (sc.mi * scene->state.v[e] + sc.mj * scene->state.v[3 + e]) / M;
            } else {
              cm0[e] = scene->state.x[3 + e];
              vcm[e] = 0;
            }
          }
          double err = 0;
          for (int s = 1; s <= steps; ++s) {
            ho.step(*scene, sc.h);
            const double t = s * sc.h;
            const auto ex = exact_axial(sc.d0, sc.rate0, (long double)sc.k * sc.W, sc.beta, t);
            const double L = static_cast<double>(sc.l0 + ex.delta);
            for (int e = 0; e < 3; ++e) {
              const double gt = (M > 0 ? 0.5 * sc.g[e] * t * t : 0.0);
              const double cm = cm0[e] + vcm[e] * t + gt;
              const double xi = cm - (sc.wi / sc.W) * L * sc.n[e];
              const double xj = cm + (sc.wj / sc.W) * L * sc.n[e];
              err = std::max({err, std::abs(scene->state.x[e] - xi), std::abs(scene->state.x[3 + e] - xj)});
            }
            ASSERT_TRUE(std::isfinite(scene->state.x[0])) << sc.label();
          }
          EXPECT_LE(err, 1e-11 * A0 + 1e-13) << sc.label() << (grav ? " gravity" : "");
          worst = std::max(worst, err / A0);
        }
  RecordProperty("worst_relative_error", std::to_string(worst));
}

// Amplitude 0 and whole numbers of periods: finite for every variant (the published formula
// is 0/0 there as printed).
TEST(HoHardCases, ZeroAmplitudeAndWholePeriods) {
  for (HoVariant var : {HoVariant::Velocity, HoVariant::AnalyticPosition, HoVariant::KangCho2011}) {
    for (Masses m : {Masses::Equal, Masses::Pinned}) {
      // amplitude 0: the spring at rest, moving uniformly
      SpringCase sc{m, 1.0, 0.5, 0.0};
      sc.d0 = 0;
      sc.rate_sign = 0;
      auto scene = sc.build();
      const std::vector<double> v0 = scene->state.v;
      HoIntegrator ho(var);
      ho.prepare(*scene, sc.h);
      ho.step(*scene, sc.h);
      for (int e = 0; e < 6; ++e) {
        ASSERT_TRUE(std::isfinite(scene->state.v[e]));
        EXPECT_NEAR(scene->state.v[e], v0[e], 1e-13) << to_string(var);   // delta = l - l0 rounds to ~1e-16
      }
      // h = 3 periods exactly (kang_cho: H = h mod period = 0)
      for (double zeta : {0.0, 0.3}) {
        if (var == HoVariant::KangCho2011 && zeta > 0) continue;
        SpringCase sp{m, -1.0, 3 * 2 * kPi, zeta};
        auto sc2 = sp.build();
        HoIntegrator ho2(var);
        ho2.prepare(*sc2, sp.h);
        for (int s = 0; s < 3; ++s) ho2.step(*sc2, sp.h);
        for (int e = 0; e < 6; ++e) {
          ASSERT_TRUE(std::isfinite(sc2->state.v[e])) << to_string(var);
          ASSERT_TRUE(std::isfinite(sc2->state.x[e])) << to_string(var);
        }
      }
    }
  }
}

// The three damping regimes join continuously and nothing overflows at huge damping.
TEST(HoKernel, DampingRegimesContinuousAndNoOverflow) {
  using kernels::ho_flow;
  const double om2 = 4000, h = 0.01, om = std::sqrt(om2);
  for (double eps : {1e-6, 1e-9}) {
    const auto under = ho_flow(om2, om * (1 - eps), h);
    const auto crit = ho_flow(om2, om, h);
    const auto over = ho_flow(om2, om * (1 + eps), h);
    for (auto [a, b, c] : {std::tuple{under.a_x, crit.a_x, over.a_x}, std::tuple{under.a_v, crit.a_v, over.a_v},
                           std::tuple{under.b_x, crit.b_x, over.b_x}, std::tuple{under.b_v, crit.b_v, over.b_v}}) {
      EXPECT_NEAR(a, b, 20 * eps * std::abs(b) + 1e-14);
      EXPECT_NEAR(c, b, 20 * eps * std::abs(b) + 1e-14);
    }
  }
  // tiny damping joins the undamped closed form
  const auto und = ho_flow(om2, 0.0, h), tiny = ho_flow(om2, 1e-10, h);
  EXPECT_NEAR(und.a_x, tiny.a_x, 1e-8 * std::abs(und.a_x));
  EXPECT_NEAR(und.a_v, tiny.a_v, 1e-8 * std::abs(und.a_v));
  EXPECT_NEAR(und.b_v, tiny.b_v, 1e-8 * std::abs(und.b_v));
  // beta h = 1e4 (exp(beta h) would overflow): finite, and the motion is frozen (delta' -> 0)
  for (double beta : {1e6, 1e8}) {
    const auto f = ho_flow(om2, beta, h);
    for (double q : {f.a_x, f.a_v, f.b_x, f.b_v}) ASSERT_TRUE(std::isfinite(q));
    EXPECT_NEAR(f.a_v, -1.0, 1e-6);   // the relative velocity is damped out
    const auto ex = exact_axial(0.0, 1.0, om2, beta, h);
    EXPECT_NEAR(f.b_v, static_cast<double>(ex.delta) - h, 1e-12);
  }
  // omega = 0 with damping: pure damper
  const auto d = ho_flow(0.0, 5.0, h);
  EXPECT_NEAR(d.a_v, std::expm1(-2 * 5.0 * h), 1e-15);   // delta'' = -2 beta delta'
  EXPECT_EQ(d.a_x, 0.0);
  // float instantiation agrees with double
  const auto cf = kernels::ho_coefficients<float>(2000.f, 3.f, 1.f, 0.2f, 1e-3f);
  const auto cd = kernels::ho_coefficients<double>(2000., 3., 1., 0.2, 1e-3);
  EXPECT_NEAR(cf.kx, cd.kx, 1e-5 * cd.kx);
  EXPECT_NEAR(cf.kv, cd.kv, 1e-5 * cd.kv);
  EXPECT_NEAR(cf.ev, cd.ev, 1e-4 * std::abs(cd.ev));
}

// Small theta: the velocity update is symplectic Euler plus a damper k h/2 (NUMERICS 1.2);
// the published formula gives half the stiffness.
TEST(HoKernel, SmallStepLimitAndPublishedHalfStiffness) {
  const double k = 2000, w = 1.0;
  for (double h : {1e-4, 1e-5}) {
    const auto c = kernels::ho_coefficients<double>(k, 0.0, w, w, h);
    EXPECT_NEAR(c.kx / (k * h), 1.0, 2 * k * 2 * w * h * h);   // 1 - theta^2/6
    EXPECT_NEAR(c.kv / (k * h * h / 2), 1.0, 2 * k * 2 * w * h * h);
    const auto p = kernels::kang_cho_coefficients<double>(k, w, w, h);
    EXPECT_NEAR(p.kx / (k * h), 0.5, 2 * k * w * h * h);
  }
  // published formula restores (positive stiffness) for both signs of the rate and is finite
  // at whole periods
  const double period = 2 * kPi / std::sqrt(k * 2 * w);
  const auto p3 = kernels::kang_cho_coefficients<double>(k, w, w, 3 * period);
  EXPECT_TRUE(std::isfinite(p3.kx) && std::isfinite(p3.ka));
}

// Linear and angular momentum are conserved exactly (to rounding) by the velocity variant on
// a random damped network with random masses; linear momentum also by the other variants.
TEST(HoConservation, MomentumOnRandomNetwork) {
  std::mt19937 rng(7);
  std::uniform_real_distribution<double> U(-1, 1), P(0.2, 2.0);
  const int n = 40, S = 120;
  std::vector<double> x(3 * n), v(3 * n), m(n);
  for (int q = 0; q < n; ++q) {
    m[q] = P(rng);
    for (int e = 0; e < 3; ++e) {
      x[3 * q + e] = U(rng);
      v[3 * q + e] = U(rng);
    }
  }
  SpringSet s;
  for (int q = 0; q < S; ++q) {
    Index a = rng() % n, b = rng() % n;
    if (a == b) b = (a + 1) % n;
    double l = 0;
    for (int e = 0; e < 3; ++e) l += (x[3 * a + e] - x[3 * b + e]) * (x[3 * a + e] - x[3 * b + e]);
    s.add(a, b, std::sqrt(l) * (0.8 + 0.4 * P(rng) / 2), 500 * P(rng), (q % 3 == 0) ? 0.0 : 2 * P(rng),
          SpringClass::Structural);
  }
  for (HoVariant var : {HoVariant::Velocity, HoVariant::AnalyticPosition, HoVariant::KangCho2011}) {
    if (var == HoVariant::KangCho2011)
      for (double& c : s.damping) c = 0;
    auto scene = make_scene(x, v, m, {}, {0, 0, 0}, std::make_unique<TestSpringMaterial>(s, m));
    auto momenta = [&](double Pm[3], double Lm[3]) {
      for (int e = 0; e < 3; ++e) Pm[e] = Lm[e] = 0;
      const auto& X = scene->state.x;
      const auto& V = scene->state.v;
      for (int q = 0; q < n; ++q) {
        const double* xq = &X[3 * q];
        const double* vq = &V[3 * q];
        for (int e = 0; e < 3; ++e) Pm[e] += m[q] * vq[e];
        Lm[0] += m[q] * (xq[1] * vq[2] - xq[2] * vq[1]);
        Lm[1] += m[q] * (xq[2] * vq[0] - xq[0] * vq[2]);
        Lm[2] += m[q] * (xq[0] * vq[1] - xq[1] * vq[0]);
      }
    };
    double P0[3], L0[3], P1[3], L1[3];
    momenta(P0, L0);
    HoIntegrator ho(var);
    const double h = 2e-3;
    ho.prepare(*scene, h);
    for (int st = 0; st < 100; ++st) ho.step(*scene, h);
    momenta(P1, L1);
    double ke = 0;
    for (int q = 0; q < n; ++q)
      for (int e = 0; e < 3; ++e) ke += m[q] * std::abs(scene->state.v[3 * q + e]);
    for (int e = 0; e < 3; ++e) {
      EXPECT_NEAR(P1[e], P0[e], 1e-13 * ke) << to_string(var);
      if (var != HoVariant::AnalyticPosition) {
        EXPECT_NEAR(L1[e], L0[e], 1e-12 * ke) << to_string(var);
      }
    }
  }
}

// Pinned vertices stay exactly where they are (bit for bit); free ones move.
TEST(HoPins, PinnedVerticesExact) {
  const int nx = 6;
  std::vector<double> x, v, m;
  for (int r = 0; r < nx; ++r)
    for (int c = 0; c < nx; ++c) {
      x.insert(x.end(), {0.1 * c, 0.0, 0.1 * r});
      v.insert(v.end(), {0, 0, 0});
      m.push_back(0.01);
    }
  SpringSet s;
  for (int r = 0; r < nx; ++r)
    for (int c = 0; c < nx; ++c) {
      const int a = r * nx + c;
      if (c + 1 < nx) s.add(a, a + 1, 0.1, 2000, 0.1, SpringClass::Structural);
      if (r + 1 < nx) s.add(a, a + nx, 0.1, 2000, 0.1, SpringClass::Structural);
      if (c + 1 < nx && r + 1 < nx) s.add(a, a + nx + 1, 0.1 * std::sqrt(2.0), 2000, 0.0, SpringClass::Shear);
    }
  // one spring between two pinned vertices (must be skipped: W = 0)
  s.add(0, nx - 1, 0.3, 2000, 0.0, SpringClass::Bend);
  const std::vector<Index> pins{0, nx - 1};
  for (HoVariant var : {HoVariant::Velocity, HoVariant::AnalyticPosition}) {
    auto scene = make_scene(x, v, m, pins, {0, -9.81, 0}, std::make_unique<TestSpringMaterial>(s, m));
    HoIntegrator ho(var);
    ho.prepare(*scene, 2e-4);
    for (int st = 0; st < 300; ++st) ho.step(*scene, 2e-4);
    for (Index p : pins)
      for (int e = 0; e < 3; ++e) {
        EXPECT_EQ(scene->state.x[3 * p + e], x[3 * p + e]) << to_string(var);
        EXPECT_EQ(scene->state.v[3 * p + e], 0.0) << to_string(var);
      }
    EXPECT_LT(scene->state.x[3 * (nx * nx - 1) + 1], -1e-3) << "free corner falls";
    EXPECT_NEAR(scene->state.time, 300 * 2e-4, 1e-15);
    EXPECT_EQ(scene->state.step, 300);
  }
}

TEST(HoInput, RefusesMaterialWithoutSprings) {
  SpringSet s;
  s.add(0, 1, 1.0, 100, 0, SpringClass::Structural);
  std::vector<double> m{1, 1};
  auto scene = make_scene({0, 0, 0, 1, 0, 0}, {0, 0, 0, 0, 0, 0}, m, {}, {0, 0, 0},
                          std::make_unique<TestSpringMaterial>(s, m, false));
  HoIntegrator ho(HoVariant::Velocity);
  EXPECT_TRUE(ho.needs().springs);
  try {
    ho.prepare(*scene, 1e-3);
    FAIL() << "expected InputError";
  } catch (const InputError& e) {
    const std::string msg = e.what();
    EXPECT_NE(msg.find("test_no_springs"), std::string::npos) << msg;
    EXPECT_NE(msg.find("mass_spring"), std::string::npos) << msg;
  }
}

TEST(HoInput, VariantParameter) {
  auto p = Params::from_string("variant: analytic_position\n");
  HoIntegrator a(p);
  EXPECT_EQ(a.variant(), HoVariant::AnalyticPosition);
  EXPECT_NO_THROW(p.check_unused());
  HoIntegrator d(Params::from_string("{}\n"));
  EXPECT_EQ(d.variant(), HoVariant::Velocity);
  EXPECT_THROW(HoIntegrator(Params::from_string("variant: velocty\n")), InputError);
  // published formula with damping is refused with the fix
  SpringSet s;
  s.add(0, 1, 1.0, 100, 0.5, SpringClass::Structural);
  std::vector<double> m{1, 1};
  auto scene = make_scene({0, 0, 0, 1, 0, 0}, {0, 0, 0, 0, 0, 0}, m, {}, {0, 0, 0},
                          std::make_unique<TestSpringMaterial>(s, m));
  HoIntegrator kc(HoVariant::KangCho2011);
  EXPECT_THROW(kc.prepare(*scene, 1e-3), InputError);
}

// The parallel traversal (2 threads) gives bit-for-bit the serial result, for a grid large
// enough to take the parallel path.
TEST(HoParallel, TwoThreadsMatchOneThreadBitwise) {
  const int nx = 100;   // 100 x 100 vertices, ~39k springs (> kHoSerialSprings)
  std::vector<double> x, v, m;
  std::mt19937 rng(3);
  std::uniform_real_distribution<double> U(-0.01, 0.01);
  for (int r = 0; r < nx; ++r)
    for (int c = 0; c < nx; ++c) {
      x.insert(x.end(), {0.01 * c + U(rng) / 10, U(rng) / 10, 0.01 * r});
      v.insert(v.end(), {U(rng), U(rng), U(rng)});
      m.push_back(1e-4 * (1 + 50 * std::abs(U(rng))));
    }
  SpringSet s;
  for (int r = 0; r < nx; ++r)
    for (int c = 0; c < nx; ++c) {
      const int a = r * nx + c;
      if (c + 1 < nx) s.add(a, a + 1, 0.01, 2000, 0.01, SpringClass::Structural);
      if (r + 1 < nx) s.add(a + nx, a, 0.01, 2000, 0.0, SpringClass::Structural);
      if (c + 1 < nx && r + 1 < nx) s.add(a, a + nx + 1, 0.01 * std::sqrt(2.0), 1000, 0.0, SpringClass::Shear);
      if (c > 0 && r + 1 < nx) s.add(a, a + nx - 1, 0.01 * std::sqrt(2.0), 1000, 0.0, SpringClass::Shear);
    }
  ASSERT_GT(s.size(), kHoSerialSprings);
  for (HoVariant var : {HoVariant::Velocity, HoVariant::AnalyticPosition}) {
    std::vector<double> res[2];
    for (int threads : {1, 2}) {
      omp_set_num_threads(threads);
      auto scene = make_scene(x, v, m, {0, nx - 1}, {0, -9.81, 0}, std::make_unique<TestSpringMaterial>(s, m));
      HoIntegrator ho(var);
      ho.prepare(*scene, 1e-4);
      EXPECT_TRUE(ho.springs().grouped);
      for (int st = 0; st < 10; ++st) ho.step(*scene, 1e-4);
      res[threads - 1] = scene->state.x;
      res[threads - 1].insert(res[threads - 1].end(), scene->state.v.begin(), scene->state.v.end());
    }
    omp_set_num_threads(2);
    ASSERT_EQ(res[0].size(), res[1].size());
    for (std::size_t q = 0; q < res[0].size(); ++q) ASSERT_EQ(res[0][q], res[1][q]) << to_string(var) << " entry " << q;
  }
}

// Parameter tables (deduplicated l0, k, c, W) and per-spring constants give the same bits.
TEST(HoStorage, TableAndDirectAgreeBitwise) {
  const int nx = 30;
  std::vector<double> x, v, m;
  for (int r = 0; r < nx; ++r)
    for (int c = 0; c < nx; ++c) {
      x.insert(x.end(), {0.02 * c, 0.0, 0.02 * r});
      v.insert(v.end(), {0.01 * std::sin(r + 2.0 * c), 0.0, 0.0});
      m.push_back(r == 0 || c == 0 ? 5e-4 : 1e-3);
    }
  SpringSet s;
  for (int r = 0; r < nx; ++r)
    for (int c = 0; c < nx; ++c) {
      const int a = r * nx + c;
      if (c + 1 < nx) s.add(a, a + 1, 0.02, 2000, 0.02, SpringClass::Structural);
      if (r + 1 < nx) s.add(a, a + nx, 0.02, 2000, 0.0, SpringClass::Structural);
      if (c + 1 < nx && r + 1 < nx) s.add(a, a + nx + 1, 0.02 * std::sqrt(2.0), 500, 0.0, SpringClass::Shear);
      if (c + 2 < nx) s.add(a, a + 2, 0.04, 50, 0.0, SpringClass::Bend);
    }
  for (HoVariant var : {HoVariant::Velocity, HoVariant::AnalyticPosition, HoVariant::KangCho2011}) {
    if (var == HoVariant::KangCho2011)
      for (double& c : s.damping) c = 0;
    std::vector<double> res[2];
    for (int table : {0, 1}) {
      auto scene = make_scene(x, v, m, {nx * (nx - 1), nx * nx - 1}, {0, -9.81, 0},
                              std::make_unique<TestSpringMaterial>(s, m));
      HoIntegrator ho(var, table == 1);
      ho.set_tables_on_window(table == 1);   // the windowed sweep streams per-spring constants by default
      ho.prepare(*scene, 1e-4);
      EXPECT_EQ(ho.springs().table, table == 1);
      if (table) {
        EXPECT_LE(ho.springs().t_l0.size(), 20u);
      }
      for (int st = 0; st < 50; ++st) ho.step(*scene, 1e-4);
      res[table] = scene->state.x;
      res[table].insert(res[table].end(), scene->state.v.begin(), scene->state.v.end());
    }
    for (std::size_t q = 0; q < res[0].size(); ++q) ASSERT_EQ(res[0][q], res[1][q]) << to_string(var) << " " << q;
  }
  // parameter parsing
  EXPECT_NO_THROW(HoIntegrator(Params::from_string("storage: direct\n")));
  EXPECT_THROW(HoIntegrator(Params::from_string("storage: tables\n")), InputError);
}

// The grouped sweep (springs in runs of equal offset j - i along consecutive i, contiguous
// reads) and the plain blocked sweep compute the same step up to summation order.
TEST(HoStorage, GroupedAndPlainSweepsAgree) {
  const int nx = 40;
  std::vector<double> x, v, m;
  for (int r = 0; r < nx; ++r)
    for (int c = 0; c < nx; ++c) {
      x.insert(x.end(), {0.02 * c, 0.001 * std::sin(0.7 * c + r), 0.02 * r});
      v.insert(v.end(), {0.01 * std::sin(r + 2.0 * c), 0.02 * std::cos(3.0 * r - c), 0.0});
      m.push_back(1e-3 * (1 + 0.5 * ((r * 7 + c * 3) % 5)));
    }
  SpringSet s;
  for (int r = 0; r < nx; ++r)
    for (int c = 0; c < nx; ++c) {
      const int a = r * nx + c;
      if (c + 1 < nx) s.add(a, a + 1, 0.02, 2000, 0.02, SpringClass::Structural);
      if (r + 1 < nx) s.add(a + nx, a, 0.02, 2000, 0.0, SpringClass::Structural);   // reversed endpoints
      if (c + 1 < nx && r + 1 < nx && (r + c) % 2 == 0) s.add(a, a + nx + 1, 0.02 * std::sqrt(2.0), 500, 0.0, SpringClass::Shear);
      if (c > 0 && r + 1 < nx && (r + c) % 2 == 1) s.add(a, a + nx - 1, 0.02 * std::sqrt(2.0), 500, 0.0, SpringClass::Shear);
      if (c + 2 < nx) s.add(a, a + 2, 0.04, 50, 0.0, SpringClass::Bend);
      if (c + 2 < nx && r % 3 == 0) s.add(a, a + 2, 0.04, 50, 0.0, SpringClass::Bend);   // duplicate pairs
    }
  for (HoVariant var : {HoVariant::Velocity, HoVariant::AnalyticPosition}) {
    std::vector<double> res[2];
    for (int grouped : {0, 1}) {
      auto scene = make_scene(x, v, m, {nx * (nx - 1), nx * nx - 1}, {0, -9.81, 0},
                              std::make_unique<TestSpringMaterial>(s, m));
      HoIntegrator ho(var, true, grouped == 1);
      ho.prepare(*scene, 1e-4);
      EXPECT_EQ(ho.springs().grouped, grouped == 1);
      for (int st = 0; st < 50; ++st) ho.step(*scene, 1e-4);
      res[grouped] = scene->state.x;
      res[grouped].insert(res[grouped].end(), scene->state.v.begin(), scene->state.v.end());
    }
    double err = 0, scale = 0;
    for (std::size_t q = 0; q < res[0].size(); ++q) {
      err = std::max(err, std::abs(res[0][q] - res[1][q]));
      scale = std::max(scale, std::abs(res[0][q]));
    }
    EXPECT_LE(err, 1e-13 * scale) << to_string(var);
  }
}

// An nx x nx grid of 2 cm cells, slightly rumpled, with varied velocities and masses: the
// state of the windowed-sweep bit-identity tests.
static void perturbed_grid_state(int nx, std::vector<double>& x, std::vector<double>& v, std::vector<double>& m) {
  for (int r = 0; r < nx; ++r)
    for (int c = 0; c < nx; ++c) {
      x.insert(x.end(), {0.02 * c + 0.003 * std::sin(1.3 * r * c), 0.001 * std::sin(0.7 * c + r), 0.02 * r});
      v.insert(v.end(), {0.01 * std::sin(r + 2.0 * c), 0.02 * std::cos(3.0 * r - c), 0.005 * std::sin(c - r)});
      m.push_back(1e-3 * (1 + 0.5 * ((r * 7 + c * 3) % 5)));
    }
}

// The windowed grouped sweep (ho_window.hpp: x, v and the accumulators of the live vertices in
// structure of arrays) performs the plain grouped sweep's operations in the same order: the
// same bits, for every variant and storage, with the default capacity and with the smallest
// one the plan allows (the window then moves its live vertices every block or two).
TEST(HoStorage, WindowedSweepIsBitIdentical) {
  const int nx = 48;
  std::vector<double> x, v, m;
  perturbed_grid_state(nx, x, v, m);
  SpringSet s;
  for (int r = 0; r < nx; ++r)
    for (int c = 0; c < nx; ++c) {
      const int a = r * nx + c;
      if (c + 1 < nx) s.add(a, a + 1, 0.02, 2000, 0.0, SpringClass::Structural);
      if (r + 1 < nx) s.add(a + nx, a, 0.02, 2000, 0.0, SpringClass::Structural);
      if (c + 1 < nx && r + 1 < nx) s.add(a, a + nx + 1, 0.02 * std::sqrt(2.0), 500, 0.0, SpringClass::Shear);
      if (c > 0 && r + 1 < nx) s.add(a, a + nx - 1, 0.02 * std::sqrt(2.0), 500 + (c % 3), 0.0, SpringClass::Shear);
      if (c + 2 < nx) s.add(a, a + 2, 0.04, 50, 0.0, SpringClass::Bend);
      if (r + 2 < nx && (c % 2 == 0)) s.add(a, a + 2 * nx, 0.04, 50, 0.0, SpringClass::Bend);   // step-2 runs
      if (c + 2 < nx && r % 3 == 0) s.add(a, a + 2, 0.04, 50, 0.0, SpringClass::Bend);   // duplicate pairs
    }
  const std::vector<Index> pins{nx * (nx - 1), nx * nx - 1};
  int checked = 0;
  for (HoVariant var : {HoVariant::Velocity, HoVariant::AnalyticPosition, HoVariant::KangCho2011})
    for (bool table : {true, false}) {
      auto scene = make_scene(x, v, m, pins, {0, -9.81, 0}, std::make_unique<TestSpringMaterial>(s, m));
      HoIntegrator ho(var, table, true, HoReorder::None);
      ho.set_tables_on_window(table);
      ho.prepare(*scene, 1e-4);
      ASSERT_TRUE(ho.springs().grouped);
      ASSERT_GT(ho.springs().win_cap, 0);
      ASSERT_GE(ho.springs().win_cap, ho.springs().win_span);
      EXPECT_EQ(ho.springs().table, table);
      const std::array<double, 3> g{0, -9.81, 0};
      const double* w = scene->state.inv_mass.data();
      auto run = [&](Index cap) {
        HoSprings<double> sp = ho.springs();
        sp.win_cap = cap;
        allocate_ho_window(sp, ho.layout().parts());
        std::vector<double> X = x, V = v, dv(x.size(), 0.0), dx(x.size(), 0.0);
        for (int st = 0; st < 12; ++st) ho_step_variant(var, ho.layout(), sp, X, V, dv, dx, w, 1e-4, g);
        EXPECT_TRUE(std::all_of(dv.begin(), dv.end(), [](double d) { return d == 0.0; }));
        X.insert(X.end(), V.begin(), V.end());
        return X;
      };
      const std::vector<double> plain = run(0);
      const std::vector<double> moved0 = run(ho.springs().win_cap);
      const std::vector<double> moved1 = run(ho.springs().win_span);
      ASSERT_EQ(plain.size(), moved0.size());
      double change = 0;
      for (std::size_t q = 0; q < plain.size(); ++q) {
        ASSERT_EQ(plain[q], moved0[q]) << to_string(var) << " table " << table << " entry " << q;
        ASSERT_EQ(plain[q], moved1[q]) << to_string(var) << " table " << table << " entry " << q << " (smallest window)";
        change = std::max(change, std::abs(plain[q] - (q < x.size() ? x[q] : v[q - x.size()])));
      }
      EXPECT_GT(change, 1e-6);   // the springs did act
      ++checked;
    }
  EXPECT_EQ(checked, 6);
}

// Issue 16: on the windowed sweep, a unit-stride segment whose lower and upper ranges are
// disjoint (off >= len) computes its impulses and scatters them in one pass
// (ho_window_impulses_scatter). Every slot then gets the same additions in the same order as with
// the two passes, so 12 steps give the two-pass windowed sweep's and the plain grouped sweep's
// bits exactly, in the velocity and kang_cho_2011 variants, with and without tables, on 1 and 2
// threads. The cloth has both kinds of unit-stride segment (rows of 80 vertices: the vertical and
// diagonal springs' segments are disjoint, the horizontal ones overlap).
TEST(HoStorage, FusedImpulseScatterIsBitIdentical) {
  const int nx = 80;
  std::vector<double> x, v, m;
  perturbed_grid_state(nx, x, v, m);
  SpringSet s;
  for (int r = 0; r < nx; ++r)
    for (int c = 0; c < nx; ++c) {
      const int a = r * nx + c;
      if (c + 1 < nx) s.add(a, a + 1, 0.02, 2000, 0.0, SpringClass::Structural);
      if (r + 1 < nx) s.add(a + nx, a, 0.02, 2000, 0.0, SpringClass::Structural);
      if (c + 1 < nx && r + 1 < nx) s.add(a, a + nx + 1, 0.02 * std::sqrt(2.0), 500, 0.0, SpringClass::Shear);
      if (c > 0 && r + 1 < nx) s.add(a, a + nx - 1, 0.02 * std::sqrt(2.0), 500 + (c % 3), 0.0, SpringClass::Shear);
      if (c + 2 < nx) s.add(a, a + 2, 0.04, 50, 0.0, SpringClass::Bend);
      if (r + 2 < nx) s.add(a, a + 2 * nx, 0.04, 50 + (r % 2), 0.0, SpringClass::Bend);
    }
  const std::vector<Index> pins{nx * (nx - 1), nx * nx - 1};
  int checked = 0;
  for (HoVariant var : {HoVariant::Velocity, HoVariant::KangCho2011})
    for (bool table : {true, false}) {
      auto scene = make_scene(x, v, m, pins, {0, -9.81, 0}, std::make_unique<TestSpringMaterial>(s, m));
      HoIntegrator ho(var, table, true, HoReorder::None);
      ho.set_tables_on_window(table);
      ho.prepare(*scene, 1e-4);
      ASSERT_TRUE(ho.springs().grouped);
      ASSERT_GT(ho.springs().win_cap, 0);
      EXPECT_TRUE(ho.springs().fuse);   // the default
      int disjoint = 0, overlapping = 0;
      for (const auto& G : ho.springs().segs)
        if (G.step == 1) (G.off >= G.len ? disjoint : overlapping) += 1;
      ASSERT_GT(disjoint, 100);
      ASSERT_GT(overlapping, 100);
      const std::array<double, 3> g{0, -9.81, 0};
      const double* w = scene->state.inv_mass.data();
      auto run = [&](bool window, bool fuse, int threads) {
        omp_set_num_threads(threads);
        HoSprings<double> sp = ho.springs();
        sp.fuse = fuse;
        if (!window) sp.win_cap = 0;
        allocate_ho_window(sp, ho.layout().parts());
        std::vector<double> X = x, V = v, dv(x.size(), 0.0);
        for (int st = 0; st < 12; ++st) {
          if (var == HoVariant::Velocity)
            ho_step_arrays<double, HoVariant::Velocity>(ho.layout(), sp, X.data(), V.data(), dv.data(), nullptr, w,
                                                        1e-4, g);
          else
            ho_step_arrays<double, HoVariant::KangCho2011>(ho.layout(), sp, X.data(), V.data(), dv.data(), nullptr,
                                                           w, 1e-4, g);
        }
        EXPECT_TRUE(std::all_of(dv.begin(), dv.end(), [](double d) { return d == 0.0; }));
        X.insert(X.end(), V.begin(), V.end());
        return X;
      };
      const std::vector<double> plain = run(false, true, 1);
      const std::vector<double> two_pass = run(true, false, 1);
      double change = 0;
      for (int threads : {1, 2}) {
        const std::vector<double> fused = run(true, true, threads);
        ASSERT_EQ(plain.size(), fused.size());
        for (std::size_t q = 0; q < plain.size(); ++q) {
          ASSERT_EQ(two_pass[q], fused[q]) << to_string(var) << " table " << table << " threads " << threads << " entry " << q;
          ASSERT_EQ(plain[q], fused[q]) << to_string(var) << " table " << table << " threads " << threads << " entry " << q;
          change = std::max(change, std::abs(plain[q] - (q < x.size() ? x[q] : v[q - x.size()])));
        }
      }
      EXPECT_GT(change, 1e-6);   // the springs did act
      ++checked;
    }
  omp_set_num_threads(2);
  EXPECT_EQ(checked, 4);
}

// Issue 16: duplicate springs on the same pair (the kang_cho_table1 stencil puts two springs on
// most pairs) give twin segments (SpringSegment::twin: the same i0, len, off and step), whose
// geometry the windowed sweep computes once (ho_window_impulses_twin,
// ho_window_impulses_scatter_twin). Each slot then gets the two segments' additions in the order
// of the two segments run one after the other, so 12 steps give the bits of the windowed sweep
// without twins and of the plain grouped sweep, in every variant, with and without tables, fused
// and two-pass, on 1 and 2 threads. The duplicates have their own rest lengths, stiffnesses and
// dampers (a twin that used its partner's constants would change the result), and the cloth has
// twin pairs of all kinds: unit stride with disjoint and with overlapping ranges, and stride 2.
TEST(HoStorage, TwinSegmentsAreBitIdentical) {
  const int nx = 130;   // rows longer than a block: most blocks hold one row's segments
  std::vector<double> x, v, m;
  perturbed_grid_state(nx, x, v, m);
  int checked = 0;
  for (HoVariant var : {HoVariant::Velocity, HoVariant::AnalyticPosition, HoVariant::KangCho2011}) {
    const double c = var == HoVariant::KangCho2011 ? 0.0 : 0.01;   // kang_cho_2011 has no dampers
    SpringSet s;
    const double d = 0.02, dd = 0.02 * std::sqrt(2.0);
    for (int r = 0; r < nx; ++r)
      for (int col = 0; col < nx; ++col) {
        const int a = r * nx + col;
        if (col + 1 < nx) {
          s.add(a, a + 1, d, 2000, c, SpringClass::Structural);
          s.add(a + 1, a, 1.01 * d, 1500, 2 * c, SpringClass::Structural);   // twin, horizontal: overlapping
        }
        if (r + 1 < nx) {
          s.add(a, a + nx, d, 2000, c, SpringClass::Structural);
          s.add(a + nx, a, 0.99 * d, 2500, 0.5 * c, SpringClass::Structural);   // twin, disjoint
        }
        if (col + 1 < nx && r + 1 < nx) {
          s.add(a, a + nx + 1, dd, 500, c, SpringClass::Shear);
          s.add(a, a + nx + 1, 1.02 * dd, 700, 0.0, SpringClass::Shear);
        }
        if (col > 0 && r + 1 < nx) s.add(a, a + nx - 1, dd, 500 + (col % 3), c, SpringClass::Shear);
        if (col + 2 < nx && (r + col) % 2 == 0) {   // stride-2 twins
          s.add(a, a + 2, 2 * d, 50, c, SpringClass::Bend);
          s.add(a + 2, a, 2.03 * d, 80, 0.0, SpringClass::Bend);
        }
        if (r + 2 < nx) s.add(a, a + 2 * nx, 2 * d, 50, 0.0, SpringClass::Bend);
      }
    const std::vector<Index> pins{nx * (nx - 1), nx * nx - 1};
    for (bool table : {true, false}) {
      auto scene = make_scene(x, v, m, pins, {0, -9.81, 0}, std::make_unique<TestSpringMaterial>(s, m));
      HoIntegrator ho(var, table, true, HoReorder::None);
      ho.set_tables_on_window(table);
      ho.set_merge_springs(false);   // twins are what merge_springs folds away
      ho.prepare(*scene, 1e-4);
      const HoSprings<double>& sp0 = ho.springs();
      ASSERT_TRUE(sp0.grouped);
      ASSERT_GT(sp0.win_cap, 0);
      EXPECT_EQ(sp0.table, table);
      EXPECT_EQ(ho.merged_springs(), 0);
      EXPECT_TRUE(sp0.twins);   // the default
      int disjoint = 0, overlapping = 0, stride2 = 0;
      Index twin_springs = 0;
      for (std::size_t sg = 0; sg < sp0.segs.size(); ++sg) {
        const HoSegment& G = sp0.segs[sg];
        if (!G.twin) continue;
        ASSERT_LT(sg + 1, sp0.segs.size());
        const HoSegment& H = sp0.segs[sg + 1];
        EXPECT_EQ(H.twin, 0);
        for (Index r = 0; r < G.len; ++r) {   // the same endpoints, spring by spring
          ASSERT_EQ(sp0.i[G.begin + r], sp0.i[H.begin + r]);
          ASSERT_EQ(sp0.j[G.begin + r], sp0.j[H.begin + r]);
        }
        twin_springs += 2 * G.len;
        if (G.step == 2) ++stride2;
        else (G.off >= G.len ? disjoint : overlapping) += 1;
      }
      EXPECT_GT(disjoint, 100);
      EXPECT_GT(overlapping, 100);
      EXPECT_GT(stride2, 100);
      // 8 of the 9 springs per vertex (all but the second shear and the vertical bend) are duplicates
      EXPECT_GT(twin_springs, sp0.size() / 2);
      const std::array<double, 3> g{0, -9.81, 0};
      const double* w = scene->state.inv_mass.data();
      auto run = [&](bool window, bool twins, bool fuse, int threads) {
        omp_set_num_threads(threads);
        HoSprings<double> sp = ho.springs();
        sp.twins = twins;
        sp.fuse = fuse;
        if (!window) sp.win_cap = 0;
        allocate_ho_window(sp, ho.layout().parts());
        std::vector<double> X = x, V = v, dv(x.size(), 0.0), dx(x.size(), 0.0);
        for (int st = 0; st < 12; ++st) ho_step_variant(var, ho.layout(), sp, X, V, dv, dx, w, 1e-4, g);
        EXPECT_TRUE(std::all_of(dv.begin(), dv.end(), [](double e) { return e == 0.0; }));
        X.insert(X.end(), V.begin(), V.end());
        return X;
      };
      const std::vector<double> plain = run(false, false, true, 1);
      double change = 0;
      for (bool fuse : {true, false}) {
        const std::vector<double> single = run(true, false, fuse, 1);
        for (int threads : {1, 2}) {
          const std::vector<double> twin = run(true, true, fuse, threads);
          ASSERT_EQ(plain.size(), twin.size());
          for (std::size_t q = 0; q < plain.size(); ++q) {
            ASSERT_EQ(single[q], twin[q]) << to_string(var) << " table " << table << " fuse " << fuse << " threads "
                                          << threads << " entry " << q;
            ASSERT_EQ(plain[q], twin[q]) << to_string(var) << " table " << table << " fuse " << fuse << " threads "
                                         << threads << " entry " << q;
            change = std::max(change, std::abs(plain[q] - (q < x.size() ? x[q] : v[q - x.size()])));
          }
        }
      }
      EXPECT_GT(change, 1e-6);   // the springs did act
      ++checked;
    }
  }
  omp_set_num_threads(2);
  EXPECT_EQ(checked, 6);
}

// Issue 16: merge_springs folds springs on the same two vertices into one whose constants are the
// sums of its members' (HO's impulse is linear in the stretch and the axial velocity, with
// constants that depend on k, c, W and h only). The run with merged springs must agree with the
// run that steps every spring on its own (merge_springs: false) in every variant, with per-spring
// constants and with tables, in the mesh's order and reordered, on groups of two and three
// springs given in either endpoint order with their own stiffnesses, dampers and rest lengths,
// one member of some groups so stiff that omega h = 1 (merging by adding the stiffnesses instead
// of the constants is then off by about 3 %). analytic_position merges only groups whose rest
// lengths are equal. The yardstick is rounding: the merged spring rounds differently from its
// members (its weighted rest length, its summed constants), and a cloth with springs at omega h =
// 1 amplifies a rounding-level difference step after step (measured: positions one ulp off at the
// start differ by 1.6e-12 of the cloth's size and 3e-11 of its speed after 40 steps). So the merged
// run may differ from the unmerged one by at most 4 times what the unmerged run itself moves when
// every seventh coordinate starts one ulp off, plus a few ulps; merging by stiffness instead of
// by constants misses by about 1e-2.
TEST(HoMerge, MergedSpringsAgreeWithEverySpring) {
  const int nx = 40;
  std::vector<double> x, v, m;
  perturbed_grid_state(nx, x, v, m);
  std::vector<double> x_ulp = x;   // every seventh coordinate one ulp larger
  for (std::size_t q = 0; q < x_ulp.size(); q += 7) x_ulp[q] = std::nextafter(x_ulp[q], 10.0);
  const std::vector<Index> pins{nx * (nx - 1), nx * nx - 1};
  for (HoVariant var : {HoVariant::Velocity, HoVariant::AnalyticPosition, HoVariant::KangCho2011}) {
    const double c = var == HoVariant::KangCho2011 ? 0.0 : 0.01;   // kang_cho_2011 has no dampers
    SpringSet s;
    Index equal_extra = 0, all_extra = 0;
    const double d = 0.02, dd = 0.02 * std::sqrt(2.0);
    for (int r = 0; r < nx; ++r)
      for (int col = 0; col < nx; ++col) {
        const int a = r * nx + col;
        if (col + 1 < nx) {   // equal rest lengths
          s.add(a, a + 1, d, 2000, c, SpringClass::Structural);
          s.add(a + 1, a, d, 1500, 2 * c, SpringClass::Structural);
          ++equal_extra;
          ++all_extra;
        }
        if (r + 1 < nx) {   // unequal rest lengths; every fifth with a member at omega h = 1
          s.add(a, a + nx, d, 2000, c, SpringClass::Structural);
          s.add(a + nx, a, 0.99 * d, a % 5 == 0 ? 1e5 : 2500, 0.5 * c, SpringClass::Structural);
          ++all_extra;
        }
        if (col + 1 < nx && r + 1 < nx) {   // groups of three, unequal
          s.add(a, a + nx + 1, dd, 500, c, SpringClass::Shear);
          s.add(a + nx + 1, a, 1.02 * dd, 700, 0.0, SpringClass::Shear);
          s.add(a, a + nx + 1, dd, 300, 3 * c, SpringClass::Shear);
          all_extra += 2;
        }
        if (col + 2 < nx) s.add(a, a + 2, 2 * d, 50, c, SpringClass::Bend);   // alone
      }
    for (const char* order : {"none", "rcm"})
      for (bool table : {true, false}) {
        std::vector<double> res[3];   // every spring, merged, every spring from the state one ulp off
        for (int run : {0, 1, 2}) {
          const bool merge = run == 1;
          auto scene = make_scene(run == 2 ? x_ulp : x, v, m, pins, {0, -9.81, 0},
                                  std::make_unique<TestSpringMaterial>(s, m));
          HoIntegrator ho(Params::from_string(std::string("variant: ") + to_string(var) + "\nreorder: " + order +
                                              "\nstorage: " + (table ? "auto" : "direct") +
                                              (merge ? "\n" : "\nmerge_springs: false\n")));
          ho.set_tables_on_window(table);
          ho.prepare(*scene, 1e-4);
          EXPECT_EQ(ho.reordered(), std::string(order) == "rcm");
          EXPECT_EQ(ho.springs().table, table);
          const Index expect = merge ? (var == HoVariant::AnalyticPosition ? equal_extra : all_extra) : 0;
          EXPECT_EQ(ho.merged_springs(), expect) << to_string(var);
          EXPECT_EQ(ho.springs().size(), s.size() - expect);
          for (int st = 0; st < 40; ++st) ho.step(*scene, 1e-4);
          ho.step(*scene, 5e-5);   // a new h: the merged constants are recomputed from the members
          res[run] = scene->state.x;
          res[run].insert(res[run].end(), scene->state.v.begin(), scene->state.v.end());
        }
        double xs = 0, vs = 0, moved = 0, dx = 0, dv = 0, ux = 0, uv = 0;
        const std::size_t n3 = x.size();
        for (std::size_t q = 0; q < n3; ++q) {
          xs = std::max(xs, std::abs(res[0][q]));
          vs = std::max(vs, std::abs(res[0][n3 + q]));
          moved = std::max(moved, std::abs(res[0][q] - x[q]));
          dx = std::max(dx, std::abs(res[1][q] - res[0][q]));
          dv = std::max(dv, std::abs(res[1][n3 + q] - res[0][n3 + q]));
          ux = std::max(ux, std::abs(res[2][q] - res[0][q]));
          uv = std::max(uv, std::abs(res[2][n3 + q] - res[0][n3 + q]));
        }
        EXPECT_GT(moved, 1e-4);
        const double eps = std::numeric_limits<double>::epsilon();
        EXPECT_LE(dx, 4 * ux + 8 * eps * xs) << to_string(var) << " " << order << " table " << table;
        EXPECT_LE(dv, 4 * uv + 8 * eps * vs) << to_string(var) << " " << order << " table " << table;
        std::printf("[ measured ] %s %s table %d: merged against every spring, x %.1e, v %.1e relative "
                    "(every spring from positions one ulp off: x %.1e, v %.1e)\n",
                    to_string(var), order, table ? 1 : 0, dx / xs, dv / vs, ux / xs, uv / vs);
      }
  }
  EXPECT_THROW(HoIntegrator(Params::from_string("merge_springs: perhaps\n")), InputError);
}

// The block size of the grouping (build_ho_springs' group_block, default kHoGroupBlock) changes
// only the order of the additions into a vertex: 12 velocity steps with blocks of 16, 64, 128 and
// 256 vertices agree with the plain (ungrouped) sweep to rounding; every segment stays inside one
// block.
TEST(HoStorage, GroupBlockSizeOnlyReordersSums) {
  const int nx = 60;
  std::vector<double> x, v, w;
  SpringSet s;
  for (int r = 0; r < nx; ++r)
    for (int c = 0; c < nx; ++c) {
      x.insert(x.end(), {0.02 * c + 0.003 * std::sin(1.3 * r * c), 0.001 * std::sin(0.7 * c + r), 0.02 * r});
      v.insert(v.end(), {0.01 * std::sin(r + 2.0 * c), 0.02 * std::cos(3.0 * r - c), 0.005 * std::sin(c - r)});
      w.push_back(r == nx - 1 && (c == 0 || c == nx - 1) ? 0.0 : 1000.0 / (1 + 0.5 * ((r * 7 + c * 3) % 5)));
      const int a = r * nx + c;
      if (c + 1 < nx) s.add(a, a + 1, 0.02, 2000, 0.0, SpringClass::Structural);
      if (r + 1 < nx) s.add(a + nx, a, 0.02, 2000, 0.01, SpringClass::Structural);
      if (c + 1 < nx && r + 1 < nx) s.add(a, a + nx + 1, 0.02 * std::sqrt(2.0), 500, 0.0, SpringClass::Shear);
      if (r + 2 < nx && (c % 2 == 0)) s.add(a, a + 2 * nx, 0.04, 50, 0.0, SpringClass::Bend);   // step-2 runs
      if (c + 2 < nx && r % 3 == 0) s.add(a, a + 2, 0.04, 50, 0.0, SpringClass::Bend);
    }
  const Index n = nx * nx;
  const std::array<double, 3> g{0, -9.81, 0};
  auto run = [&](bool grouped, Index block) {
    SpringLayout layout;
    HoSprings<double> sp;
    build_ho_springs(n, s, layout, sp, grouped, block);
    EXPECT_EQ(sp.grouped, grouped);
    if (grouped) {
      EXPECT_GT(sp.win_cap, 0);
      for (int p = 0; p < layout.parts(); ++p)
        for (Index bk = sp.part_block[p]; bk < sp.part_block[p + 1]; ++bk)
          for (Index sg = sp.blocks[bk].seg_begin; sg < sp.blocks[bk].seg_end; ++sg) {
            const HoSegment& G = sp.segs[sg];
            const Index last = G.i0 + G.step * (G.len - 1);
            EXPECT_LE(G.len, block);
            EXPECT_EQ((G.i0 - layout.part_vertex_begin(p)) / block, (last - layout.part_vertex_begin(p)) / block);
            EXPECT_LT(last, sp.blocks[bk].vertex_end);
          }
    }
    update_ho_coefficients(sp, HoVariant::Velocity, w.data(), 1e-4);
    std::vector<double> X = x, V = v, dv(x.size(), 0.0);
    for (int st = 0; st < 12; ++st)
      ho_step_arrays<double, HoVariant::Velocity>(layout, sp, X.data(), V.data(), dv.data(), nullptr, w.data(), 1e-4,
                                                  g);
    X.insert(X.end(), V.begin(), V.end());
    return X;
  };
  const std::vector<double> plain = run(false, kSpringGroupBlock);
  double scale = 0, change = 0;
  for (std::size_t q = 0; q < plain.size(); ++q) {
    scale = std::max(scale, std::abs(plain[q]));
    change = std::max(change, std::abs(plain[q] - (q < x.size() ? x[q] : v[q - x.size()])));
  }
  EXPECT_GT(change, 1e-6);   // the springs did act
  for (Index block : {16, 64, 128, 256}) {
    const std::vector<double> res = run(true, block);
    double err = 0;
    for (std::size_t q = 0; q < plain.size(); ++q) err = std::max(err, std::abs(res[q] - plain[q]));
    EXPECT_LE(err, 1e-13 * scale) << "block " << block;
  }
}

// ---- Vertex order (reorder key): RCM order, user-visible results unchanged ----

namespace {

// A 2D grid mesh (nx x nx, spacing 0.02) whose vertices are numbered in a random order: user
// vertex pi[g] holds grid vertex g. Structural, shear and bend springs, some damped.
struct ShuffledGrid {
  int nx;
  std::vector<Index> pi;
  std::vector<double> x, v, m;
  SpringSet s;
  std::vector<Index> pins;
  ShuffledGrid(int nx_, unsigned seed, bool shuffle = true) : nx(nx_) {
    const int n = nx * nx;
    pi.resize(n);
    std::iota(pi.begin(), pi.end(), 0);
    if (shuffle) std::shuffle(pi.begin(), pi.end(), std::mt19937(seed));
    x.resize(3 * n);
    v.resize(3 * n);
    m.resize(n);
    for (int r = 0; r < nx; ++r)
      for (int c = 0; c < nx; ++c) {
        const Index u = pi[r * nx + c];
        const double p[3] = {0.02 * c, 0.001 * std::sin(0.7 * c + r), 0.02 * r};
        const double w[3] = {0.01 * std::sin(r + 2.0 * c), 0.02 * std::cos(3.0 * r - c), 0.005 * std::sin(5.0 * c)};
        for (int e = 0; e < 3; ++e) {
          x[3 * u + e] = p[e];
          v[3 * u + e] = w[e];
        }
        m[u] = 1e-3 * (1 + 0.5 * ((r * 7 + c * 3) % 5));
      }
    for (int r = 0; r < nx; ++r)
      for (int c = 0; c < nx; ++c) {
        const int a = r * nx + c;
        auto add = [&](int b, double l0, double k, double damp, SpringClass cl) { s.add(pi[a], pi[b], l0, k, damp, cl); };
        if (c + 1 < nx) add(a + 1, 0.02, 2000, 0.02, SpringClass::Structural);
        if (r + 1 < nx) add(a + nx, 0.02, 2000, 0.0, SpringClass::Structural);
        if (c + 1 < nx && r + 1 < nx) add(a + nx + 1, 0.02 * std::sqrt(2.0), 500, 0.0, SpringClass::Shear);
        if (c > 0 && r + 1 < nx) add(a + nx - 1, 0.02 * std::sqrt(2.0), 500, 0.0, SpringClass::Shear);
        if (c + 2 < nx) add(a + 2, 0.04, 50, 0.0, SpringClass::Bend);
      }
    pins = {pi[nx * (nx - 1)], pi[nx * nx - 1]};
  }
};

}  // namespace

TEST(VertexOrder, RcmIsAPermutationThatShrinksTheSpan) {
  const ShuffledGrid g(60, 11);
  const Index n = static_cast<Index>(g.m.size());
  const VertexOrder o = rcm_order(n, g.s.i, g.s.j);
  ASSERT_EQ(o.perm.size(), static_cast<std::size_t>(n));
  std::vector<int> seen(n, 0);
  for (Index k = 0; k < n; ++k) {
    ++seen[o.perm[k]];
    EXPECT_EQ(o.inv[o.perm[k]], k);
  }
  for (int c : seen) ASSERT_EQ(c, 1);
  // every spring of the RCM order joins vertices at most one BFS level apart: its span is at
  // most about two grid diagonals (the widest level of a 60 x 60 grid has <= 120 vertices)
  Index maxspan = 0;
  for (Index q = 0; q < g.s.size(); ++q) maxspan = std::max(maxspan, std::abs(o.inv[g.s.i[q]] - o.inv[g.s.j[q]]));
  EXPECT_LE(maxspan, 4 * 60);
  const double user = mean_spring_span(g.s.i, g.s.j), rcm = mean_spring_span(g.s.i, g.s.j, &o);
  EXPECT_GT(user, 1000.0);   // a random numbering: about n/3
  EXPECT_LT(rcm, 120.0);
  // a path given in a shuffled order becomes 0-1-2-... (span 1), and disconnected pieces and
  // isolated vertices are all placed
  std::vector<Index> perm(10);
  std::iota(perm.begin(), perm.end(), 0);
  std::shuffle(perm.begin(), perm.end(), std::mt19937(5));
  std::vector<Index> pi_, pj_;
  for (int q = 0; q + 1 < 7; ++q) {   // path over perm[0..6]; perm[7], perm[8] joined; perm[9] alone
    pi_.push_back(perm[q]);
    pj_.push_back(perm[q + 1]);
  }
  pi_.push_back(perm[7]);
  pj_.push_back(perm[8]);
  const VertexOrder p = rcm_order(10, pi_, pj_);
  ASSERT_EQ(p.perm.size(), 10u);
  for (std::size_t q = 0; q < pi_.size(); ++q) EXPECT_EQ(std::abs(p.inv[pi_[q]] - p.inv[pj_[q]]), 1);
  // gather and scatter are inverse
  std::vector<double> a(30), b(30), c(30);
  for (int q = 0; q < 30; ++q) a[q] = q * 1.5;
  gather_vertices<3>(p, a.data(), b.data());
  for (int k = 0; k < 10; ++k) EXPECT_EQ(b[3 * k + 1], a[3 * p.perm[k] + 1]);
  scatter_vertices<3>(p, b.data(), c.data());
  EXPECT_EQ(a, c);
  std::vector<double> d(30), e2(30), f2(30), g2(30);
  for (int q = 0; q < 30; ++q) d[q] = -q * 0.5;
  gather_state(p, a.data(), d.data(), e2.data(), f2.data());
  EXPECT_EQ(e2, b);
  for (int k = 0; k < 10; ++k) EXPECT_EQ(f2[3 * k + 2], d[3 * p.perm[k] + 2]);
  scatter_state(p, e2.data(), f2.data(), c.data(), g2.data());
  EXPECT_EQ(c, a);
  EXPECT_EQ(g2, d);
}

// A run in the RCM order equals the run in the user's order to rounding, and is reported in
// the user's numbering (positions, velocities; pinned vertices bit for bit), for every variant.
TEST(HoReorder, ReorderedRunEqualsUserOrderRun) {
  const ShuffledGrid g(40, 7);
  for (HoVariant var : {HoVariant::Velocity, HoVariant::AnalyticPosition, HoVariant::KangCho2011}) {
    SpringSet s = g.s;
    if (var == HoVariant::KangCho2011)
      for (double& c : s.damping) c = 0;
    std::vector<double> res[2];
    for (int ro : {0, 1}) {
      auto scene = make_scene(g.x, g.v, g.m, g.pins, {0, -9.81, 0}, std::make_unique<TestSpringMaterial>(s, g.m));
      HoIntegrator ho(var, true, true, ro ? HoReorder::Rcm : HoReorder::None);
      ho.prepare(*scene, 1e-4);
      EXPECT_EQ(ho.reordered(), ro == 1);
      for (int st = 0; st < 60; ++st) ho.step(*scene, 1e-4);
      for (Index p : g.pins)
        for (int e = 0; e < 3; ++e) EXPECT_EQ(scene->state.x[3 * p + e], g.x[3 * p + e]);
      res[ro] = scene->state.x;
      res[ro].insert(res[ro].end(), scene->state.v.begin(), scene->state.v.end());
    }
    // the runs differ only in the order of the additions into each vertex
    double scale_x = 0, scale_v = 0, moved = 0;
    const std::size_t m3 = g.x.size();
    for (std::size_t q = 0; q < m3; ++q) {
      scale_x = std::max(scale_x, std::abs(res[0][q]));
      scale_v = std::max(scale_v, std::abs(res[0][m3 + q]));
      moved = std::max(moved, std::abs(res[0][q] - g.x[q]));
    }
    EXPECT_GT(moved, 1e-6) << to_string(var);   // the cloth moved (the comparison means something)
    for (std::size_t q = 0; q < m3; ++q) {
      ASSERT_NEAR(res[1][q], res[0][q], 1e-13 * scale_x) << to_string(var) << " x " << q;
      ASSERT_NEAR(res[1][m3 + q], res[0][m3 + q], 1e-11 * scale_v) << to_string(var) << " v " << q;
    }
  }
}

// reorder: auto reorders a large shuffled mesh and keeps a grid numbered row by row; the key is
// declared and checked.
TEST(HoReorder, AutoRuleAndParameter) {
  for (bool shuffle : {true, false}) {
    const ShuffledGrid g(130, 3, shuffle);   // 16900 vertices >= kHoReorderMinVertices
    auto scene = make_scene(g.x, g.v, g.m, g.pins, {0, -9.81, 0}, std::make_unique<TestSpringMaterial>(g.s, g.m));
    HoIntegrator ho(HoVariant::Velocity);
    ho.prepare(*scene, 1e-4);
    EXPECT_EQ(ho.reordered(), shuffle);
  }
  EXPECT_FALSE(ho_reorder_pays(kHoReorderMinVertices - 1, 1000.0, 1.0));
  EXPECT_TRUE(ho_reorder_pays(kHoReorderMinVertices, 4.0, 1.0));
  EXPECT_FALSE(ho_reorder_pays(kHoReorderMinVertices, 3.9, 1.0));
  EXPECT_EQ(HoIntegrator(Params::from_string("reorder: rcm\n")).reorder_mode(), HoReorder::Rcm);
  EXPECT_EQ(HoIntegrator(Params::from_string("reorder: none\n")).reorder_mode(), HoReorder::None);
  EXPECT_EQ(HoIntegrator(Params::from_string("variant: velocity\n")).reorder_mode(), HoReorder::Auto);
  EXPECT_THROW(HoIntegrator(Params::from_string("reorder: metis\n")), InputError);
}

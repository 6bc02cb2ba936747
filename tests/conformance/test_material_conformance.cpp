// Every material plugin of the build, with its default parameters and again wrapped in the
// framework's hinge bending (exact Jacobian), must satisfy what any elastic model satisfies,
// independently of its formulas:
//  * zero force and zero energy in the rest configuration;
//  * forces at a random deformation equal minus the gradient of elastic_energy (central
//    differences of the energy: an independent computation of the same quantity);
//  * df/dx and df/dv equal central differences of compute_forces (in a stretched state, where
//    no compression clamp or PSD projection is active, so the exact Jacobian is the one built);
//  * energy and forces are invariant under a rigid motion: E(Rx + t) = E(x),
//    f(Rx + t, Rv) = R f(x, v).
// The plugins come from the loader (conformance.hpp): a new material is covered without an edit.
#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <random>

#include "conformance.hpp"
#include "loom/bending.hpp"
#include "loom/bsr.hpp"

namespace {

using loom::Index;
using loom::Material;
using loom::Params;
namespace lc = loom::conformance;

struct Case {
  std::string name;
  bool bending = false;
};

std::string case_name(const testing::TestParamInfo<Case>& i) {
  return i.param.name + (i.param.bending ? "_with_bending" : "");
}

std::vector<Case> cases() {
  std::vector<Case> c;
  for (const auto& n : lc::plugin_names(loom::PluginKind::Material)) {
    c.push_back({n, false});
    c.push_back({n, true});
  }
  return c;
}

double max_abs(const std::vector<double>& v) {
  double m = 0;
  for (double x : v) m = std::max(m, std::abs(x));
  return m;
}

struct MaterialConformance : testing::TestWithParam<Case> {
  // A small grid, not square, so that the stencils and the triangles are not all alike.
  loom::Mesh mesh = loom::make_grid(5, 4, 1.0, 0.8);
  std::unique_ptr<Material> mat;
  std::vector<double> rest;
  Index n = 0;
  double spacing = 0.25;

  void SetUp() override {
    const Case& c = GetParam();
    auto& l = lc::plugins();
    if (!l.reg.has(loom::PluginKind::Material, c.name))
      GTEST_SKIP() << "material plugin '" << c.name << "' is not built here (no loom_material_" << c.name
                   << ".so in " << LOOM_PLUGIN_DIR << ")";
    const std::string yaml = lc::required_keys(c.name);
    try {
      mat = l.reg.make_material(c.name, "cpu", Params::from_string(yaml.empty() ? "{}" : yaml, "conformance.yaml"),
                                mesh);
    } catch (const loom::InputError& e) {
      FAIL() << c.name << " cannot be built with its defaults (" << e.what()
             << "); add its required keys to required_keys() in tests/conformance/conformance.cpp";
    }
    if (c.bending)
      mat = loom::add_bending(std::move(mat), Params::from_string("{stiffness: 1.0e-3, jacobian: exact}"), mesh, "cpu");
    rest = mesh.positions;
    n = mesh.num_vertices();
  }

  std::vector<double> forces(const std::vector<double>& x, const std::vector<double>& v) const {
    std::vector<double> f(3 * n, 0.0);
    mat->compute_forces(x, v, f);
    return f;
  }

  // rest + amplitude * spacing * (uniform noise in [-1, 1]^3), after scaling about the centroid.
  std::vector<double> deformed(double scale, double amplitude, unsigned seed) const {
    std::mt19937 rng(seed);
    std::uniform_real_distribution<double> u(-1.0, 1.0);
    double c[3] = {0, 0, 0};
    for (Index i = 0; i < n; ++i)
      for (int e = 0; e < 3; ++e) c[e] += rest[3 * i + e] / n;
    std::vector<double> x(3 * n);
    for (Index i = 0; i < n; ++i)
      for (int e = 0; e < 3; ++e) x[3 * i + e] = c[e] + scale * (rest[3 * i + e] - c[e]) + amplitude * spacing * u(rng);
    return x;
  }
  std::vector<double> random_velocity(unsigned seed) const {
    std::mt19937 rng(seed);
    std::uniform_real_distribution<double> u(-1.0, 1.0);
    std::vector<double> v(3 * n);
    for (double& q : v) q = u(rng);
    return v;
  }
};

TEST_P(MaterialConformance, MassesArePositive) {
  std::vector<double> m(n, -1.0);
  mat->compute_masses(m);
  for (double q : m) EXPECT_TRUE(q > 0 && std::isfinite(q)) << q;
}

TEST_P(MaterialConformance, ZeroForceAndEnergyAtRest) {
  const std::vector<double> zero(3 * n, 0.0);
  const auto x = deformed(1.0, 0.05, 1);
  const double f_scale = max_abs(forces(x, zero));
  const double e_scale = mat->elastic_energy(x);
  ASSERT_GT(f_scale, 0) << "no force at a 5% random deformation: the test would not see anything";
  ASSERT_GT(e_scale, 0);
  EXPECT_LE(max_abs(forces(rest, zero)), 1e-12 * f_scale);
  EXPECT_LE(std::abs(mat->elastic_energy(rest)), 1e-12 * e_scale);
}

TEST_P(MaterialConformance, ForcesAreMinusTheEnergyGradient) {
  // Random deformation, some elements compressed and some stretched, out of the plane too.
  const std::vector<double> zero(3 * n, 0.0);
  auto x = deformed(1.0, 0.05, 2);
  const auto f = forces(x, zero);
  // Central differences: truncation O(eps^2 E''') and rounding ~1e-16 E / eps, both far below
  // the 1e-6 relative tolerance at eps = 1e-6 spacing.
  const double eps = 1e-6 * spacing;
  double worst = 0;
  for (Index k = 0; k < 3 * n; ++k) {
    const double x0 = x[k];
    x[k] = x0 + eps;
    const double ep = mat->elastic_energy(x);
    x[k] = x0 - eps;
    const double em = mat->elastic_energy(x);
    x[k] = x0;
    worst = std::max(worst, std::abs(f[k] + (ep - em) / (2 * eps)));
  }
  EXPECT_LE(worst, 1e-6 * max_abs(f)) << "max |f + dE/dx| against max |f| = " << max_abs(f);
}

TEST_P(MaterialConformance, JacobiansMatchFiniteDifferencesOfTheForces) {
  if (!mat->has_jacobian()) GTEST_SKIP() << GetParam().name << " has no Jacobian";
  // 5% stretched about the centroid plus small noise: every element in tension, so no clamp of
  // compressed springs and no PSD projection changes the exact Jacobian.
  auto x = deformed(1.05, 0.003, 3);
  auto v = random_velocity(4);
  std::vector<std::array<Index, 2>> pairs;
  mat->jacobian_pairs(pairs);
  const auto pattern = loom::BsrPattern::from_pairs(n, pairs);
  mat->bind_pattern(pattern);
  loom::BsrMatrix dfdx(&pattern), dfdv(&pattern);
  mat->compute_jacobians(x, v, dfdx, &dfdv);
  const auto Jx = dfdx.to_dense(), Jv = dfdv.to_dense();
  const std::size_t N = static_cast<std::size_t>(3 * n);
  const double eps = 1e-7 * spacing;
  double worst_x = 0, worst_v = 0, scale_x = max_abs(Jx), scale_v = max_abs(Jv);
  ASSERT_GT(scale_x, 0);
  for (std::size_t c = 0; c < N; ++c) {
    for (auto* y : {&x, &v}) {
      const double y0 = (*y)[c];
      (*y)[c] = y0 + eps;
      const auto fp = forces(x, v);
      (*y)[c] = y0 - eps;
      const auto fm = forces(x, v);
      (*y)[c] = y0;
      const auto& J = y == &x ? Jx : Jv;
      double& worst = y == &x ? worst_x : worst_v;
      for (std::size_t r = 0; r < N; ++r)
        worst = std::max(worst, std::abs(J[r * N + c] - (fp[r] - fm[r]) / (2 * eps)));
    }
  }
  EXPECT_LE(worst_x, 1e-6 * scale_x) << "df/dx against central differences of the forces";
  EXPECT_LE(worst_v, 1e-6 * std::max(scale_v, 1e-12 * scale_x)) << "df/dv against central differences";
}

TEST_P(MaterialConformance, RigidMotionChangesNeitherEnergyNorForces) {
  const auto x = deformed(1.02, 0.05, 5);
  const auto v = random_velocity(6);
  // Rotation by 0.7 rad about the unit axis a (Rodrigues), then a translation.
  const double a[3] = {1 / std::sqrt(14.0), 2 / std::sqrt(14.0), 3 / std::sqrt(14.0)};
  const double th = 0.7, c = std::cos(th), s = std::sin(th);
  double R[3][3];
  for (int i = 0; i < 3; ++i)
    for (int j = 0; j < 3; ++j) R[i][j] = (i == j ? c : 0.0) + (1 - c) * a[i] * a[j];
  R[0][1] -= s * a[2]; R[0][2] += s * a[1];
  R[1][0] += s * a[2]; R[1][2] -= s * a[0];
  R[2][0] -= s * a[1]; R[2][1] += s * a[0];
  const double t[3] = {0.3, -1.2, 2.0};
  auto rotate = [&](const std::vector<double>& y, bool translate) {
    std::vector<double> out(y.size());
    for (Index q = 0; q < n; ++q)
      for (int i = 0; i < 3; ++i) {
        double acc = translate ? t[i] : 0.0;
        for (int j = 0; j < 3; ++j) acc += R[i][j] * y[3 * q + j];
        out[3 * q + i] = acc;
      }
    return out;
  };
  const double e = mat->elastic_energy(x);
  EXPECT_NEAR(mat->elastic_energy(rotate(x, true)), e, 1e-10 * std::abs(e));
  const auto f = forces(x, v);
  const auto Rf = rotate(f, false);
  const auto fR = forces(rotate(x, true), rotate(v, false));
  double worst = 0;
  for (std::size_t k = 0; k < f.size(); ++k) worst = std::max(worst, std::abs(fR[k] - Rf[k]));
  EXPECT_LE(worst, 1e-10 * max_abs(f));
}

INSTANTIATE_TEST_SUITE_P(EveryMaterial, MaterialConformance, testing::ValuesIn(cases()), case_name);

}  // namespace

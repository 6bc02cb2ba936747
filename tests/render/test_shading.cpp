// CPU shading math of the woven-fabric renderer (loom/kernels/shading.glsl via shading.hpp):
// MDF normalisation, weave elements, eq. 13 normals, MDF rotation (eqs. 17-19).
#include <gtest/gtest.h>

#include <cmath>
#include <cstdio>
#include <random>
#include <string>
#include <vector>

#include "loom/kernels/shading.hpp"

using namespace loom::shading;

namespace {

constexpr double kPi = 3.14159265358979323846;

// Midpoint rule over the hemisphere in (theta, phi) of D(h) cos(theta) (the projected MDF),
// with h built by `frame` from the spherical direction (identity for the plain MDF).
template <class D>
double projected_integral(D mdf, int n_theta, int n_phi) {
  double sum = 0.0;
  const double dt = 0.5 * kPi / n_theta, dp = 2.0 * kPi / n_phi;
  for (int a = 0; a < n_theta; ++a) {
    const double t = (a + 0.5) * dt;
    const double st = std::sin(t), ct = std::cos(t);
    double ring = 0.0;
    for (int b = 0; b < n_phi; ++b) {
      const double p = (b + 0.5) * dp;
      const vec3 h(float(st * std::cos(p)), float(st * std::sin(p)), float(ct));
      ring += mdf(h);
    }
    sum += ring * ct * st;
  }
  return sum * dt * dp;
}

// Integral over the whole sphere of D(T(h)) max(h . n, 0): the projected MDF seen from a
// perturbed normal n. Midpoint rule in (theta, phi) around n's own pole.
template <class D>
double projected_integral_about(vec3 n, D mdf, int n_theta, int n_phi) {
  const vec3 a = std::abs(n.x) < 0.9f ? vec3(1, 0, 0) : vec3(0, 1, 0);
  const vec3 t = glm::normalize(a - n * glm::dot(a, n));
  const vec3 b = glm::cross(n, t);
  double sum = 0.0;
  const double dt = 0.5 * kPi / n_theta, dp = 2.0 * kPi / n_phi;
  for (int i = 0; i < n_theta; ++i) {
    const double th = (i + 0.5) * dt;
    const double st = std::sin(th), ct = std::cos(th);
    double ring = 0.0;
    for (int k = 0; k < n_phi; ++k) {
      const double p = (k + 0.5) * dp;
      const vec3 h = t * float(st * std::cos(p)) + b * float(st * std::sin(p)) + n * float(ct);
      ring += mdf(glm::normalize(h));
    }
    sum += ring * ct * st;
  }
  return sum * dt * dp;
}

Fabric test_fabric() {
  Fabric f{};
  f.n_w = 2;
  f.n_pi = 1;
  f.n_sigma = 1;
  f.density_u = f.density_v = 10.0f;
  f.yarn_curvature = 0.6f;
  f.fibre_curvature = 0.3f;
  f.fibre_slope = 0.5f;
  f.twists = 2.0f;
  f.mdf = LOOM_MDF_WARD;
  f.alpha_along = 0.15f;
  f.alpha_across = 0.5f;
  f.mode = LOOM_MODE_ROTATE_EXACT;
  f.weft_color = vec3(0.6f, 0.2f, 0.2f);
  f.warp_color = vec3(0.2f, 0.2f, 0.6f);
  f.specular = vec3(0.1f);
  return f;
}

}  // namespace

// ---- MDF normalisation -------------------------------------------------------------------

TEST(ShadingMdf, WardProjectedIntegralIsOne) {
  const float cases[][2] = {{0.1f, 0.1f}, {0.1f, 0.5f}, {0.5f, 0.1f}, {0.3f, 0.8f}, {1.0f, 1.0f}, {0.05f, 0.6f}};
  for (const auto& c : cases) {
    const double I = projected_integral([&](vec3 h) { return double(ward_mdf(h, c[0], c[1])); }, 4000, 256);
    std::printf("  Ward ax=%.2f ay=%.2f: integral - 1 = %+.2e\n", c[0], c[1], I - 1.0);
    EXPECT_NEAR(I, 1.0, 1e-4) << "ax=" << c[0] << " ay=" << c[1];
  }
}

TEST(ShadingMdf, AshikhminProjectedIntegralIsOne) {
  const float cases[][2] = {{0.0f, 0.0f}, {1.0f, 1.0f}, {10.0f, 100.0f}, {100.0f, 10.0f}, {1000.0f, 50.0f}, {398.0f, 6.0f}};
  for (const auto& c : cases) {
    const double I = projected_integral([&](vec3 h) { return double(ashikhmin_mdf(h, c[0], c[1])); }, 4000, 256);
    std::printf("  Ashikhmin nu=%.0f nv=%.0f: integral - 1 = %+.2e\n", c[0], c[1], I - 1.0);
    EXPECT_NEAR(I, 1.0, 1e-4) << "nu=" << c[0] << " nv=" << c[1];
    // The original Ashikhmin-Shirley constant sqrt((nu+1)(nv+1))/(2 pi) normalises D, not D cos:
    // its projected integral would be sqrt((nu+1)(nv+1)/((nu+2)(nv+2))), visibly below 1.
    const double as_paper = std::sqrt((c[0] + 1.0) * (c[1] + 1.0) / ((c[0] + 2.0) * (c[1] + 2.0)));
    if (c[0] < 200 && c[1] < 200) {
      EXPECT_GT(std::abs(I - as_paper), 4e-3);
    }
  }
}

TEST(ShadingMdf, QuadratureConvergesAtSecondOrder) {
  // Midpoint rule on a smooth integrand: the error drops ~4x per halving of the step.
  auto I = [](int n) { return projected_integral([](vec3 h) { return double(ward_mdf(h, 0.3f, 0.6f)); }, n, n); };
  const double e1 = std::abs(I(16) - 1.0), e2 = std::abs(I(32) - 1.0), e3 = std::abs(I(64) - 1.0);
  const double p1 = std::log2(e1 / e2), p2 = std::log2(e2 / e3);
  std::printf("  midpoint quadrature of the Ward projected MDF: errors %.3e %.3e %.3e, orders %.2f %.2f\n", e1, e2, e3,
              p1, p2);
  EXPECT_GT(p1, 1.7);
  EXPECT_GT(p2, 1.7);
  EXPECT_LT(e3, 1e-3);
}

TEST(ShadingMdf, RotatedMdfStaysNormalisedAboutThePerturbedNormal) {
  // Rotating the MDF onto n~ moves its lobe; the projected integral taken about n~ is still 1,
  // for the exact frame and for the paper's (eq. 17) one.
  const vec3 n = perturbed_normal(1.0f, 0.8f, 0.3f, 0.6f, 2.0f, 0.5f, 0.3f);
  for (float mode : {LOOM_MODE_ROTATE_EXACT, LOOM_MODE_ROTATE_PAPER}) {
    const double Iw = projected_integral_about(
        n, [&](vec3 h) { return double(ward_mdf(mdf_half_vector(h, n, mode), 0.2f, 0.5f)); }, 2000, 256);
    const double Ia = projected_integral_about(
        n, [&](vec3 h) { return double(ashikhmin_mdf(mdf_half_vector(h, n, mode), 40.0f, 6.0f)); }, 2000, 256);
    EXPECT_NEAR(Iw, 1.0, 1e-4) << "mode " << mode;
    EXPECT_NEAR(Ia, 1.0, 1e-4) << "mode " << mode;
  }
}

TEST(ShadingMdf, ZeroBelowTheHorizonAndPeakAtTheNormal) {
  EXPECT_EQ(ward_mdf(vec3(0.3f, 0.2f, -0.1f), 0.2f, 0.4f), 0.0f);
  EXPECT_EQ(ashikhmin_mdf(vec3(0.3f, 0.2f, -0.1f), 10.0f, 10.0f), 0.0f);
  EXPECT_NEAR(ward_mdf(vec3(0, 0, 1), 0.2f, 0.4f), 1.0 / (kPi * 0.08), 1e-4);
  EXPECT_NEAR(ashikhmin_mdf(vec3(0, 0, 1), 10.0f, 40.0f), std::sqrt(12.0 * 42.0) / (2 * kPi), 1e-4);
  // Anisotropy: the lobe is wider along the axis with the larger roughness.
  const vec3 hx = glm::normalize(vec3(0.2f, 0, 1)), hy = glm::normalize(vec3(0, 0.2f, 1));
  EXPECT_LT(ward_mdf(hx, 0.1f, 0.5f), ward_mdf(hy, 0.1f, 0.5f));
  EXPECT_GT(ashikhmin_mdf(hx, 10.0f, 200.0f), ashikhmin_mdf(hy, 10.0f, 200.0f));
}

// ---- weave elements (section 4.2) --------------------------------------------------------

namespace {
// Rows of the pattern as strings ('-' weft, '|' warp) for i = 0..cols-1, j = 0..rows-1.
std::vector<std::string> pattern(float nw, float npi, float ns, int cols, int rows) {
  std::vector<std::string> out;
  for (int j = 0; j < rows; ++j) {
    std::string r;
    for (int i = 0; i < cols; ++i) r += weave_is_warp(float(i), float(j), nw, npi, ns) > 0.5f ? '|' : '-';
    out.push_back(r);
  }
  return out;
}
}  // namespace

TEST(ShadingWeave, HandWorkedPatterns) {
  // Plain (1,1,1): a checkerboard.
  EXPECT_EQ(pattern(1, 1, 1, 6, 3), (std::vector<std::string>{"-|-|-|", "|-|-|-", "-|-|-|"}));
  // 1/2 twill (1,2,1) as in the paper's text.
  EXPECT_EQ(pattern(1, 2, 1, 6, 3), (std::vector<std::string>{"-||-||", "|-||-|", "||-||-"}));
  // 2/1 twill (2,1,1), Fig. 10 (b): the warp float moves one element per row.
  EXPECT_EQ(pattern(2, 1, 1, 6, 4), (std::vector<std::string>{"--|--|", "|--|--", "-|--|-", "--|--|"}));
  // 4/1 twill (4,1,1), Fig. 10 (c).
  EXPECT_EQ(pattern(4, 1, 1, 5, 5), (std::vector<std::string>{"----|", "|----", "-|---", "--|--", "---|-"}));
  // Satin (5,1,2): period 6, shift 2.
  EXPECT_EQ(pattern(5, 1, 2, 6, 4), (std::vector<std::string>{"-----|", "-|----", "---|--", "-----|"}));
  // Silk-like (0,100,1): warp everywhere.
  for (const auto& r : pattern(0, 100, 1, 7, 3)) EXPECT_EQ(r, "|||||||");
}

TEST(ShadingWeave, NegativeIndicesContinueThePattern) {
  // mod() keeps the pattern periodic through u, v < 0.
  for (int j = -7; j < 7; ++j)
    for (int i = -9; i < 9; ++i) {
      EXPECT_EQ(weave_is_warp(float(i), float(j), 1, 1, 1), float(((i + j) % 2 + 2) % 2)) << i << "," << j;
      EXPECT_EQ(weave_is_warp(float(i), float(j), 4, 1, 1), weave_is_warp(float(i + 5), float(j), 4, 1, 1));
      EXPECT_EQ(weave_is_warp(float(i), float(j), 4, 1, 1), weave_is_warp(float(i + 1), float(j + 1), 4, 1, 1));
    }
}

TEST(ShadingWeave, EveryRowHasNwWeftElementsPerPeriod) {
  const float pats[][3] = {{1, 1, 1}, {2, 1, 1}, {4, 1, 1}, {5, 1, 2}, {3, 2, 1}, {1, 3, 2}};
  for (const auto& p : pats) {
    const int period = int(p[0] + p[1]);
    for (int j = 0; j < 2 * period; ++j) {
      int weft = 0;
      for (int i = 0; i < period; ++i) weft += weave_is_warp(float(i), float(j), p[0], p[1], p[2]) < 0.5f;
      EXPECT_EQ(weft, int(p[0]));
      // The next row is this row shifted by n_sigma.
      for (int i = 0; i < period; ++i)
        EXPECT_EQ(weave_is_warp(float(i), float(j), p[0], p[1], p[2]),
                  weave_is_warp(float(i + p[2]), float(j + 1), p[0], p[1], p[2]));
    }
  }
}

// ---- perturbed normals (eq. 13) ----------------------------------------------------------

TEST(ShadingNormals, HandWorkedEq13) {
  const float cy = 0.6f, N = 2.0f, sf = 0.5f, cf = 0.3f;
  // Warp at (fu, fv) = (0.75, 0.4): sigma^u = 0.5, x = c_y 0.5 = 0.3;
  // y = c_f (2 fract(2 (0.4 - 0.5 * 0.5)) - 1) = 0.3 (2 * 0.3 - 1) = -0.12.
  vec3 n = perturbed_normal(1.0f, 0.75f, 0.4f, cy, N, sf, cf);
  EXPECT_NEAR(n.x, 0.3f, 1e-6f);
  EXPECT_NEAR(n.y, -0.12f, 1e-6f);
  EXPECT_NEAR(n.z, std::sqrt(1.0f - 0.09f - 0.0144f), 1e-6f);
  // Weft at (0.3, 0.9): sigma^v = 0.8, y = 0.48; x = 0.3 (2 fract(2 (0.3 - 0.4)) - 1) = 0.3 (2 * 0.8 - 1) = 0.18.
  n = perturbed_normal(0.0f, 0.3f, 0.9f, cy, N, sf, cf);
  EXPECT_NEAR(n.x, 0.18f, 1e-6f);
  EXPECT_NEAR(n.y, 0.48f, 1e-6f);
  // Filament yarn (N = 0): no twist term, only the yarn curvature.
  n = perturbed_normal(0.0f, 0.3f, 0.9f, cy, 0.0f, sf, cf);
  EXPECT_EQ(n.x, 0.0f);
  EXPECT_NEAR(n.y, 0.48f, 1e-6f);
  // Yarn centre line (sigma = 0) without twist: the unperturbed normal.
  n = perturbed_normal(1.0f, 0.5f, 0.1f, cy, 0.0f, sf, cf);
  EXPECT_EQ(n, vec3(0, 0, 1));
}

TEST(ShadingNormals, UnitLengthEverywhere) {
  for (float warp : {0.0f, 1.0f})
    for (int a = 0; a < 64; ++a)
      for (int b = 0; b < 64; ++b) {
        const vec3 n = perturbed_normal(warp, a / 64.0f, b / 64.0f, 0.8f, 3.0f, 0.7f, 0.59f);
        ASSERT_NEAR(glm::length(n), 1.0f, 2e-6f);
        ASSERT_GT(n.z, 0.0f);
      }
}

TEST(ShadingNormals, TwistIsContinuousAlongTheYarnForWholeN) {
  // Across the boundary between two elements along a weft yarn (fu: 1 -> 0) the twist phase
  // changes by N, a whole number: the fibre pattern continues.
  for (float N : {1.0f, 3.0f})
    for (float fv : {0.13f, 0.42f, 0.77f}) {
      const vec3 a = perturbed_normal(0.0f, 1.0f - 1e-5f, fv, 0.5f, N, 0.5f, 0.3f);
      const vec3 b = perturbed_normal(0.0f, 0.0f, fv, 0.5f, N, 0.5f, 0.3f);
      EXPECT_NEAR(a.x, b.x, 1e-3f);
    }
}

// ---- MDF rotation (eqs. 17-19) -----------------------------------------------------------

TEST(ShadingRotation, ExactFrameIsOrthonormalAndMapsNormal) {
  std::mt19937 rng(7);
  std::uniform_real_distribution<float> u(-0.65f, 0.65f);
  for (int k = 0; k < 200; ++k) {
    const float x = u(rng), y = u(rng);
    const vec3 n(x, y, std::sqrt(1.0f - x * x - y * y));
    // Rows of R^T are the images of the basis vectors' duals: R^T e_i.
    const vec3 c0 = rotate_half_exact(vec3(1, 0, 0), n), c1 = rotate_half_exact(vec3(0, 1, 0), n),
               c2 = rotate_half_exact(vec3(0, 0, 1), n);
    const glm::mat3 Rt(c0, c1, c2);  // columns R^T e_i
    const glm::mat3 I = glm::transpose(Rt) * Rt;
    for (int i = 0; i < 3; ++i)
      for (int j = 0; j < 3; ++j) ASSERT_NEAR(I[i][j], i == j ? 1.0f : 0.0f, 2e-6f);
    EXPECT_NEAR(glm::determinant(Rt), 1.0f, 2e-6f);
    // R^T n~ = e_z, i.e. R maps the unperturbed normal (0,0,1) onto n~.
    const vec3 m = rotate_half_exact(n, n);
    EXPECT_NEAR(m.x, 0.0f, 2e-6f);
    EXPECT_NEAR(m.y, 0.0f, 2e-6f);
    EXPECT_NEAR(m.z, 1.0f, 2e-6f);
    const vec3 back = glm::transpose(Rt) * vec3(0, 0, 1);
    EXPECT_NEAR(glm::length(back - n), 0.0f, 2e-6f);
    // The paper's frame (eq. 17) maps n~ to e_z as well; its u', v' are scaled by sqrt(1 - n_y^2).
    const vec3 mp = rotate_half_paper(n, n);
    EXPECT_NEAR(glm::length(mp - vec3(0, 0, 1)), 0.0f, 2e-6f);
    const vec3 h = glm::normalize(vec3(u(rng), u(rng), 1.0f));
    const vec3 he = rotate_half_exact(h, n), hp = rotate_half_paper(h, n);
    const float s = std::sqrt(1.0f - y * y);
    EXPECT_NEAR(hp.x, he.x * s, 2e-6f);
    EXPECT_NEAR(hp.y, he.y * s, 2e-6f);
    EXPECT_NEAR(hp.z, he.z, 2e-6f);
    EXPECT_NEAR(glm::length(he), 1.0f, 2e-6f);
    // Eq. 19 written out equals the matrix of eq. 17 applied to h.
    const glm::mat3 Rp_t = glm::transpose(glm::mat3(vec3(n.z, 0, -n.x), vec3(-n.x * n.y, 1 - n.y * n.y, -n.y * n.z), n));
    EXPECT_NEAR(glm::length(Rp_t * h - hp), 0.0f, 2e-6f);
    // D depends on h~ only through h~_z and the azimuth, so the approximate frame gives the same D.
    EXPECT_NEAR(ward_mdf(hp, 0.2f, 0.5f), ward_mdf(he, 0.2f, 0.5f), 1e-4f * ward_mdf(he, 0.2f, 0.5f) + 1e-6f);
    EXPECT_NEAR(ashikhmin_mdf(hp, 40.0f, 6.0f), ashikhmin_mdf(he, 40.0f, 6.0f),
                1e-4f * ashikhmin_mdf(he, 40.0f, 6.0f) + 1e-6f);
  }
}

TEST(ShadingRotation, RotatedLobePeaksAtThePerturbedNormal) {
  const vec3 n = glm::normalize(vec3(0.3f, -0.2f, 1.0f));
  const float peak = ward_mdf(mdf_half_vector(n, n, LOOM_MODE_ROTATE_EXACT), 0.2f, 0.5f);
  EXPECT_NEAR(peak, 1.0 / (kPi * 0.1), 1e-3);
  for (float d : {0.05f, -0.05f}) {
    const vec3 h = glm::normalize(n + vec3(d, d, 0));
    EXPECT_LT(ward_mdf(mdf_half_vector(h, n, LOOM_MODE_ROTATE_EXACT), 0.2f, 0.5f), peak);
  }
  // With n~ = (0,0,1) every mode is the plain MDF.
  const vec3 h = glm::normalize(vec3(0.1f, 0.3f, 1.0f)), z(0, 0, 1);
  for (float mode : {LOOM_MODE_NORMAL_MAP, LOOM_MODE_ROTATE_EXACT, LOOM_MODE_ROTATE_PAPER})
    EXPECT_NEAR(ward_mdf(mdf_half_vector(h, z, mode), 0.2f, 0.5f), ward_mdf(h, 0.2f, 0.5f), 1e-5f);
}

TEST(ShadingRotation, NormalMappingDistortsTheAnisotropicLobe) {
  // Fig. 3: with normal mapping the lobe keeps the old tangent axes, so its shape around the
  // tilted normal differs from the rotated one (the difference the paper's Fig. 6 shows).
  const vec3 n = glm::normalize(vec3(0.5f, 0.0f, 1.0f));
  const vec3 b = vec3(0.0f, 1.0f, 0.0f);          // = exact v' for n_y = 0
  const vec3 h = glm::normalize(n + 0.15f * b);     // off-peak along the rotated y axis
  const float rot = ward_mdf(mdf_half_vector(h, n, LOOM_MODE_ROTATE_EXACT), 0.1f, 0.5f);
  const float nm = ward_mdf(mdf_half_vector(h, n, LOOM_MODE_NORMAL_MAP), 0.1f, 0.5f);
  EXPECT_GT(std::abs(rot - nm), 0.05f * rot);
}

// ---- the BRDF ----------------------------------------------------------------------------

TEST(ShadingBrdf, LightBelowTheSurfaceGivesAmbientOnly) {
  Fabric f = test_fabric();
  const vec3 c = shade_fabric(f, vec2(0.05f, 0.05f), glm::normalize(vec3(0.2f, 0.1f, -0.3f)),
                              glm::normalize(vec3(0.1f, 0.1f, 1.0f)), vec3(1.0f), vec3(0.1f));
  // (0.05, 0.05) * 10 = element (0, 0): weft for (2,1,1).
  EXPECT_NEAR(c.x, 0.1f * 0.6f, 1e-6f);
  EXPECT_NEAR(c.z, 0.1f * 0.2f, 1e-6f);
}

TEST(ShadingBrdf, FlatModeMatchesHandComputedWard) {
  Fabric f = test_fabric();
  f.mode = LOOM_MODE_FLAT;
  const vec3 l = glm::normalize(vec3(0.3f, 0.1f, 1.0f)), v = glm::normalize(vec3(-0.2f, 0.05f, 1.0f));
  const vec3 c = shade_fabric(f, vec2(0.25f, 0.05f), l, v, vec3(1.0f), vec3(0.0f));  // element (2,0): warp
  const vec3 h = glm::normalize(l + v);
  const double ax = 0.5, ay = 0.15;  // warp: fibres along y
  const double D = std::exp(-(h.x * h.x / (ax * ax) + h.y * h.y / (ay * ay)) / (h.z * h.z)) /
                   (kPi * ax * ay * std::pow(h.z, 4.0));
  const double F = 0.1 + 0.9 * std::pow(1.0 - glm::dot(v, h), 5.0);
  const double nl = l.z, nv = v.z;
  const double expect = 0.2 * nl + kPi * D * F * nl / (4.0 * std::max(nl, nv));
  EXPECT_NEAR(c.x, expect, 1e-5 * expect);
}

// The gnatv material plugin on whole meshes: masses, rest state, global force/energy/
// Jacobian consistency, parallel determinism, orientation, material files and errors.
#include <gtest/gtest.h>
#include <omp.h>

#include <algorithm>
#include <cmath>
#include <filesystem>
#include <fstream>
#include <iostream>
#include <random>

#include "common/tube_obj.hpp"
#include "gnatv_material.hpp"
#include "loom/bsr.hpp"
#include "loom/mesh.hpp"
#include "loom/params.hpp"

namespace fs = std::filesystem;
using loom::gnatv::GnatvMaterial;

namespace {

const std::string kWool = std::string(LOOM_SOURCE_DIR) + "/materials/wool.yaml";

std::unique_ptr<GnatvMaterial> make(const loom::Mesh& mesh, const std::string& extra = "") {
  auto p = loom::Params::from_string("material_file: " + kWool + "\n" + extra, "<test>");
  auto m = std::make_unique<GnatvMaterial>(p, mesh);
  p.check_unused();
  return m;
}

std::vector<double> perturbed(const loom::Mesh& mesh, double amp, unsigned seed) {
  std::mt19937 rng(seed);
  std::uniform_real_distribution<double> U(-1, 1);
  std::vector<double> x = mesh.positions;
  for (double& c : x) c += amp * U(rng);
  return x;
}

struct TempDir {
  fs::path dir;
  TempDir() {
    dir = fs::temp_directory_path() / ("loom_gnatv_" + std::to_string(::getpid()) + "_" +
                                       std::to_string(std::random_device{}()));
    fs::create_directories(dir);
  }
  ~TempDir() { std::error_code ec; fs::remove_all(dir, ec); }
  std::string write(const std::string& name, const std::string& text) const {
    std::ofstream(dir / name) << text;
    return (dir / name).string();
  }
};

// A valid file around the given weft curve; the weft gets `measure: green_pk2` unless it
// names a measure itself (or `nomeasure` is set).
std::string good_file(std::string weft_curve, bool nomeasure = false) {
  if (!nomeasure && weft_curve.find("measure") == std::string::npos && weft_curve.rfind('{', 0) == 0)
    weft_curve.insert(1, "measure: green_pk2, ");
  return "areal_density: 0.2\n"
         "curves:\n"
         "  weft: " + weft_curve + "\n"
         "  warp: {measure: green_pk2, start: 0.0, step: 0.01, stress: [0, 10, 30]}\n"
         "  shear: {measure: green_pk2, strain: [-0.1, 0.0, 0.1], stress: [-5, 0, 5]}\n";
}

}  // namespace

TEST(GnatvMaterial, LumpedMassesSumToDensityTimesArea) {
  const loom::Mesh mesh = loom::make_grid(9, 7, 2.0, 1.5, loom::GridPlane::XZ);
  auto m = make(mesh);
  std::vector<double> mass(mesh.num_vertices());
  m->compute_masses(mass);
  double total = 0;
  for (double v : mass) { EXPECT_GT(v, 0); total += v; }
  EXPECT_NEAR(total, 0.15 * 2.0 * 1.5, 1e-12);
  auto m2 = make(mesh, "density: 0.4\n");
  m2->compute_masses(mass);
  total = 0;
  for (double v : mass) total += v;
  EXPECT_NEAR(total, 0.4 * 3.0, 1e-12);
}

TEST(GnatvMaterial, RestStateIsForceFreeOnBothTriangulations) {
  for (bool alt : {true, false})
    for (auto plane : {loom::GridPlane::XY, loom::GridPlane::XZ}) {
      const loom::Mesh mesh = loom::make_grid(8, 6, 10.0, 7.0, plane, alt);
      auto m = make(mesh, "weft_angle: 0.3\n");
      std::vector<double> f(mesh.positions.size(), 1.0), v(mesh.positions.size(), 0.0);
      m->compute_forces(mesh.positions, v, f);
      for (double c : f) EXPECT_NEAR(c, 0.0, 1e-9);
      EXPECT_NEAR(m->elastic_energy(mesh.positions), 0.0, 1e-12);
      EXPECT_LT(m->max_strain(mesh.positions), 1e-12);
    }
}

TEST(GnatvMaterial, ColouringIsRaceFree) {
  for (int n : {5, 17, 64}) {
    const loom::Mesh mesh = loom::make_grid(n, n + 3, 1.0, 1.0);
    auto m = make(mesh);
    const auto& cs = m->colour_start();
    const auto& ks = m->chunk_start();
    EXPECT_EQ(ks.back(), mesh.num_triangles());
    EXPECT_EQ(cs.back() + 1, static_cast<loom::Index>(ks.size()));
    EXPECT_LE(m->num_colours(), 12);
    std::vector<int> seen_tri(mesh.num_triangles(), 0);
    for (int c = 0; c < m->num_colours(); ++c) {
      std::vector<loom::Index> owner(mesh.num_vertices(), -1);  // chunk that touched the vertex
      for (loom::Index q = cs[c]; q < cs[c + 1]; ++q)
        for (loom::Index t = ks[q]; t < ks[q + 1]; ++t)
          for (loom::Index v : m->triangles()[t]) {
            EXPECT_TRUE(owner[v] == -1 || owner[v] == q) << "colour " << c << " vertex " << v;
            owner[v] = q;
          }
    }
    // Every mesh triangle is stored exactly once.
    std::vector<std::array<loom::Index, 3>> a(m->triangles()), b;
    for (loom::Index t = 0; t < mesh.num_triangles(); ++t)
      b.push_back({mesh.triangles[3 * t], mesh.triangles[3 * t + 1], mesh.triangles[3 * t + 2]});
    std::sort(a.begin(), a.end());
    std::sort(b.begin(), b.end());
    EXPECT_EQ(a, b);
  }
}

TEST(GnatvMaterial, ForceIsMinusGradientOfTotalEnergy) {
  const loom::Mesh mesh = loom::make_grid(6, 5, 1.0, 0.8);
  auto m = make(mesh);
  const std::vector<double> x = perturbed(mesh, 0.02, 3);
  std::vector<double> f(x.size()), v(x.size(), 0.0);
  m->compute_forces(x, v, f);
  double scale = 0, worst = 0;
  for (double c : f) scale = std::max(scale, std::fabs(c));
  for (std::size_t i = 0; i < x.size(); ++i) {
    std::vector<double> xp = x, xm = x;
    const double h = 1e-7;
    xp[i] += h;
    xm[i] -= h;
    const double g = (m->elastic_energy(xp) - m->elastic_energy(xm)) / (2 * h);
    worst = std::max(worst, std::fabs(f[i] + g) / scale);
  }
  EXPECT_LT(worst, 1e-5);
}

TEST(GnatvMaterial, PatchTestAndMomentumBalance) {
  // Homogeneous deformation (stretch beyond the data, compression, shear, then a
  // rotation): every interior vertex is in equilibrium, on both triangulations. For any
  // deformation the internal forces have zero resultant and zero moment.
  for (bool alt : {true, false}) {
    const int nx = 7, ny = 6;
    const loom::Mesh mesh = loom::make_grid(nx, ny, 1.2, 1.0, loom::GridPlane::XY, alt);
    auto m = make(mesh, "weft_angle: 0.4\n");
    const double c = std::cos(0.6), s = std::sin(0.6);
    std::vector<double> x(mesh.positions.size());
    for (loom::Index i = 0; i < mesh.num_vertices(); ++i) {
      const double X = mesh.positions[3 * i], Y = mesh.positions[3 * i + 1];
      const double px = 1.15 * X + 0.3 * Y, py = 0.92 * Y, pz = 0.05 * X;  // F = [[1.15, .3], [0, .92], [.05, 0]]
      x[3 * i] = c * px - s * pz;
      x[3 * i + 1] = py;
      x[3 * i + 2] = s * px + c * pz;
    }
    std::vector<double> f(x.size()), v(x.size(), 0.0);
    m->compute_forces(x, v, f);
    double scale = 0;
    for (double q : f) scale = std::max(scale, std::fabs(q));
    ASSERT_GT(scale, 1.0);
    for (int iy = 1; iy + 1 < ny; ++iy)
      for (int ix = 1; ix + 1 < nx; ++ix)
        for (int k = 0; k < 3; ++k) EXPECT_NEAR(f[3 * (iy * nx + ix) + k], 0.0, 1e-12 * scale) << ix << "," << iy;
  }
  const loom::Mesh mesh = loom::make_grid(9, 8, 1.0, 1.0);
  auto m = make(mesh);
  const std::vector<double> x = perturbed(mesh, 0.05, 17);
  std::vector<double> f(x.size()), v(x.size(), 0.0);
  m->compute_forces(x, v, f);
  double R[3] = {0, 0, 0}, T[3] = {0, 0, 0}, scale = 0;
  for (loom::Index i = 0; i < mesh.num_vertices(); ++i) {
    const double* p = &x[3 * i];
    const double* q = &f[3 * i];
    for (int k = 0; k < 3; ++k) { R[k] += q[k]; scale = std::max(scale, std::fabs(q[k])); }
    T[0] += p[1] * q[2] - p[2] * q[1];
    T[1] += p[2] * q[0] - p[0] * q[2];
    T[2] += p[0] * q[1] - p[1] * q[0];
  }
  for (int k = 0; k < 3; ++k) {
    EXPECT_NEAR(R[k], 0.0, 1e-11 * scale);
    EXPECT_NEAR(T[k], 0.0, 1e-11 * scale);
  }
}

TEST(GnatvMaterial, AssembledJacobianIsSymmetricAndMatchesFiniteDifferences) {
  const loom::Mesh mesh = loom::make_grid(6, 5, 1.0, 0.8);
  auto m = make(mesh, "psd_projection: false\n");
  std::vector<std::array<loom::Index, 2>> pairs;
  m->jacobian_pairs(pairs);
  pairs.push_back({0, mesh.num_vertices() - 1});  // a block no triangle writes
  const loom::BsrPattern pat = loom::BsrPattern::from_pairs(mesh.num_vertices(), pairs);
  m->bind_pattern(pat);
  loom::BsrMatrix J(&pat), D(&pat);
  const std::vector<double> x = perturbed(mesh, 0.02, 5);
  std::vector<double> v(x.size(), 0.0);
  std::fill(D.values().begin(), D.values().end(), 7.0);
  std::fill(J.values().begin(), J.values().end(), std::nan(""));  // every value must be overwritten
  m->compute_jacobians(x, v, J, &D);
  for (double d : D.values()) EXPECT_EQ(d, 0.0);  // no material damping
  const double* extra = J.block(pat.find(0, mesh.num_vertices() - 1));
  for (int e = 0; e < 9; ++e) EXPECT_EQ(extra[e], 0.0);
  // Assembling twice gives the same matrix (assign-then-add scatter).
  const std::vector<double> first = J.values();
  m->compute_jacobians(x, v, J, nullptr);
  EXPECT_EQ(first, J.values());
  EXPECT_EQ(J.asymmetry(), 0.0);
  const std::vector<double> dense = J.to_dense();
  const std::size_t n3 = x.size();
  double scale = 0, worst = 0;
  for (double c : dense) scale = std::max(scale, std::fabs(c));
  std::vector<double> fp(n3), fm(n3);
  for (std::size_t i = 0; i < n3; ++i) {
    std::vector<double> xp = x, xm = x;
    const double h = 1e-9;
    xp[i] += h;
    xm[i] -= h;
    m->compute_forces(xp, v, fp);
    m->compute_forces(xm, v, fm);
    for (std::size_t r = 0; r < n3; ++r)
      worst = std::max(worst, std::fabs(dense[r * n3 + i] - (fp[r] - fm[r]) / (2 * h)) / scale);
  }
  std::cout << "[ measured ] assembled Jacobian vs central FD of the forces: " << worst << "\n";
  EXPECT_LT(worst, 1e-6);
  // With the projection on, the compressed cloth's -J is still symmetric.
  m->set_psd_projection(true);
  std::vector<double> xc = mesh.positions;
  for (std::size_t i = 0; i < xc.size(); i += 3) xc[i] *= 0.8;
  m->compute_jacobians(xc, v, J, nullptr);
  EXPECT_EQ(J.asymmetry(), 0.0);
}

TEST(GnatvMaterial, ParallelResultsEqualSerialBitForBit) {
  // Above the serial rule (kParallelMinVertices): smaller meshes run on one thread anyway.
  const loom::Mesh mesh = loom::make_grid(70, 70, 10.0, 10.0);
  ASSERT_GE(mesh.num_vertices(), loom::kParallelMinVertices);
  auto m = make(mesh);
  std::vector<std::array<loom::Index, 2>> pairs;
  m->jacobian_pairs(pairs);
  const loom::BsrPattern pat = loom::BsrPattern::from_pairs(mesh.num_vertices(), pairs);
  m->bind_pattern(pat);
  const std::vector<double> x = perturbed(mesh, 0.05, 9);
  std::vector<double> v(x.size(), 0.0), f1(x.size()), f2(x.size());
  loom::BsrMatrix J1(&pat), J2(&pat);
  const int saved = omp_get_max_threads();
  omp_set_num_threads(1);
  m->compute_forces(x, v, f1);
  m->compute_jacobians(x, v, J1, nullptr);
  const double e1 = m->elastic_energy(x);
  omp_set_num_threads(2);
  m->compute_forces(x, v, f2);
  m->compute_jacobians(x, v, J2, nullptr);
  const double e2 = m->elastic_energy(x);
  omp_set_num_threads(saved);
  EXPECT_EQ(f1, f2);
  EXPECT_EQ(J1.values(), J2.values());
  EXPECT_NEAR(e1, e2, 1e-12 * std::fabs(e1));
}

TEST(GnatvMaterial, WeftAngleSelectsTheCurve) {
  // A homogeneous stretch along x of a flat cloth: energy = area * W_weft(e) with the weft
  // along x, and area * W_warp(e) after turning the weft by 90 degrees.
  const loom::Mesh mesh = loom::make_grid(7, 5, 2.0, 1.0, loom::GridPlane::XY);
  std::vector<double> x = mesh.positions;
  const double lam = 1.01, e = 0.5 * (lam * lam - 1);
  for (std::size_t i = 0; i < x.size(); i += 3) x[i] *= lam;
  auto m0 = make(mesh);
  auto m90 = make(mesh, "weft_angle: 1.5707963267948966\n");
  auto mx = make(mesh, "orientation: x_axis\n");
  const double Ww = m0->data().weft.energy(e), Wv = m0->data().warp.energy(e);
  EXPECT_GT(std::fabs(Ww - Wv), 0.1 * Ww);
  EXPECT_NEAR(m0->elastic_energy(x), 2.0 * Ww, 1e-10 * Ww);
  EXPECT_NEAR(mx->elastic_energy(x), 2.0 * Ww, 1e-10 * Ww);
  EXPECT_NEAR(m90->elastic_energy(x), 2.0 * Wv, 1e-10 * Wv);
  // Shear: a 45-degree weft sees the x stretch partly as shear.
  auto m45 = make(mesh, "weft_angle: 0.7853981633974483\n");
  EXPECT_GT(std::fabs(m45->elastic_energy(x) - 2.0 * Ww), 1e-3 * Ww);
}

TEST(GnatvMaterial, UvOrientationFollowsTheTextureCoordinates) {
  // Rotate the grid's UVs by 90 degrees: the weft follows u, i.e. the mesh's y axis.
  loom::Mesh mesh = loom::make_grid(5, 5, 1.0, 1.0, loom::GridPlane::XY);
  ASSERT_EQ(mesh.uvs.size(), 2u * mesh.num_vertices());
  for (std::size_t i = 0; i < mesh.uvs.size(); i += 2) {
    const double u = mesh.uvs[i], v = mesh.uvs[i + 1];
    mesh.uvs[i] = v;
    mesh.uvs[i + 1] = -u;
  }
  std::vector<double> x = mesh.positions;
  const double lam = 1.01, e = 0.5 * (lam * lam - 1);
  for (std::size_t i = 0; i < x.size(); i += 3) x[i] *= lam;
  auto uv = make(mesh, "orientation: uv\n");
  EXPECT_NEAR(uv->elastic_energy(x), uv->data().warp.energy(e), 1e-10 * uv->data().warp.energy(e));
  mesh.uvs.clear();
  EXPECT_THROW(make(mesh, "orientation: uv\n"), loom::InputError);
}

TEST(GnatvMaterial, DegenerateRestTriangleIsAClearError) {
  loom::Mesh mesh;
  mesh.positions = {0, 0, 0, 1, 0, 0, 2, 0, 0, 0, 1, 0};
  mesh.triangles = {0, 1, 3, 0, 1, 2};
  mesh.source = "collinear.obj";
  try {
    make(mesh);
    FAIL() << "no error";
  } catch (const loom::InputError& e) {
    const std::string w = e.what();
    EXPECT_NE(w.find("triangle 1"), std::string::npos) << w;
    EXPECT_NE(w.find("zero rest area"), std::string::npos) << w;
  }
}

TEST(GnatvMaterial, MaterialFileResolvesAgainstTheSceneFolder) {
  const loom::Mesh mesh = loom::make_grid(3, 3, 1.0, 1.0);
  auto p = loom::Params::from_string("material_file: ../materials/wool.yaml\n",
                                     std::string(LOOM_SOURCE_DIR) + "/scenes/some_scene.yaml");
  GnatvMaterial m(p, mesh);
  EXPECT_EQ(m.data().name, "wool");
  EXPECT_DOUBLE_EQ(m.density(), 0.15);
}

TEST(GnatvMaterial, UsersOwnFileWithTheSameShapeWorks) {
  TempDir td;
  const std::string f = td.write("mine.yaml", good_file("{start: 0.0, step: 0.02, stress: [0, 5, 12, 30]}"));
  const loom::Mesh mesh = loom::make_grid(3, 3, 1.0, 1.0);
  auto p = loom::Params::from_string("material_file: mine.yaml\ninterpolation: bspline\n", f);
  GnatvMaterial m(p, mesh);
  EXPECT_DOUBLE_EQ(m.density(), 0.2);
  EXPECT_NEAR(m.data().weft.stress(0.04), 12.0, 1e-12);
  EXPECT_NEAR(m.data().shear.stress(0.1), 5.0, 1e-12);
}

// A nominal tensile curve (force per reference width P against engineering strain e) is
// converted exactly to the model's measure: S = P / (1 + e) at Green strain e + e^2/2; a
// nominal shear curve (force per clamp length against the trellis angle phi) to sigma_uv = P
// at eps_uv = sin(phi). Checked at the samples (tests/kawabata checks it through the model).
TEST(GnatvMaterial, NominalCurvesAreConvertedExactlyOnLoad) {
  TempDir td;
  const std::string text =
      "areal_density: 0.2\n"
      "curves:\n"
      "  weft: {measure: nominal, start: 0.0, step: 0.02, stress: [0, 5, 12, 30]}\n"
      "  warp: {measure: nominal, strain: [-0.01, 0.0, 0.05, 0.1], stress: [-1, 0, 20, 60]}\n"
      "  shear: {measure: nominal, strain: [-0.2, 0.0, 0.2], stress: [-5, 0, 5]}\n";
  const std::string f = td.write("nominal.yaml", text);
  const loom::Mesh mesh = loom::make_grid(3, 3, 1.0, 1.0);
  auto p = loom::Params::from_string("material_file: " + f + "\n", "<test>");
  GnatvMaterial m(p, mesh);
  EXPECT_EQ(m.data().weft_measure, "nominal");
  const double P[4] = {0, 5, 12, 30};
  for (int k = 0; k < 4; ++k) {
    const double e = 0.02 * k, lam = 1 + e;
    EXPECT_NEAR(m.data().weft.stress((lam * lam - 1) / 2), P[k] / lam, 1e-12) << k;
  }
  const double ew[4] = {-0.01, 0.0, 0.05, 0.1}, Pw[4] = {-1, 0, 20, 60};
  for (int k = 0; k < 4; ++k) {
    const double lam = 1 + ew[k];
    EXPECT_NEAR(m.data().warp.stress((lam * lam - 1) / 2), Pw[k] / lam, 1e-12) << k;
  }
  EXPECT_NEAR(m.data().shear.stress(std::sin(0.2)), 5.0, 1e-12);
  EXPECT_NEAR(m.data().shear.stress(std::sin(-0.2)), -5.0, 1e-12);
}

TEST(GnatvMaterial, BadMaterialFilesNameTheFileAndLine) {
  TempDir td;
  struct Bad {
    std::string name, text, expect;
  };
  const std::vector<Bad> bad = {
      {"grid.yaml",
       good_file("{strain: [0.0, 0.02, 0.01, 0.03], stress: [0, 5, 12, 30]}"), "increasing"},
      {"step.yaml", good_file("{start: 0.0, step: -0.02, stress: [0, 5, 12, 30]}"), "step"},
      {"nan.yaml", good_file("{start: 0.0, step: 0.02, stress: [0, 5, .nan, 30]}"), "finite"},
      {"short.yaml", good_file("{start: 0.0, step: 0.02, stress: [0]}"), "at least 2"},
      {"missing.yaml",
       "areal_density: 0.2\ncurves:\n  weft: {measure: green_pk2, start: 0.0, step: 0.01, stress: [0, 10]}\n"
       "  shear: {measure: green_pk2, start: -0.1, step: 0.1, stress: [-5, 0, 5]}\n",
       "missing curve 'warp'"},
      {"rest.yaml", good_file("{start: 0.0, step: 0.02, stress: [1, 5, 12, 30]}"), "stress free"},
      {"typo.yaml", good_file("{start: 0.0, stepp: 0.02, step: 0.02, stress: [0, 5, 12, 30]}"), "stepp"},
      {"density.yaml", "areal_density: -1\ncurves: {}\n", "areal_density"},
      // issue 13: what a curve measures, percent strains, softening curves
      {"nomeasure.yaml", good_file("{start: 0.0, step: 0.02, stress: [0, 5, 12, 30]}", true),
       "does not say what it measures"},
      {"badmeasure.yaml", good_file("{measure: engineering, start: 0.0, step: 0.02, stress: [0, 5, 12, 30]}"),
       "green_pk2"},
      {"percent.yaml", good_file("{measure: nominal, strain: [0, 2, 4, 6], stress: [0, 5, 12, 30]}"),
       "percent"},
      {"percent_step.yaml", good_file("{start: 0.0, step: 0.5, stress: [0, 5, 12, 30]}"), "divide the strains by 100"},
      {"dip.yaml", good_file("{start: 0.0, step: 0.02, stress: [0, 5, 4.5, 30]}"), "sample 2"},
      // issue 20: samples near the double range and infinite end slopes pass the sample
      // checks but give Inf energies or forces: refused at load
      {"huge.yaml", good_file("{start: 0.0, step: 0.02, stress: [0, 5, 12, 1.0e308]}"), "is not finite at strain"},
  };
  const loom::Mesh mesh = loom::make_grid(3, 3, 1.0, 1.0);
  {
    // an infinite B-spline end slope (used only with interpolation: bspline)
    const std::string f =
        td.write("infslope.yaml", good_file("{start: 0.0, step: 0.02, stress: [0, 5, 12, 30], bspline_right_slope: .inf}"));
    try {
      auto p = loom::Params::from_string("material_file: " + f + "\ninterpolation: bspline\n", "<test>");
      GnatvMaterial m(p, mesh);
      ADD_FAILURE() << "infinite end slope: no error";
    } catch (const loom::InputError& e) {
      EXPECT_NE(std::string(e.what()).find("is not finite at strain"), std::string::npos) << e.what();
    }
  }
  for (const Bad& b : bad) {
    const std::string f = td.write(b.name, b.text);
    try {
      auto p = loom::Params::from_string("material_file: " + f + "\n", "<test>");
      GnatvMaterial m(p, mesh);
      ADD_FAILURE() << b.name << ": no error";
    } catch (const loom::InputError& e) {
      const std::string w = e.what();
      EXPECT_NE(w.find(f + ":"), std::string::npos) << b.name << ": " << w;  // file:line
      EXPECT_NE(w.find(b.expect), std::string::npos) << b.name << ": " << w;
    }
  }
  // A missing file.
  try {
    auto p = loom::Params::from_string("material_file: /nonexistent/wool.yaml\n", "<test>");
    GnatvMaterial m(p, mesh);
    ADD_FAILURE() << "no error";
  } catch (const loom::InputError& e) {
    EXPECT_NE(std::string(e.what()).find("/nonexistent/wool.yaml"), std::string::npos);
  }
}

TEST(GnatvMaterial, UnknownSceneParameterIsReported) {
  const loom::Mesh mesh = loom::make_grid(3, 3, 1.0, 1.0);
  auto p = loom::Params::from_string("material_file: " + kWool + "\ninterpolaton: bspline\n", "<test>");
  GnatvMaterial m(p, mesh);
  try {
    p.check_unused();
    FAIL() << "no error";
  } catch (const loom::InputError& e) {
    EXPECT_NE(std::string(e.what()).find("interpolation"), std::string::npos) << e.what();
  }
}

namespace {

// Radial, tangential and axial force at every vertex of a tube (tests/common/tube_obj.hpp),
// and the largest deviation, ring by ring, from the ring's first vertex relative to the
// largest force component on the tube.
double ring_asymmetry(const tube_test::Tube& tube, const std::vector<double>& f) {
  double fmax = 0, worst = 0;
  for (double c : f) fmax = std::max(fmax, std::fabs(c));
  for (int r = 0; r < tube.M; ++r) {
    double ref[3] = {0, 0, 0};
    for (int c = 0; c < tube.N; ++c) {
      const double* F = &f[3 * static_cast<std::size_t>(tube.vertex(r, c))];
      const double ca = std::cos(tube.angle(c)), sa = std::sin(tube.angle(c));
      const double comp[3] = {ca * F[0] + sa * F[1], -sa * F[0] + ca * F[1], F[2]};
      for (int k = 0; k < 3; ++k) {
        if (c == 0) ref[k] = comp[k];
        worst = std::max(worst, std::fabs(comp[k] - ref[k]));
      }
    }
  }
  return worst / fmax;
}

}  // namespace

TEST(GnatvMaterial, TubeWithAUvSeamIsRotationallySymmetric) {
  // A tube whose weft runs around it as a helix (v = r/M + shear c/N), cut along one column
  // with the closing quads using u = 1 at the seam (tests/common/tube_obj.hpp). Rotating the tube
  // by 2 pi / N maps it onto itself, its texture coordinates onto themselves shifted (a
  // translation in uv, the same weft direction), so after a radial stretch by 1 % every vertex
  // of a ring feels the same radial, tangential and axial force. Rounding: positions from
  // cos/sin of different angles differ from exactly rotated ones by ~1e-16 R, which moves the
  // strains (~1e-2) by ~1e-16 R / edge ~ 1e-15 relative, so 1e-10 of the largest force is
  // loose. With one uv per vertex (first use, u = 0 at the seam) the closing triangles get
  // u from (N-1)/N to 0 without the v jump: a sheared parametrisation there, a weft turned
  // away from the helix (checked: the first-use rule gives 2.0 here, 1.5e-12 with corners).
  // The helix matters: with shear 0 the seam maps u to (1 - N) u + const on the closing
  // triangles, which only reverses the weft, and gnatv's strains do not see the sign (checked:
  // the first-use rule passes with shear 0).
  tube_test::Tube tube;
  tube.shear = 0.5;
  const loom::Mesh mesh = loom::read_obj(tube.write("gnatv"));
  ASSERT_EQ(mesh.corner_uvs.size(), 6u * mesh.num_triangles());
  auto m = make(mesh, "orientation: uv\n");
  std::vector<double> x = mesh.positions;
  for (std::size_t i = 0; i < x.size(); i += 3) {
    x[i] *= 1.01;
    x[i + 1] *= 1.01;
  }
  const std::vector<double> v(x.size(), 0.0);
  std::vector<double> f(x.size(), 0.0);
  m->compute_forces(x, v, f);
  double fmax = 0;
  for (double c : f) fmax = std::max(fmax, std::fabs(c));
  ASSERT_GT(fmax, 0.0);
  const double asym = ring_asymmetry(tube, f);
  std::cout << "[ info ] gnatv tube ring asymmetry " << asym << "\n";
  EXPECT_LT(asym, 1e-10);
}

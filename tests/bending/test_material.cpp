// The framework adapter (loom/bending.hpp) over real membrane materials: global force =
// -grad of the global energy, assembled Jacobians against differences of the force, rest
// angles from non-flat meshes, undamped RK4 energy conservation, bad input.
#include <gtest/gtest.h>

#include <Eigen/Dense>
#include <cmath>
#include <iostream>
#include <numbers>
#include <random>

#include "common.hpp"
#include "common/tube_obj.hpp"
#include "gnatv_material.hpp"
#include "loom/bsr.hpp"

namespace {

using bending_test::springs_with_bending;

std::vector<double> wrinkled(const loom::Mesh& mesh, double amp, unsigned seed) {
  std::mt19937 rng(seed);
  std::uniform_real_distribution<double> U(-1, 1);
  std::vector<double> x = mesh.positions;
  for (double& c : x) c += amp * U(rng);
  return x;
}

// A grid rolled onto a cylinder of radius R about the z axis (a non-flat rest shape).
loom::Mesh rolled_grid(int nx, int ny, double R) {
  loom::Mesh m = loom::make_grid(nx, ny, 1.0, 0.5, loom::GridPlane::XZ);
  for (loom::Index i = 0; i < m.num_vertices(); ++i) {
    const double s = m.positions[3 * i];
    m.positions[3 * i + 0] = R * std::sin(s / R);
    m.positions[3 * i + 1] = R * (1 - std::cos(s / R));
  }
  return m;
}

std::string expect_input_error(const std::function<void()>& f) {
  try {
    f();
  } catch (const loom::InputError& e) {
    return e.what();
  }
  ADD_FAILURE() << "no InputError";
  return "";
}

}  // namespace

TEST(BendingMaterial, ForceIsMinusGradientOfTotalEnergyAndJacobiansMatchDifferences) {
  const loom::Mesh mesh = loom::make_grid(6, 5, 0.5, 0.4, loom::GridPlane::XZ);
  auto m = springs_with_bending(mesh, "stiffness: {weft: 0.02, warp: 0.005, bias: 0.01}\njacobian: exact\n", 50.0);
  EXPECT_GT(m->hinges().num_hinges(), 0);
  const std::vector<double> x = wrinkled(mesh, 0.03, 1);
  const std::vector<double> v(x.size(), 0.0);
  const std::size_t N = x.size();
  std::vector<double> f(N);
  m->compute_forces(x, v, f);
  double fmax = 0;
  for (double c : f) fmax = std::max(fmax, std::fabs(c));
  double worst = 0;
  const double eta = 1e-6;
  for (std::size_t d = 0; d < N; ++d) {
    std::vector<double> xp = x, xm = x;
    xp[d] += eta;
    xm[d] -= eta;
    const double g = (m->elastic_energy(xp) - m->elastic_energy(xm)) / (2 * eta);
    worst = std::max(worst, std::fabs(f[d] + g) / fmax);
  }
  EXPECT_LT(worst, 1e-7);

  // Jacobians: exact bending + mass_spring without its compressed-spring clamp against
  // central differences of the force; the pattern holds the hinges' opposite-vertex pairs.
  auto p = loom::Params::from_string("stencil: mesh_edges\nstiffness: 50\nclamp_compressed: false\n", "<t>");
  auto membrane = std::make_unique<loom::mass_spring::MassSpringMaterial>(p, mesh);
  loom::BendingOptions o = m->hinges().options();
  loom::BentMaterial exact(std::move(membrane), mesh, o);
  std::vector<std::array<loom::Index, 2>> pairs;
  exact.jacobian_pairs(pairs);
  const auto pattern = loom::BsrPattern::from_pairs(mesh.num_vertices(), pairs);
  exact.bind_pattern(pattern);
  loom::BsrMatrix J(&pattern);
  exact.compute_jacobians(x, v, J, nullptr);
  const std::vector<double> Jd = J.to_dense();
  double jmax = 0;
  for (double c : Jd) jmax = std::max(jmax, std::fabs(c));
  double worst_j = 0;
  for (std::size_t d = 0; d < N; ++d) {
    std::vector<double> xp = x, xm = x, fp(N), fm(N);
    xp[d] += eta;
    xm[d] -= eta;
    exact.compute_forces(xp, v, fp);
    exact.compute_forces(xm, v, fm);
    for (std::size_t r = 0; r < N; ++r)
      worst_j = std::max(worst_j, std::fabs(Jd[r * N + d] - (fp[r] - fm[r]) / (2 * eta)) / jmax);
  }
  EXPECT_LT(worst_j, 1e-7);
  EXPECT_LT(J.asymmetry(), 1e-13);

  // Gauss-Newton: the bending part of -J is PSD (membrane springs at rest length add a PSD part).
  exact.hinges().set_exact_jacobian(false);
  exact.compute_jacobians(mesh.positions, v, J, nullptr);
  Eigen::MatrixXd K = -Eigen::Map<const Eigen::MatrixXd>(J.to_dense().data(), N, N);
  const Eigen::SelfAdjointEigenSolver<Eigen::MatrixXd> es(0.5 * (K + K.transpose()));
  EXPECT_GE(es.eigenvalues().minCoeff(), -1e-10 * es.eigenvalues().maxCoeff());
}

TEST(BendingMaterial, RestAnglesComeFromTheMeshSoANonFlatRestShapeIsForceFree) {
  const loom::Mesh mesh = rolled_grid(9, 5, 0.3);
  auto m = springs_with_bending(mesh, "stiffness: 0.01\n");
  std::vector<double> f(mesh.positions.size(), 1.0);
  std::fill(f.begin(), f.end(), 0.0);
  m->hinges().add_forces(mesh.positions, f);
  for (double c : f) EXPECT_EQ(c, 0.0);
  EXPECT_EQ(m->hinges().energy(mesh.positions), 0.0);
  // The rolled grid's vertical-edge hinges are bent by (column spacing)/R; flattening it costs energy.
  double max_theta0 = 0;
  for (const auto& r : m->hinges().rest()) max_theta0 = std::max(max_theta0, std::fabs(r.theta0));
  EXPECT_NEAR(max_theta0, (1.0 / 8) / 0.3, 1e-9);
  const loom::Mesh flat = loom::make_grid(9, 5, 1.0, 0.5, loom::GridPlane::XZ);
  EXPECT_GT(m->hinges().energy(flat.positions), 0.0);
}

TEST(BendingMaterial, ComposesWithGnatvAndKeepsItsMasses) {
  const loom::Mesh mesh = loom::make_grid(5, 5, 0.4, 0.4, loom::GridPlane::XZ);
  auto p = loom::Params::from_string("material_file: " + std::string(LOOM_SOURCE_DIR) + "/materials/wool.yaml\n", "<t>");
  auto g = std::make_unique<loom::gnatv::GnatvMaterial>(p, mesh);
  auto g2 = std::make_unique<loom::gnatv::GnatvMaterial>(p, mesh);
  loom::BendingOptions o;
  o.b_weft = o.b_warp = o.b_bias = 1e-3;
  loom::BentMaterial bent(std::move(g), mesh, o);
  std::vector<double> m1(mesh.num_vertices()), m2(mesh.num_vertices());
  bent.compute_masses(m1);
  g2->compute_masses(m2);
  EXPECT_EQ(m1, m2);
  const std::vector<double> x = wrinkled(mesh, 0.01, 2), v(x.size(), 0.0);
  std::vector<double> f1(x.size()), f2(x.size(), 0.0), f3(x.size(), 0.0);
  bent.compute_forces(x, v, f1);
  g2->compute_forces(x, v, f2);
  bent.hinges().add_forces(x, f3);
  for (std::size_t i = 0; i < x.size(); ++i) EXPECT_NEAR(f1[i], f2[i] + f3[i], 1e-12 * (1 + std::fabs(f1[i])));
  EXPECT_NEAR(bent.elastic_energy(x), g2->elastic_energy(x) + bent.hinges().energy(x), 1e-14);
  EXPECT_EQ(bent.springs(), nullptr);
  EXPECT_TRUE(bent.has_jacobian());
}

// Undamped bending oscillation of a free sheet with RK4: the energy error at a fixed time
// falls at 4th to 5th order as h halves (no gravity, no pins, only the bending and membrane forces).
TEST(BendingMaterial, UndampedOscillationConservesEnergyWithRK4AtFourthOrder) {
  const loom::Mesh mesh = loom::make_grid(5, 4, 0.2, 0.15, loom::GridPlane::XZ);
  auto m = springs_with_bending(mesh, "stiffness: 2.0e-3\n", 0.5, 0.1);
  const std::size_t N = mesh.positions.size();
  std::vector<double> mass(mesh.num_vertices());
  m->compute_masses(mass);
  std::vector<double> x0 = mesh.positions;
  for (loom::Index i = 0; i < mesh.num_vertices(); ++i) {  // a bent initial shape, at rest
    const double s = x0[3 * i] - 0.1, t = x0[3 * i + 2] - 0.075;
    x0[3 * i + 1] = 0.3 * s * s + 0.15 * s * t;
  }
  auto total = [&](const std::vector<double>& x, const std::vector<double>& v) {
    double ke = 0;
    for (std::size_t i = 0; i < N; ++i) ke += 0.5 * mass[i / 3] * v[i] * v[i];
    return ke + m->elastic_energy(x);
  };
  const std::vector<double> zero(N, 0.0);
  const double E0 = total(x0, zero);
  ASSERT_GT(m->hinges().energy(x0), 0.5 * E0);  // mostly bending energy
  auto run = [&](int steps, double T) {
    const double h = T / steps;
    std::vector<double> x = x0, v(N, 0.0), k1x(N), k1v(N), k2x(N), k2v(N), k3x(N), k3v(N), k4x(N), k4v(N), xt(N),
        vt(N), f(N);
    auto deriv = [&](const std::vector<double>& xs, const std::vector<double>& vs, std::vector<double>& dx,
                     std::vector<double>& dv) {
      m->compute_forces(xs, vs, f);
      for (std::size_t i = 0; i < N; ++i) {
        dx[i] = vs[i];
        dv[i] = f[i] / mass[i / 3];
      }
    };
    for (int s = 0; s < steps; ++s) {
      deriv(x, v, k1x, k1v);
      for (std::size_t i = 0; i < N; ++i) { xt[i] = x[i] + 0.5 * h * k1x[i]; vt[i] = v[i] + 0.5 * h * k1v[i]; }
      deriv(xt, vt, k2x, k2v);
      for (std::size_t i = 0; i < N; ++i) { xt[i] = x[i] + 0.5 * h * k2x[i]; vt[i] = v[i] + 0.5 * h * k2v[i]; }
      deriv(xt, vt, k3x, k3v);
      for (std::size_t i = 0; i < N; ++i) { xt[i] = x[i] + h * k3x[i]; vt[i] = v[i] + h * k3v[i]; }
      deriv(xt, vt, k4x, k4v);
      for (std::size_t i = 0; i < N; ++i) {
        x[i] += h / 6 * (k1x[i] + 2 * k2x[i] + 2 * k3x[i] + k4x[i]);
        v[i] += h / 6 * (k1v[i] + 2 * k2v[i] + 2 * k3v[i] + k4v[i]);
      }
    }
    double ke = 0;
    for (std::size_t i = 0; i < N; ++i) ke += 0.5 * mass[i / 3] * v[i] * v[i];
    EXPECT_GT(ke, 0.05 * E0);  // it really oscillates
    return std::fabs(total(x, v) - E0) / E0;
  };
  const double T = 0.5;
  const double e1 = run(500, T), e2 = run(1000, T), e3 = run(2000, T);
  std::printf("RK4 relative energy error at t = %.2f s: h = T/500 %.3e, T/1000 %.3e, T/2000 %.3e (orders %.2f, %.2f)\n",
              T, e1, e2, e3, std::log2(e1 / e2), std::log2(e2 / e3));
  // RK4 is 4th order in the state; for an oscillation its energy error over a fixed time is
  // O(h^5) (amplification 1 - (w h)^6 / 144 per step), so the observed order is 4 to 5.
  EXPECT_LT(e3, 1e-4);
  EXPECT_GT(std::log2(e1 / e2), 3.8);
  EXPECT_GT(std::log2(e2 / e3), 3.8);
  EXPECT_LT(std::log2(e2 / e3), 5.5);
}

TEST(BendingMaterial, BadInputIsRefusedWithFileLineAndFix) {
  const loom::Mesh mesh = loom::make_grid(3, 3, 1.0, 1.0, loom::GridPlane::XZ);
  auto read = [](const std::string& y) { return loom::read_bending_options(loom::Params::from_string(y, "scene.yaml")); };
  std::string e = expect_input_error([&] { read("stiffness: -1.0e-5\n"); });
  EXPECT_NE(e.find("scene.yaml:1"), std::string::npos) << e;
  EXPECT_NE(e.find(">= 0"), std::string::npos) << e;
  e = expect_input_error([&] { read("stiffness: .nan\n"); });
  EXPECT_NE(e.find("finite"), std::string::npos) << e;
  e = expect_input_error([&] { read("stiffness: {weft: 1.0e-5, warp: .inf}\n"); });
  EXPECT_NE(e.find("finite"), std::string::npos) << e;
  e = expect_input_error([&] { read("stifness: 1.0e-5\n"); });
  EXPECT_NE(e.find("stiffness"), std::string::npos) << e;
  e = expect_input_error([&] { read("stiffness: 1.0e-5\njacobain: exact\n"); });
  EXPECT_NE(e.find("jacobian"), std::string::npos) << e;  // did you mean
  e = expect_input_error([&] { read("stiffness: {weft: 1.0e-5}\n"); });
  EXPECT_NE(e.find("warp"), std::string::npos) << e;

  // Non-manifold: three triangles on edge (0, 1) are refused, naming the edge; with
  // non_manifold: skip the edge gets no hinge and a warning names it.
  loom::Mesh fan;
  fan.positions = {0, 0, 0, 1, 0, 0, 0.5, 1, 0, 0.5, -1, 0, 0.5, 0, 1};
  fan.triangles = {0, 1, 2, 1, 0, 3, 0, 1, 4};
  fan.source = "fan.obj";
  auto p = loom::Params::from_string("stencil: mesh_edges\n", "<t>");
  e = expect_input_error([&] {
    loom::BentMaterial(std::make_unique<loom::mass_spring::MassSpringMaterial>(p, fan), fan, read("stiffness: 1.0\n"));
  });
  EXPECT_NE(e.find("edge (0, 1) shared by 3 triangles"), std::string::npos) << e;
  EXPECT_NE(e.find("non_manifold: skip"), std::string::npos) << e;
  loom::BentMaterial skipped(std::make_unique<loom::mass_spring::MassSpringMaterial>(p, fan), fan,
                             read("stiffness: 1.0\nnon_manifold: skip\n"));
  EXPECT_EQ(skipped.hinges().num_hinges(), 0);
  ASSERT_EQ(skipped.hinges().warnings().size(), 1u);
  EXPECT_NE(skipped.hinges().warnings()[0].find("edge (0, 1)"), std::string::npos);

  // Anisotropic stiffness needs texture coordinates.
  loom::Mesh nouv = mesh;
  nouv.uvs.clear();
  e = expect_input_error([&] {
    loom::BentMaterial(std::make_unique<loom::mass_spring::MassSpringMaterial>(p, nouv), nouv,
                       read("stiffness: {weft: 1.0, warp: 2.0}\n"));
  });
  EXPECT_NE(e.find("texture coordinates"), std::string::npos) << e;

  // A backend without a hinge kernel is refused before it sees the material; cuda runs the
  // hinges through describe_device() (tests/cuda/test_cuda_materials.cpp).
  e = expect_input_error([&] {
    loom::add_bending(std::make_unique<loom::mass_spring::MassSpringMaterial>(p, mesh),
                      loom::Params::from_string("stiffness: 1.0\n", "scene.yaml"), mesh, "opencl");
  });
  EXPECT_NE(e.find("backend: cpu or cuda"), std::string::npos) << e;
  EXPECT_NO_THROW(loom::add_bending(std::make_unique<loom::mass_spring::MassSpringMaterial>(p, mesh),
                                    loom::Params::from_string("stiffness: 1.0\n", "scene.yaml"), mesh, "cuda"));
  // No bending block: the material is returned as it is.
  auto plain = std::make_unique<loom::mass_spring::MassSpringMaterial>(p, mesh);
  const loom::Material* raw = plain.get();
  EXPECT_EQ(loom::add_bending(std::move(plain), loom::Params(), mesh, "cpu").get(), raw);
}

TEST(BendingMaterial, TubeWithAUvSeamIsRotationallySymmetric) {
  // A tube cut along one column, the closing quads using u = 1 at the seam (tests/common/
  // tube_obj.hpp), with weft/warp/bias rigidities. Rotating by 2 pi / N maps the tube, its
  // hinges and the texture directions of their edges onto themselves (a translation in uv), so
  // after a radial stretch by 1 % and a twist (ring r turned by 0.05 r rad, which bends the
  // quads across their diagonals) every vertex of a ring feels the same radial, tangential
  // and axial force. Rounding of the positions (~1e-16 R) moves each hinge angle by ~1e-15
  // against angle changes of ~1e-2: 1e-10 of the largest force is loose. With one uv per
  // vertex (first use: u = 0 at the seam) the seam's diagonals point at
  // atan2(1/M, -(N-1)/N) instead of atan2(1/M, 1/N) in texture space: another rigidity there
  // (checked: the first-use rule breaks the symmetry by 1.15, 3.5e-14 with corners).
  tube_test::Tube tube;
  const loom::Mesh mesh = loom::read_obj(tube.write("bending"));
  ASSERT_EQ(mesh.corner_uvs.size(), 6u * mesh.num_triangles());
  const loom::HingeSet hinges(
      mesh, loom::read_bending_options(loom::Params::from_string("stiffness: {weft: 1.0e-3, warp: 4.0e-3, bias: 1.5e-3}\n", "<t>")));
  EXPECT_EQ(hinges.num_hinges(), 3 * tube.N * (tube.M - 1) - tube.N);  // vertical + diagonal + inner rings
  std::vector<double> x = mesh.positions;
  for (int r = 0; r < tube.M; ++r)
    for (int c = 0; c < tube.N; ++c) {
      double* X = &x[3 * static_cast<std::size_t>(tube.vertex(r, c))];
      const double a = tube.angle(c) + 0.05 * r;
      X[0] = 1.01 * tube.R * std::cos(a);
      X[1] = 1.01 * tube.R * std::sin(a);
    }
  std::vector<double> f(x.size(), 0.0);
  hinges.add_forces(x, f);
  double fmax = 0, worst = 0;
  for (double c : f) fmax = std::max(fmax, std::fabs(c));
  ASSERT_GT(fmax, 0.0);
  for (int r = 0; r < tube.M; ++r) {
    double ref[3] = {0, 0, 0};
    for (int c = 0; c < tube.N; ++c) {
      const double* F = &f[3 * static_cast<std::size_t>(tube.vertex(r, c))];
      const double a = tube.angle(c) + 0.05 * r;
      const double ca = std::cos(a), sa = std::sin(a);
      const double comp[3] = {ca * F[0] + sa * F[1], -sa * F[0] + ca * F[1], F[2]};
      for (int k = 0; k < 3; ++k) {
        if (c == 0) ref[k] = comp[k];
        worst = std::max(worst, std::fabs(comp[k] - ref[k]));
      }
    }
  }
  std::cout << "[ info ] bending tube ring asymmetry " << worst / fmax << "\n";
  EXPECT_LT(worst / fmax, 1e-10);
}

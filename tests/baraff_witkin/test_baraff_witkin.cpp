// baraff_witkin integrator: exact recurrences (free fall, Rayleigh, Kang-Cho, damped
// spring), pins bit for bit, plane constraints through the filter, stiff springs, the
// order of the consistent Kang-Cho damping on a 1D chain, the failure policy, errors.
#include <gtest/gtest.h>
#include <omp.h>

#include <Eigen/Dense>
#include <unsupported/Eigen/MatrixFunctions>
#include <chrono>
#include <cmath>
#include <cstring>
#include <memory>
#include <random>
#include <vector>

#include "baraff_witkin.hpp"
#include "eigen_ldlt.hpp"
#include "eigen_pcg.hpp"
#include "loom/params.hpp"
#include "loom/scene.hpp"
#include "loom/state.hpp"
#include "test_materials.hpp"

namespace {

using loom::BaraffWitkin;
using loom::BaraffWitkinOptions;
using loom::Index;
using loom::Scene;
using loom::testing::NullMaterial;
using loom::testing::SpringMaterial;

enum class SolverKind { Pcg, Ldlt };
const SolverKind kBoth[] = {SolverKind::Pcg, SolverKind::Ldlt};
const char* label(SolverKind k) { return k == SolverKind::Pcg ? "eigen_pcg" : "eigen_ldlt"; }

std::unique_ptr<loom::LinearSolver> make_solver(SolverKind k, double tol = 1e-13) {
  if (k == SolverKind::Ldlt) return std::make_unique<loom::EigenLdlt>();
  loom::PcgOptions o;
  o.tolerance = tol;
  o.max_iterations = 10000;
  return std::make_unique<loom::EigenPcg>(o);
}

// Vertices of an nx x ny grid with spacing dx in the xy plane (y up; row ny-1 on top).
std::vector<double> grid_xy(Index nx, Index ny, double dx) {
  std::vector<double> x;
  for (Index iy = 0; iy < ny; ++iy)
    for (Index ix = 0; ix < nx; ++ix) {
      x.push_back(ix * dx);
      x.push_back(iy * dx);
      x.push_back(0.0);
    }
  return x;
}
// Same grid lying flat in the xz plane.
std::vector<double> grid_xz(Index nx, Index ny, double dx) {
  std::vector<double> x;
  for (Index iy = 0; iy < ny; ++iy)
    for (Index ix = 0; ix < nx; ++ix) {
      x.push_back(ix * dx);
      x.push_back(0.0);
      x.push_back(iy * dx);
    }
  return x;
}
std::vector<std::array<Index, 2>> grid_pairs(Index nx, Index ny) {
  std::vector<std::array<Index, 2>> p;
  for (const auto& s : loom::testing::grid_springs(nx, ny, 1.0, 1.0)) p.push_back({s.i, s.j});
  return p;
}

double rel_err(const std::vector<double>& a, const std::vector<double>& b) {
  double num = 0, den = 0;
  for (std::size_t k = 0; k < a.size(); ++k) {
    num += (a[k] - b[k]) * (a[k] - b[k]);
    den += b[k] * b[k];
  }
  return std::sqrt(num / std::max(den, 1e-300));
}

}  // namespace

// No elastic forces: implicit Euler is v_{n+1} = v_n + h g, x_{n+1} = x_n + h v_{n+1}
// (also with Kang-Cho damping when the motion is uniform: L v = 0).
TEST(BaraffWitkin, FreeFallMatchesImplicitEulerRecurrence) {
  for (SolverKind sk : kBoth)
    for (double cd : {0.0, 2.0}) {
      Scene sc;
      const Index nx = 4, ny = 3;
      std::vector<double> mass(nx * ny);
      for (Index i = 0; i < nx * ny; ++i) mass[i] = 0.01 * (1 + i % 5);
      loom::testing::init_scene(sc, grid_xy(nx, ny, 0.1),
                                std::make_unique<NullMaterial>(mass, grid_pairs(nx, ny)));
      sc.gravity = {0.3, -9.81, 0.1};
      sc.solver = make_solver(sk);
      // non-uniform initial velocities only without damping (damping couples them)
      for (Index i = 0; i < nx * ny; ++i)
        for (int c = 0; c < 3; ++c) sc.state.v[3 * i + c] = cd == 0 ? 0.1 * ((i + c) % 3) : 0.25 * (c + 1);
      BaraffWitkinOptions o;
      o.kang_cho_damping = cd;
      BaraffWitkin bw(o);
      const double h = 0.01;
      bw.prepare(sc, h);
      std::vector<double> x = sc.state.x, v = sc.state.v;
      for (int n = 0; n < 50; ++n) {
        bw.step(sc, h);
        for (std::size_t k = 0; k < x.size(); ++k) {
          v[k] = v[k] + h * sc.gravity[k % 3];
          x[k] = x[k] + h * v[k];
        }
      }
      EXPECT_LT(rel_err(sc.state.v, v), 1e-11) << label(sk) << " c_d " << cd;
      EXPECT_LT(rel_err(sc.state.x, x), 1e-12) << label(sk) << " c_d " << cd;
      EXPECT_EQ(sc.state.step, 50);
      EXPECT_NEAR(sc.state.time, 0.5, 1e-12);
      EXPECT_EQ(bw.last_step().force_evaluations, 1);
    }
}

// A mass on a spring to a pinned anchor, moving along the spring (a linear 1D problem):
// m dv = h(-k x1 - beta k v1 - alpha m v1 - c_d v1) with x1 = x0 + h v1, solved exactly.
TEST(BaraffWitkin, DampedSpringMatchesScalarImplicitEuler) {
  const double m = 0.05, k = 300, l0 = 0.1, alpha = 0.7, beta = 0.01, cd = 0.4, h = 0.005;
  for (SolverKind sk : kBoth) {
    Scene sc;
    std::vector<double> x0 = {0, 0, 0, l0 + 0.02, 0, 0};
    loom::testing::init_scene(
        sc, x0,
        std::make_unique<SpringMaterial>(std::vector<double>{m, m},
                                         std::vector<SpringMaterial::Spring>{{0, 1, l0, k}}, true));
    sc.state.pin(0);
    sc.state.update_inverse_masses();
    sc.state.v[3] = -0.3;
    sc.gravity = {0, 0, 0};
    sc.solver = make_solver(sk);
    BaraffWitkinOptions o;
    o.rayleigh_alpha = alpha;
    o.rayleigh_beta = beta;
    o.kang_cho_damping = cd;
    BaraffWitkin bw(o);
    bw.prepare(sc, h);
    double u = 0.02, w = -0.3;  // displacement and velocity of the free mass
    for (int n = 0; n < 200; ++n) {
      bw.step(sc, h);
      const double dv = h * (-k * u - (h + beta) * k * w - alpha * m * w - cd * w) /
                        (m * (1 + h * alpha) + (h * h + h * beta) * k + h * cd);
      w += dv;
      u += h * w;
    }
    EXPECT_NEAR(sc.state.x[3] - l0, u, 1e-12 * 0.02) << label(sk);
    EXPECT_NEAR(sc.state.v[3], w, 1e-10 * 0.3) << label(sk);
    EXPECT_EQ(sc.state.x[4], 0.0);
    EXPECT_EQ(sc.state.x[5], 0.0);
  }
}

// Kang-Cho damping between two particles of different masses (no spring): the full
// Laplacian (with its off-diagonal blocks) gives [[m0 + hc, -hc], [-hc, m1 + hc]] v1 = M v0,
// and the momentum is conserved.
TEST(BaraffWitkin, KangChoDampingCouplesNeighboursAndConservesMomentum) {
  const double m0 = 0.02, m1 = 0.05, c = 0.8, h = 0.01;
  for (SolverKind sk : kBoth) {
    Scene sc;
    loom::testing::init_scene(sc, std::vector<double>{0, 0, 0, 0.1, 0, 0},
                              std::make_unique<NullMaterial>(std::vector<double>{m0, m1},
                                                             std::vector<std::array<Index, 2>>{{0, 1}}));
    sc.gravity = {0, 0, 0};
    sc.state.v = {1.0, 0.0, -0.2, -1.0, 0.5, 0.3};
    sc.solver = make_solver(sk);
    BaraffWitkinOptions o;
    o.kang_cho_damping = c;
    BaraffWitkin bw(o);
    bw.prepare(sc, h);
    std::vector<double> v = sc.state.v;
    double p0[3];
    for (int a = 0; a < 3; ++a) p0[a] = m0 * v[a] + m1 * v[3 + a];
    for (int n = 0; n < 30; ++n) {
      bw.step(sc, h);
      for (int a = 0; a < 3; ++a) {
        const double A00 = m0 + h * c, A01 = -h * c, A11 = m1 + h * c;
        const double r0 = m0 * v[a], r1 = m1 * v[3 + a];
        const double det = A00 * A11 - A01 * A01;
        v[a] = (A11 * r0 - A01 * r1) / det;
        v[3 + a] = (A00 * r1 - A01 * r0) / det;
      }
    }
    EXPECT_LT(rel_err(sc.state.v, v), 1e-11) << label(sk);
    for (int a = 0; a < 3; ++a)
      EXPECT_NEAR(m0 * sc.state.v[a] + m1 * sc.state.v[3 + a], p0[a], 1e-14) << label(sk);
    // the relative velocity really decayed
    EXPECT_LT(std::abs(sc.state.v[0] - sc.state.v[3]), 0.2 * 2.0);
  }
}

// Fixed pins never move, bit for bit, while the rest of the cloth swings.
TEST(BaraffWitkin, PinnedVerticesAreFixedBitForBit) {
  for (SolverKind sk : kBoth) {
    Scene sc;
    const Index nx = 8, ny = 8;
    const double dx = 0.05;
    std::vector<double> x0 = grid_xz(nx, ny, dx);
    // a small non-planar start so that nothing is symmetric
    for (Index i = 0; i < nx * ny; ++i) x0[3 * i + 1] = 1e-3 * std::sin(1.7 * i);
    loom::testing::init_scene(sc, x0,
                              std::make_unique<SpringMaterial>(std::vector<double>(nx * ny, 0.002),
                                                               loom::testing::grid_springs(nx, ny, dx, 500), true));
    const Index pins[2] = {(ny - 1) * nx, ny * nx - 1};
    for (Index p : pins) sc.state.pin(p);
    sc.state.update_inverse_masses();
    sc.solver = make_solver(sk, 1e-6);
    BaraffWitkinOptions o;
    o.kang_cho_damping = 0.01;
    BaraffWitkin bw(o);
    bw.prepare(sc, 0.01);
    std::vector<double> before = sc.state.x;
    for (int n = 0; n < 60; ++n) bw.step(sc, 0.01);
    for (Index p : pins) {
      EXPECT_EQ(std::memcmp(&sc.state.x[3 * p], &before[3 * p], 3 * sizeof(double)), 0) << label(sk);
      for (int c = 0; c < 3; ++c) EXPECT_EQ(sc.state.v[3 * p + c], 0.0);
    }
    // the free corner fell
    EXPECT_LT(sc.state.x[1], -0.05) << label(sk);
  }
}

// A plane constraint through the filter (the path collisions use): particles slide on a
// tilted plane; the normal velocity stays 0 and the tangential acceleration is g_t.
TEST(BaraffWitkin, PlaneConstraintThroughTheFilter) {
  for (SolverKind sk : kBoth) {
    Scene sc;
    loom::testing::init_scene(sc, grid_xy(3, 2, 0.1),
                              std::make_unique<NullMaterial>(std::vector<double>(6, 0.01), grid_pairs(3, 2)));
    sc.gravity = {0, -9.81, 0};
    sc.solver = make_solver(sk);
    const double nrm[3] = {0.6, 0.8, 0.0};
    BaraffWitkin bw;
    bw.set_constraint_hook([&](const loom::State& s, double, loom::Filter& S, std::span<double> z) {
      for (Index i = 0; i < s.size(); ++i) {
        S.constrain_direction(i, nrm);
        const double vn = s.v[3 * i] * nrm[0] + s.v[3 * i + 1] * nrm[1] + s.v[3 * i + 2] * nrm[2];
        for (int c = 0; c < 3; ++c) z[3 * i + c] = -vn * nrm[c];  // target normal velocity 0
      }
    });
    const double h = 0.01;
    bw.prepare(sc, h);
    const double gn = sc.gravity[1] * nrm[1];
    const double gt[3] = {-gn * nrm[0], sc.gravity[1] - gn * nrm[1], 0.0};
    for (int n = 0; n < 40; ++n) bw.step(sc, h);
    for (Index i = 0; i < 6; ++i) {
      const double* v = &sc.state.v[3 * i];
      EXPECT_NEAR(v[0] * nrm[0] + v[1] * nrm[1], 0.0, 1e-13);
      for (int c = 0; c < 3; ++c) EXPECT_NEAR(v[c], 40 * h * gt[c], 1e-12) << label(sk);
    }
    EXPECT_EQ(bw.filter().free_dofs(0), 2);
  }
}

// Stiff springs (k = 1e6, NUMERICS.md 1.5 grid: 10x10, spacing 0.1 m, 0.01 kg) at h = 0.01,
// where every explicit method blows up (h* ~ 7e-5): bounded, and the energy does not grow.
TEST(BaraffWitkin, StiffSpringsStayBoundedAtLargeSteps) {
  Scene sc;
  const Index nx = 10, ny = 10;
  const double dx = 0.1;
  loom::testing::init_scene(sc, grid_xz(nx, ny, dx),
                            std::make_unique<SpringMaterial>(std::vector<double>(nx * ny, 0.01),
                                                             loom::testing::grid_springs(nx, ny, dx, 1e6), true));
  sc.state.pin((ny - 1) * nx);
  sc.state.pin(ny * nx - 1);
  sc.state.update_inverse_masses();
  sc.solver = make_solver(SolverKind::Ldlt);
  BaraffWitkin bw;
  const double h = 0.01;
  bw.prepare(sc, h);
  const double g[3] = {sc.gravity[0], sc.gravity[1], sc.gravity[2]};
  auto energy = [&] {  // serial on purpose: tiny, and OpenMP start-up dominates on a loaded machine
    double e = sc.material->elastic_energy(sc.state.x);
    for (Index i = 0; i < sc.state.size(); ++i)
      for (int c = 0; c < 3; ++c)
        e += sc.state.mass[i] * (0.5 * sc.state.v[3 * i + c] * sc.state.v[3 * i + c] - g[c] * sc.state.x[3 * i + c]);
    return e;
  };
  const double e0 = energy();
  double emax = e0, strain = 0;
  for (int n = 0; n < 100; ++n) {
    bw.step(sc, h);
    emax = std::max(emax, energy());
    strain = std::max(strain, sc.material->max_strain(sc.state.x));
    for (double xv : sc.state.x) ASSERT_TRUE(std::isfinite(xv));
  }
  EXPECT_LE(emax, e0 + 1e-9);  // implicit Euler only dissipates here
  EXPECT_LT(strain, 0.01);     // k = 1e6 barely stretches under gravity
  EXPECT_LT(sc.state.x[1], -0.3);  // and the cloth really swung down
}

// Consistent Kang-Cho damping (NUMERICS.md 3.2) converges at order 1 to the damped exact
// solution of a 1D chain (6 masses, m = 0.05, k = 200, c_d = 0.5, one end anchored),
// computed here with the matrix exponential; the undamped solution is far away.
TEST(BaraffWitkin, KangChoDampingConvergesAtOrderOneOnAChain) {
  const int nf = 6;
  const double m = 0.05, k = 200, cd = 0.5, l0 = 0.1;
  std::vector<double> u0(nf);
  for (int i = 0; i < nf; ++i) u0[i] = 0.02 * (i + 1) / nf;  // a uniform 20% stretch
  // exact: y = [u; w], y' = [[0, I], [-K/m, -cd L/m]] y, chain K = k L (anchor at vertex 0)
  auto exact = [&](double c, double t) {
    Eigen::MatrixXd L = Eigen::MatrixXd::Zero(nf, nf);
    for (int i = 0; i < nf; ++i) {
      L(i, i) = (i + 1 < nf) ? 2 : 1;  // anchor counted for vertex 1; the last has one neighbour
      if (i > 0) L(i, i - 1) = -1;
      if (i + 1 < nf) L(i, i + 1) = -1;
    }
    Eigen::MatrixXd G = Eigen::MatrixXd::Zero(2 * nf, 2 * nf);
    G.topRightCorner(nf, nf) = Eigen::MatrixXd::Identity(nf, nf);
    G.bottomLeftCorner(nf, nf) = -(k / m) * L;
    G.bottomRightCorner(nf, nf) = -(c / m) * L;
    Eigen::VectorXd y0 = Eigen::VectorXd::Zero(2 * nf);
    for (int i = 0; i < nf; ++i) y0[i] = u0[i];
    const Eigen::MatrixXd E = (G * t).exp();
    return Eigen::VectorXd(E * y0);
  };
  std::vector<double> errs, errs_undamped;
  const double hs[] = {2e-3, 1e-3, 5e-4, 2.5e-4};
  for (double h : hs) {
    Scene sc;
    std::vector<double> x0(3 * (nf + 1), 0.0);
    std::vector<SpringMaterial::Spring> springs;
    for (int i = 0; i <= nf; ++i) x0[3 * i] = i * l0 + (i > 0 ? u0[i - 1] : 0.0);
    for (int i = 0; i < nf; ++i) springs.push_back({i, i + 1, l0, k});
    loom::testing::init_scene(
        sc, x0, std::make_unique<SpringMaterial>(std::vector<double>(nf + 1, m), springs, true));
    sc.state.pin(0);
    sc.state.update_inverse_masses();
    sc.gravity = {0, 0, 0};
    sc.solver = make_solver(SolverKind::Ldlt);
    BaraffWitkinOptions o;
    o.kang_cho_damping = cd;
    BaraffWitkin bw(o);
    bw.prepare(sc, h);
    // max over the samples t = 0.1, 0.2, ..., 1 s and over the masses
    const int per_sample = static_cast<int>(std::lround(0.1 / h));
    double e = 0, eu = 0;
    for (int sample = 1; sample <= 10; ++sample) {
      for (int n = 0; n < per_sample; ++n) bw.step(sc, h);
      const Eigen::VectorXd r = exact(cd, 0.1 * sample), ru = exact(0.0, 0.1 * sample);
      for (int i = 0; i < nf; ++i) {
        const double u = sc.state.x[3 * (i + 1)] - (i + 1) * l0;
        e = std::max(e, std::abs(u - r[i]));
        eu = std::max(eu, std::abs(u - ru[i]));
      }
    }
    errs.push_back(e);
    errs_undamped.push_back(eu);
  }
  for (std::size_t q = 1; q < errs.size(); ++q) {
    const double order = std::log2(errs[q - 1] / errs[q]);
    std::printf("h = %g: error %.3e (vs undamped %.3e), order %.3f\n", hs[q], errs[q],
                errs_undamped[q], order);
    EXPECT_GT(order, 0.85);
    EXPECT_LT(order, 1.2);
  }
  EXPECT_GT(errs_undamped.back(), 5 * errs.back());  // it converges to the damped motion
}

// Compressed springs without the clamp make A indefinite at large h (NUMERICS.md 3.5):
// on_solver_failure: stop throws SolverError with the reason; halve_step retries with h/2.
TEST(BaraffWitkin, SolverFailurePolicy) {
  const Index nx = 6, ny = 6;
  const double dx = 0.1;
  auto setup = [&](Scene& sc, SolverKind sk) {
    std::vector<double> x0 = grid_xy(nx, ny, dx);
    for (double& c : x0) c *= 0.7;  // every spring 30% compressed
    for (Index i = 0; i < nx * ny; ++i) x0[3 * i + 2] = 1e-3 * std::cos(2.3 * i);
    loom::testing::init_scene(sc, x0,
                              std::make_unique<SpringMaterial>(std::vector<double>(nx * ny, 0.01),
                                                               loom::testing::grid_springs(nx, ny, dx, 100), false));
    sc.gravity = {0, 0, 0};
    sc.solver = make_solver(sk, 1e-8);
  };
  const double h = 0.02;
  for (SolverKind sk : kBoth) {
    {
      Scene sc;
      setup(sc, sk);
      BaraffWitkin bw;  // default: stop
      bw.prepare(sc, h);
      const std::vector<double> x0 = sc.state.x;
      try {
        bw.step(sc, h);
        ADD_FAILURE() << label(sk) << ": an indefinite system was accepted";
      } catch (const loom::SolverError& e) {
        const std::string msg = e.what();
        EXPECT_NE(msg.find("iterations"), std::string::npos) << msg;
        EXPECT_NE(msg.find("not positive"), std::string::npos) << msg;
        EXPECT_NE(msg.find("halve_step"), std::string::npos) << msg;
      }
      EXPECT_EQ(sc.state.x, x0);  // nothing was half-applied
      EXPECT_EQ(sc.state.step, 0);
    }
    {
      Scene sc;
      setup(sc, sk);
      BaraffWitkinOptions o;
      o.on_failure = BaraffWitkinOptions::OnFailure::HalveStep;
      o.max_halvings = 1;  // h/2 is still indefinite here
      BaraffWitkin bw(o);
      bw.prepare(sc, h);
      EXPECT_THROW(bw.step(sc, h), loom::SolverError) << label(sk);
    }
    {
      Scene sc;
      setup(sc, sk);
      BaraffWitkinOptions o;
      o.on_failure = BaraffWitkinOptions::OnFailure::HalveStep;
      o.max_halvings = 5;
      BaraffWitkin bw(o);
      bw.prepare(sc, h);
      ASSERT_NO_THROW(bw.step(sc, h)) << label(sk);
      EXPECT_GE(bw.last_step().retries, 2) << label(sk);
      EXPECT_GE(bw.last_step().force_evaluations, 4);
      EXPECT_NEAR(sc.state.time, h, 1e-15);
      EXPECT_EQ(sc.state.step, 1);
      for (double xv : sc.state.x) EXPECT_TRUE(std::isfinite(xv));
    }
  }
}

// A solve that fails without a hint of halve_step (PCG out of iterations: its own message names
// max_iterations, dt and the direct solvers) gets it from the integrator under `stop`; under
// halve_step the message says how many halvings it gave up after instead.
TEST(BaraffWitkin, StopNamesHalveStepForEveryFailure) {
  const Index nx = 8, ny = 8;
  const double dx = 0.05;
  auto fail = [&](BaraffWitkinOptions::OnFailure mode) {
    Scene sc;
    loom::testing::init_scene(sc, grid_xz(nx, ny, dx),
                              std::make_unique<SpringMaterial>(std::vector<double>(nx * ny, 0.002),
                                                               loom::testing::grid_springs(nx, ny, dx, 2000), true));
    sc.state.pin((ny - 1) * nx);
    sc.state.update_inverse_masses();
    loom::PcgOptions po;
    po.tolerance = 1e-14;
    po.max_iterations = 1;  // never enough
    sc.solver = std::make_unique<loom::EigenPcg>(po);
    BaraffWitkinOptions o;
    o.on_failure = mode;
    o.max_halvings = 1;
    BaraffWitkin bw(o);
    bw.prepare(sc, 0.01);
    try {
      bw.step(sc, 0.01);
    } catch (const loom::SolverError& e) {
      return std::string(e.what());
    }
    return std::string("no failure");
  };
  const std::string stop = fail(BaraffWitkinOptions::OnFailure::Stop);
  EXPECT_NE(stop.find("not converged in 1 iterations"), std::string::npos) << stop;
  EXPECT_NE(stop.find("set integrator.on_solver_failure: halve_step"), std::string::npos) << stop;
  const std::string halve = fail(BaraffWitkinOptions::OnFailure::HalveStep);
  EXPECT_NE(halve.find("gave up after 1 halvings"), std::string::npos) << halve;
  EXPECT_EQ(halve.find("set integrator.on_solver_failure"), std::string::npos) << halve;
}

TEST(BaraffWitkin, StepStatsAndWarmStart) {
  auto run = [](bool warm, loom::StepStats& last) {
    Scene sc;
    const Index nx = 10, ny = 10;
    const double dx = 0.05;
    loom::testing::init_scene(sc, grid_xz(nx, ny, dx),
                              std::make_unique<SpringMaterial>(std::vector<double>(nx * ny, 0.002),
                                                               loom::testing::grid_springs(nx, ny, dx, 2000), true));
    sc.state.pin((ny - 1) * nx);
    sc.state.pin(ny * nx - 1);
    sc.state.update_inverse_masses();
    sc.solver = make_solver(SolverKind::Pcg, 1e-6);
    BaraffWitkinOptions o;
    o.warm_start = warm;
    BaraffWitkin bw(o);
    bw.prepare(sc, 0.005);
    long total = 0;
    for (int n = 0; n < 30; ++n) {
      bw.step(sc, 0.005);
      total += bw.last_step().linear_iterations;
    }
    last = bw.last_step();
    return total;
  };
  loom::StepStats a, b;
  const long warm = run(true, a), cold = run(false, b);
  std::printf("PCG iterations over 30 steps: warm %ld, cold %ld\n", warm, cold);
  EXPECT_LT(warm, cold);
  EXPECT_EQ(a.force_evaluations, 1);
  EXPECT_GT(a.linear_iterations, 0);
  EXPECT_LE(a.linear_residual, 1e-6);
  EXPECT_GT(a.linear_residual, 0.0);
  EXPECT_GT(a.assemble_seconds, 0.0);
  EXPECT_GT(a.solve_seconds, 0.0);
  EXPECT_EQ(a.retries, 0);
}

TEST(BaraffWitkin, RefusesImpossibleCombos) {
  class NoJacobian : public NullMaterial {
   public:
    using NullMaterial::NullMaterial;
    bool has_jacobian() const override { return false; }
  };
  {
    Scene sc;
    loom::testing::init_scene(sc, std::vector<double>{0, 0, 0},
                              std::make_unique<NoJacobian>(std::vector<double>{1.0}, std::vector<std::array<Index, 2>>{}));
    sc.solver = make_solver(SolverKind::Pcg);
    BaraffWitkin bw;
    try {
      bw.prepare(sc, 0.01);
      ADD_FAILURE() << "accepted a material without Jacobians";
    } catch (const loom::InputError& e) {
      EXPECT_NE(std::string(e.what()).find("Jacobian"), std::string::npos);
    }
  }
  {
    Scene sc;
    loom::testing::init_scene(sc, std::vector<double>{0, 0, 0},
                              std::make_unique<NullMaterial>(std::vector<double>{1.0}, std::vector<std::array<Index, 2>>{}));
    BaraffWitkin bw;
    try {
      bw.prepare(sc, 0.01);
      ADD_FAILURE() << "accepted a scene without a solver";
    } catch (const loom::InputError& e) {
      EXPECT_NE(std::string(e.what()).find("solver:"), std::string::npos);
    }
  }
  EXPECT_TRUE(BaraffWitkin().needs().jacobian);
  EXPECT_TRUE(BaraffWitkin().needs().linear_solver);
}

TEST(BaraffWitkin, ParametersAreChecked) {
  using loom::Params;
  const auto o = loom::parse_baraff_witkin_options(Params::from_string(
      "{kang_cho_damping: 0.5, rayleigh: {alpha: 0.1, beta: 0.002}, on_solver_failure: halve_step, "
      "max_halvings: 4, warm_start: false}"));
  EXPECT_EQ(o.kang_cho_damping, 0.5);
  EXPECT_EQ(o.rayleigh_alpha, 0.1);
  EXPECT_EQ(o.rayleigh_beta, 0.002);
  EXPECT_EQ(o.on_failure, BaraffWitkinOptions::OnFailure::HalveStep);
  EXPECT_EQ(o.max_halvings, 4);
  EXPECT_FALSE(o.warm_start);
  EXPECT_THROW(loom::parse_baraff_witkin_options(Params::from_string("{on_solver_failure: retry}")), loom::InputError);
  EXPECT_THROW(loom::parse_baraff_witkin_options(Params::from_string("{kang_cho_damping: -1}")), loom::InputError);
  EXPECT_THROW(loom::parse_baraff_witkin_options(Params::from_string("{rayleigh: {alpha: 1, gamma: 2}}")),
               loom::InputError);
  EXPECT_THROW(loom::parse_baraff_witkin_options(Params::from_string("{rayleigh: 0.1}")), loom::InputError);
  EXPECT_THROW(loom::parse_baraff_witkin_options(Params::from_string("{max_halvings: 0}")), loom::InputError);
}

// Above 2048 vertices the integrator's assembly and update passes are threaded: the same
// steps on 1 and 2 threads give the same system bit for bit and the same state. (Solved by
// eigen_ldlt: the threaded PCG iteration is compared with the serial one in
// test_eigen_solvers; here, on a loaded machine, it would cost seconds of barrier waits.)
TEST(BaraffWitkin, ThreadedPathsMatchSerial) {
  const Index nx = 48, ny = 48;  // 2304 vertices
  const double dx = 0.02;
  auto run = [&](int threads, SolverKind sk, std::vector<double>& x, std::vector<double>& A) {
    const int saved = omp_get_max_threads();
    omp_set_num_threads(threads);
    Scene sc;
    std::vector<double> x0 = grid_xz(nx, ny, dx);
    for (Index i = 0; i < nx * ny; ++i) x0[3 * i + 1] = 1e-3 * std::sin(0.37 * i);
    loom::testing::init_scene(sc, x0,
                              std::make_unique<SpringMaterial>(std::vector<double>(nx * ny, 1e-3),
                                                               loom::testing::grid_springs(nx, ny, dx, 200), true));
    sc.state.pin((ny - 1) * nx);
    sc.state.pin(ny * nx - 1);
    sc.state.update_inverse_masses();
    sc.solver = make_solver(sk, 1e-7);
    BaraffWitkinOptions o;
    o.kang_cho_damping = 0.01;
    BaraffWitkin bw(o);
    bw.prepare(sc, 0.005);
    bw.step(sc, 0.005);
    A = bw.system_matrix().values();  // assembled from the same initial state
    bw.step(sc, 0.005);
    x = sc.state.x;
    omp_set_num_threads(saved);
  };
  for (SolverKind sk : {SolverKind::Ldlt}) {
    std::vector<double> x1, x2, A1, A2;
    auto t0 = std::chrono::steady_clock::now();
    run(1, sk, x1, A1);
    auto t1 = std::chrono::steady_clock::now();
    run(2, sk, x2, A2);
    auto t2 = std::chrono::steady_clock::now();
    std::printf("%s: 1 thread %.0f ms, 2 threads %.0f ms (wall, this machine's load included)\n", label(sk),
                1e3 * std::chrono::duration<double>(t1 - t0).count(), 1e3 * std::chrono::duration<double>(t2 - t1).count());
    EXPECT_EQ(A1, A2) << label(sk);  // the assembly of the first step, bit for bit
    std::vector<double> d1(x1.size()), d2(x2.size());
    const std::vector<double> x0 = grid_xz(nx, ny, dx);
    for (std::size_t k = 0; k < x1.size(); ++k) {
      d1[k] = x1[k] - x0[k];
      d2[k] = x2[k] - x0[k];
    }
    EXPECT_LT(rel_err(d2, d1), 1e-12) << label(sk);
  }
}

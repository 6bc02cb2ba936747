// Test and benchmark systems for the linear-solver backends (cholmod, petsc): implicit-Euler
// matrices A = M - h^2 df/dx of spring networks, with a Baraff-Witkin filter S (pins and
// direction constraints), a prescribed constrained velocity change z and a right-hand side b.
// The spring Jacobian comes from loom/kernels/spring.hpp (the same math mass_spring uses);
// the dense reference solves the projected system of NUMERICS.md 3.4 with Eigen's LDLT.
#pragma once

#include <Eigen/Dense>

#include <array>
#include <cmath>
#include <memory>
#include <random>
#include <span>
#include <vector>

#include "loom/bsr.hpp"
#include "loom/kernels/spring.hpp"

namespace loom::testsys {

struct System {
  Index n = 0;
  std::unique_ptr<BsrPattern> pattern;  // owned here; A points into it
  BsrMatrix A;
  Filter S;
  std::vector<double> b, z;
  std::vector<double> x;                // positions (3n)
  std::vector<std::array<Index, 2>> springs;
  std::vector<double> k, l0, mass;
  double h = 0.01;
};

/// A = M - h^2 sum_springs dfdx (clamped transverse term when clamp: SPD).
inline void assemble(System& s, bool clamp) {
  s.A.set_zero();
  const double h2 = s.h * s.h;
  const BsrPattern& P = *s.pattern;
  for (Index i = 0; i < s.n; ++i) {
    double* D = s.A.block(P.diag[i]);
    for (int r = 0; r < 3; ++r) D[4 * r] += s.mass[i];
  }
  for (std::size_t e = 0; e < s.springs.size(); ++e) {
    const Index i = s.springs[e][0], j = s.springs[e][1];
    double K[9];
    kernels::spring_stiffness_block(&s.x[3 * i], &s.x[3 * j], s.k[e], s.l0[e], clamp, K);
    // df_i/dx_j = K, df_i/dx_i = -K: A_ij -= h^2 K, A_ii += h^2 K (same for j).
    double* Aij = s.A.block(P.find(i, j));
    double* Aji = s.A.block(P.find(j, i));
    double* Aii = s.A.block(P.diag[i]);
    double* Ajj = s.A.block(P.diag[j]);
    for (int t = 0; t < 9; ++t) {
      Aij[t] -= h2 * K[t];
      Aji[t] -= h2 * K[t];
      Aii[t] += h2 * K[t];
      Ajj[t] += h2 * K[t];
    }
  }
}

inline void finish(System& s) {
  s.pattern = std::make_unique<BsrPattern>(BsrPattern::from_pairs(s.n, s.springs));
  s.A = BsrMatrix(s.pattern.get());
}

/// Random unit vector.
inline std::array<double, 3> random_unit(std::mt19937_64& rng) {
  std::normal_distribution<double> g(0.0, 1.0);
  std::array<double, 3> p{g(rng), g(rng), g(rng)};
  const double l = std::sqrt(p[0] * p[0] + p[1] * p[1] + p[2] * p[2]);
  for (double& c : p) c /= l;
  return p;
}

/// Random constraints: fraction `pinned` fully pinned, `dir1` with one removed direction,
/// `dir2` with two; z = (I - S) * random (nonzero prescribed velocity change) when nonzero_z.
inline void random_constraints(System& s, std::mt19937_64& rng, double pinned, double dir1, double dir2,
                               bool nonzero_z) {
  std::uniform_real_distribution<double> u(0.0, 1.0), w(-1.0, 1.0);
  s.S.reset(s.n);
  for (Index i = 0; i < s.n; ++i) {
    const double t = u(rng);
    if (t < pinned) {
      s.S.constrain_all(i);
    } else if (t < pinned + dir1) {
      auto p = random_unit(rng);
      s.S.constrain_direction(i, p.data());
    } else if (t < pinned + dir1 + dir2) {
      auto p = random_unit(rng), q = random_unit(rng);
      s.S.constrain_direction(i, p.data());
      s.S.constrain_direction(i, q.data());
    }
  }
  s.z.assign(3 * s.n, 0.0);
  if (nonzero_z) {
    for (Index i : s.S.constrained()) {
      double r[3] = {w(rng), w(rng), w(rng)};
      const auto& Si = s.S.projector(i);
      for (int a = 0; a < 3; ++a)
        s.z[3 * i + a] = r[a] - (Si[3 * a] * r[0] + Si[3 * a + 1] * r[1] + Si[3 * a + 2] * r[2]);
    }
  }
}

/// Random spring network: n particles in the unit cube, a chain plus `extra` random springs
/// per particle, rest lengths l (1 + U(-compress, +compress)), masses in [1e-3, 1].
inline System random_network(Index n, std::uint64_t seed, double h = 0.01, double compress = 0.3,
                             int extra = 3, bool clamp = true) {
  System s;
  s.n = n;
  s.h = h;
  std::mt19937_64 rng(seed);
  std::uniform_real_distribution<double> u(0.0, 1.0);
  s.x.resize(3 * n);
  for (double& c : s.x) c = u(rng);
  s.mass.resize(n);
  for (double& m : s.mass) m = std::pow(10.0, -3.0 + 3.0 * u(rng));
  auto add = [&](Index i, Index j) {
    if (i == j) return;
    const double d0 = s.x[3 * j] - s.x[3 * i], d1 = s.x[3 * j + 1] - s.x[3 * i + 1], d2 = s.x[3 * j + 2] - s.x[3 * i + 2];
    const double l = std::sqrt(d0 * d0 + d1 * d1 + d2 * d2);
    s.springs.push_back({i, j});
    s.k.push_back(100.0 + 900.0 * u(rng));
    s.l0.push_back(l * (1.0 + compress * (2.0 * u(rng) - 1.0)));
  };
  for (Index i = 0; i + 1 < n; ++i) add(i, i + 1);
  std::uniform_int_distribution<Index> pick(0, n - 1);
  for (Index i = 0; i < n; ++i)
    for (int e = 0; e < extra; ++e) add(i, pick(rng));
  finish(s);
  assemble(s, clamp);
  random_constraints(s, rng, 0.1, 0.1, 0.1, true);
  s.b.resize(3 * n);
  for (double& c : s.b) c = 2.0 * u(rng) - 1.0;
  return s;
}

/// Hanging mass-spring cloth, nx x nx vertices, width 1 m, structural + shear + bend springs,
/// stretched 2% along y with small out-of-plane noise (so transverse terms are present),
/// top corners pinned. h^2 k / m = stiffness_ratio for the structural springs. b is
/// h * (gravity force) plus noise, as in a Baraff-Witkin step.
inline System cloth(Index nx, double h = 1e-3, double stiffness_ratio = 1e3, std::uint64_t seed = 1) {
  System s;
  s.n = nx * nx;
  s.h = h;
  std::mt19937_64 rng(seed);
  std::uniform_real_distribution<double> u(-1.0, 1.0);
  const double dx = 1.0 / (nx - 1);
  const double m = 0.1 / s.n;  // 0.1 kg cloth
  const double k = stiffness_ratio * m / (h * h);
  s.mass.assign(s.n, m);
  s.x.resize(3 * s.n);
  for (Index iy = 0; iy < nx; ++iy)
    for (Index ix = 0; ix < nx; ++ix) {
      const Index v = iy * nx + ix;
      s.x[3 * v] = ix * dx;
      s.x[3 * v + 1] = iy * dx * 1.02;
      s.x[3 * v + 2] = 0.01 * dx * u(rng);
    }
  auto add = [&](Index a, Index b, double kk, double rest) {
    s.springs.push_back({a, b});
    s.k.push_back(kk);
    s.l0.push_back(rest);
  };
  const double diag = dx * std::sqrt(2.0);
  for (Index iy = 0; iy < nx; ++iy)
    for (Index ix = 0; ix < nx; ++ix) {
      const Index v = iy * nx + ix;
      if (ix + 1 < nx) add(v, v + 1, k, dx);
      if (iy + 1 < nx) add(v, v + nx, k, dx);
      if (ix + 1 < nx && iy + 1 < nx) add(v, v + nx + 1, k, diag);
      if (ix > 0 && iy + 1 < nx) add(v, v + nx - 1, k, diag);
      if (ix + 2 < nx) add(v, v + 2, 0.05 * k, 2 * dx);
      if (iy + 2 < nx) add(v, v + 2 * nx, 0.05 * k, 2 * dx);
    }
  finish(s);
  assemble(s, true);
  s.S.reset(s.n);
  s.S.constrain_all((nx - 1) * nx);
  s.S.constrain_all(nx * nx - 1);
  s.z.assign(3 * s.n, 0.0);
  s.b.resize(3 * s.n);
  for (Index i = 0; i < s.n; ++i) {
    s.b[3 * i] = h * 0.01 * m * u(rng);
    s.b[3 * i + 1] = -h * 9.81 * m;
    s.b[3 * i + 2] = h * 0.01 * m * u(rng);
  }
  return s;
}

// ---- dense reference (NUMERICS.md 3.4) ----

inline Eigen::MatrixXd dense(const BsrMatrix& A) {
  const Index N = 3 * A.rows();
  auto d = A.to_dense();
  return Eigen::Map<Eigen::Matrix<double, Eigen::Dynamic, Eigen::Dynamic, Eigen::RowMajor>>(d.data(), N, N);
}

inline Eigen::MatrixXd dense_filter(const Filter& S) {
  const Index n = S.size();
  Eigen::MatrixXd M = Eigen::MatrixXd::Zero(3 * n, 3 * n);
  for (Index i = 0; i < n; ++i)
    for (int r = 0; r < 3; ++r)
      for (int c = 0; c < 3; ++c) M(3 * i + r, 3 * i + c) = S.projector(i)[3 * r + c];
  return M;
}

/// Projected matrix A~ = S A S + (I - S).
inline Eigen::MatrixXd projected_matrix(const System& s) {
  const Eigen::MatrixXd A = dense(s.A), S = dense_filter(s.S);
  const Eigen::Index N = A.rows();
  return S * A * S + (Eigen::MatrixXd::Identity(N, N) - S);
}

/// dv solving A~ dv = S (b - A z) + z with Eigen's dense LDLT.
inline Eigen::VectorXd dense_solution(const System& s) {
  const Eigen::MatrixXd A = dense(s.A), S = dense_filter(s.S);
  const Eigen::Index N = A.rows();
  const Eigen::Map<const Eigen::VectorXd> b(s.b.data(), N), z(s.z.data(), N);
  const Eigen::MatrixXd At = S * A * S + (Eigen::MatrixXd::Identity(N, N) - S);
  const Eigen::VectorXd bt = S * (b - A * z) + z;
  return At.ldlt().solve(bt);
}

/// Smallest eigenvalue of A restricted to range(S) (A~'s extra unit eigenvalues excluded
/// by shifting them far up).
inline double min_eig_on_range(const System& s) {
  const Eigen::MatrixXd A = dense(s.A), S = dense_filter(s.S);
  const Eigen::Index N = A.rows();
  const Eigen::MatrixXd At = S * A * S + 1e12 * (Eigen::MatrixXd::Identity(N, N) - S);
  Eigen::SelfAdjointEigenSolver<Eigen::MatrixXd> es(0.5 * (At + At.transpose()), Eigen::EigenvaluesOnly);
  return es.eigenvalues().minCoeff();
}

inline double rel_diff(std::span<const double> a, const Eigen::VectorXd& ref) {
  double num = 0, den = 0;
  for (Eigen::Index i = 0; i < ref.size(); ++i) {
    num += (a[i] - ref[i]) * (a[i] - ref[i]);
    den += ref[i] * ref[i];
  }
  return std::sqrt(num / den);
}

/// The preconditioner tests' set: two random spring networks (pins, 1- and 2-direction
/// constraints, nonzero z, masses over 3 decades), the hanging mass-spring cloth (pinned
/// corners), and a cloth with random contacts.
inline std::vector<System> preconditioner_systems() {
  std::vector<System> v;
  v.push_back(random_network(150, 3));
  v.push_back(random_network(200, 8, 0.01, 0.3, 2));
  v.push_back(cloth(12));
  System c = cloth(14, 1e-3, 1e4, 2);
  std::mt19937_64 rng(5);
  random_constraints(c, rng, 0.05, 0.1, 0.05, true);  // contacts on a cloth
  v.push_back(std::move(c));
  return v;
}

}  // namespace loom::testsys

// The filtered PCG's SpMV from a float copy of A (PcgOptions::float_spmv, `spmv_storage: float`,
// plugins/solvers/eigen/float_spmv.hpp): the product is within the float rounding bound of the
// double one, the PCG (block Jacobi and sa_amg) still meets the tolerance on the double A with
// about the same iterations, its iterates decrease the error monotonically in the norm of the
// float matrix (it is CG on A_f), and the key is parsed and checked.
#include <gtest/gtest.h>

#include <Eigen/Dense>
#include <algorithm>
#include <cmath>
#include <random>
#include <vector>

#include "eigen_pcg.hpp"
#include "float_spmv.hpp"
#include "half.hpp"
#include "loom/params.hpp"
#include "loom/solver_common.hpp"
#include "solver_systems.hpp"

namespace {

using loom::Index;
namespace ts = loom::testsys;

std::vector<ts::System> systems() { return ts::preconditioner_systems(); }

loom::PcgOptions options(loom::PcgPreconditioner pc, double tol, bool fl, int maxit = 1000) {
  loom::PcgOptions o;
  o.preconditioner = pc;
  o.tolerance = tol;
  o.max_iterations = maxit;
  o.amg.coarse_dofs = 24;
  o.float_spmv = fl;
  return o;
}

loom::SolveReport solve(ts::System& s, const loom::PcgOptions& o, std::vector<double>& dv) {
  loom::EigenPcg p(o);
  p.set_coordinates(s.x);
  p.analyze_pattern(s.A, s.S);
  loom::SolveReport f;
  EXPECT_TRUE(p.factorize(s.A, s.S, f)) << f.message;
  dv.assign(3 * static_cast<std::size_t>(s.n), 0.0);
  return p.solve(s.A, s.S, s.b, s.z, dv);
}

// |S(b - A dv)| / |S(b - A z)| with dense Eigen algebra (independent of the solver's kernels).
double true_relative_residual(const ts::System& s, const std::vector<double>& dv) {
  const Eigen::MatrixXd A = ts::dense(s.A), S = ts::dense_filter(s.S);
  const Eigen::Index N = A.rows();
  const Eigen::Map<const Eigen::VectorXd> b(s.b.data(), N), z(s.z.data(), N), x(dv.data(), N);
  return (S * (b - A * x)).norm() / (S * (b - A * z)).norm();
}

// R = Pᵀ for the level-0 transfer kernels: P has nf block rows of 3x6 blocks (rows prp, columns
// pcol, 18 values per block), R gets nc block rows of 6x3 blocks, each the transpose of a block of P.
template <class T>
void transpose_transfer(Index nf, Index nc, const std::vector<Index>& prp, const std::vector<Index>& pcol,
                        const std::vector<T>& pv, std::vector<Index>& rrp, std::vector<Index>& rcol,
                        std::vector<T>& rv) {
  rrp.assign(static_cast<std::size_t>(nc) + 1, 0);
  rcol.assign(pcol.size(), 0);
  rv.assign(pv.size(), T{});
  for (Index c : pcol) ++rrp[c + 1];
  for (Index I = 0; I < nc; ++I) rrp[I + 1] += rrp[I];
  std::vector<Index> fill(rrp.begin(), rrp.end() - 1);
  for (Index i = 0; i < nf; ++i)
    for (Index k = prp[i]; k < prp[i + 1]; ++k) {
      const Index q = fill[pcol[k]]++;
      rcol[q] = i;
      for (int a = 0; a < 3; ++a)
        for (int c = 0; c < 6; ++c) rv[18 * q + 3 * c + a] = pv[18 * k + 6 * a + c];
    }
}

}  // namespace

// Each entry of the float-copy product differs from the double product (Eigen, dense) by at
// most the rounding of the stored values, 2^-24 sum_j |A_ij| |x_j|, plus double rounding; and
// the float path is really taken (the two differ somewhere: the values are not all floats).
TEST(FloatSpmv, ProductIsWithinTheFloatRoundingBound) {
  std::mt19937_64 rng(7);
  std::normal_distribution<double> g;
  for (ts::System& s : systems()) {
    std::vector<float> af;
    loom::float_copy_values(s.A.values(), af, false);
    ASSERT_EQ(af.size(), s.A.values().size() + 4);
    for (std::size_t k = s.A.values().size(); k < af.size(); ++k) EXPECT_EQ(af[k], 0.0f);
    const std::size_t N = 3 * static_cast<std::size_t>(s.n);
    std::vector<double> x(N), y(N);
    for (double& e : x) e = g(rng);
    const loom::BsrPattern& P = s.A.pattern();
    for (Index i = 0; i < s.n; ++i)
      loom::block_row_multiply3(P.row_ptr.data(), P.col.data(), af.data(), x.data(), i, y.data() + 3 * static_cast<std::size_t>(i));
    const Eigen::MatrixXd A = ts::dense(s.A);
    const Eigen::Map<const Eigen::VectorXd> xv(x.data(), static_cast<Eigen::Index>(N));
    const Eigen::VectorXd ref = A * xv, mag = A.cwiseAbs() * xv.cwiseAbs();
    double largest = 0;
    for (std::size_t k = 0; k < N; ++k) {
      const double d = std::abs(y[k] - ref[static_cast<Eigen::Index>(k)]);
      EXPECT_LE(d, (std::ldexp(1.0, -24) + 64 * 1.1e-16) * mag[static_cast<Eigen::Index>(k)]) << "entry " << k;
      largest = std::max(largest, d / mag[static_cast<Eigen::Index>(k)]);
    }
    EXPECT_GT(largest, 1e-12) << "n " << s.n;  // the float copy rounds (a double product would be ~1e-16)
  }
}

// The answer meets the tolerance on the double A (the stopping rule's true residual, recomputed
// here with dense algebra) and, at 1e-9, matches the dense projected solution, for block Jacobi
// and sa_amg. At 1e-5 the iteration count stays within 2 of the double SpMV's; at 1e-9 the float
// operator's error (2^-24 relative per entry, amplified by the conditioning) is above the
// tolerance, so the loop restarts from the true residual (iterative refinement) and takes more.
// block_row.hpp is one template for double and float blocks (3x3 and 6x6): on values that
// are floats, the float instance (widening on load) must give bit for bit what the double
// instance gives on the same values held as doubles, every row, block rows of any length
// (including empty), the last block ending the array (nothing read past it: the float copy
// has no padding here).
TEST(FloatSpmv, FloatAndDoubleBlockRowProductsAreOneKernel) {
  std::mt19937_64 rng(5);
  std::uniform_real_distribution<double> u(-1.0, 1.0);
  std::uniform_int_distribution<int> len(0, 9);
  for (int bs : {3, 6}) {
    const Index rows = 40, cols = 40;
    std::vector<Index> rp{0}, col;
    for (Index i = 0; i < rows; ++i) {
      const int l = len(rng);
      for (int k = 0; k < l; ++k) col.push_back(static_cast<Index>((i * 7 + 3 * k) % cols));
      rp.push_back(static_cast<Index>(col.size()));
    }
    const std::size_t nv = col.size() * bs * bs;
    std::vector<float> vf(nv);
    for (float& v : vf) v = static_cast<float>(u(rng) * 1e3);
    const std::vector<double> vd(vf.begin(), vf.end());
    std::vector<double> x(static_cast<std::size_t>(cols) * bs);
    for (double& v : x) v = u(rng);
    for (Index i = 0; i < rows; ++i) {
      double yf[6], yd[6], ref[6] = {};
      if (bs == 3) {
        loom::block_row_multiply3(rp.data(), col.data(), vf.data(), x.data(), i, yf);
        loom::block_row_multiply3(rp.data(), col.data(), vd.data(), x.data(), i, yd);
      } else {
        loom::block_row_multiply6(rp.data(), col.data(), vf.data(), x.data(), i, yf);
        loom::block_row_multiply6(rp.data(), col.data(), vd.data(), x.data(), i, yd);
      }
      double mag[6] = {};
      for (Index k = rp[i]; k < rp[i + 1]; ++k)
        for (int a = 0; a < bs; ++a)
          for (int c = 0; c < bs; ++c) {
            const double t = vd[(static_cast<std::size_t>(k) * bs + a) * bs + c] * x[static_cast<std::size_t>(col[k]) * bs + c];
            ref[a] += t;
            mag[a] += std::abs(t);
          }
      for (int a = 0; a < bs; ++a) {
        EXPECT_EQ(yf[a], yd[a]) << "block " << bs << " row " << i << " entry " << a;
        EXPECT_LE(std::abs(yd[a] - ref[a]), 1e-14 * mag[a]) << "block " << bs << " row " << i;
      }
    }
  }
}

TEST(FloatSpmv, PcgMeetsTheToleranceOnTheDoubleMatrix) {
  for (ts::System& s : systems()) {
    const Eigen::VectorXd exact = ts::dense_solution(s);
    for (auto pc : {loom::PcgPreconditioner::BlockJacobi, loom::PcgPreconditioner::SaAmg})
      for (double tol : {1e-5, 1e-9}) {
        std::vector<double> f, d;
        const loom::SolveReport rf = solve(s, options(pc, tol, true), f);
        const loom::SolveReport rd = solve(s, options(pc, tol, false), d);
        ASSERT_TRUE(rf.converged && rd.converged) << rf.message << rd.message;
        const double res = true_relative_residual(s, f);
        EXPECT_LE(rf.residual, tol);
        EXPECT_NEAR(res, rf.residual, 1e-6 * tol + 1e-12) << "reported residual is the true one";
        EXPECT_LE(res, tol * (1 + 1e-6));
        if (tol > 1e-6) {
          EXPECT_LE(std::abs(rf.iterations - rd.iterations), 2) << "n " << s.n << " tol " << tol;
        } else {
          EXPECT_GE(rf.iterations, rd.iterations - 2) << "n " << s.n;
          EXPECT_LT(ts::rel_diff(f, exact), 1e-5) << "n " << s.n;
        }
      }
  }
}

// CG on A_f = fl32(A): from dv_0 = z and r_0 = S(b - A z) (double), the iterates minimise the
// A_f-norm error against dv* = z + A~_f^-1 r_0 (A~_f = S A_f S + I - S, dense, from the float
// values), so ||dv_k - dv*||_{A~_f} never grows with k (dv_k: the solver stopped after k
// iterations, cold start). Checked while the error is above 100 times ||dv* - dv*_double||:
// once the recursive residual meets the tolerance the loop restarts on the double residual,
// whose answer is dv*_double, so the later iterates approach that one instead.
TEST(FloatSpmv, PcgErrorDecreasesMonotonicallyInTheFloatMatrixNorm) {
  for (ts::System& s : systems()) {
    std::vector<float> af;
    loom::float_copy_values(s.A.values(), af, false);
    loom::BsrMatrix Af(&s.A.pattern());
    for (std::size_t k = 0; k < s.A.values().size(); ++k) Af.values()[k] = static_cast<double>(af[k]);
    const Eigen::MatrixXd A = ts::dense(s.A), Afd = ts::dense(Af), S = ts::dense_filter(s.S);
    const Eigen::Index N = A.rows();
    const Eigen::MatrixXd I = Eigen::MatrixXd::Identity(N, N);
    const Eigen::MatrixXd At = S * Afd * S + (I - S);
    const Eigen::Map<const Eigen::VectorXd> b(s.b.data(), N), z(s.z.data(), N);
    const Eigen::VectorXd star = z + At.ldlt().solve(S * (b - A * z));
    const Eigen::VectorXd gap = star - ts::dense_solution(s);
    const double floor = std::sqrt(gap.dot(At * gap));
    ASSERT_GT(floor, 0.0);
    for (auto pc : {loom::PcgPreconditioner::BlockJacobi, loom::PcgPreconditioner::SaAmg}) {
      double prev = INFINITY;
      int steps = 0;
      for (int k = 1; k <= 60; ++k) {
        loom::PcgOptions o = options(pc, 1e-12, true, k);
        loom::EigenPcg p(o);
        p.set_coordinates(s.x);
        p.analyze_pattern(s.A, s.S);
        loom::SolveReport f;
        ASSERT_TRUE(p.factorize(s.A, s.S, f));
        std::vector<double> dv(3 * static_cast<std::size_t>(s.n), 0.0);
        const loom::SolveReport rep = p.solve(s.A, s.S, s.b, s.z, dv);
        const Eigen::VectorXd e = Eigen::Map<const Eigen::VectorXd>(dv.data(), N) - star;
        const double ea = std::sqrt(std::max(0.0, e.dot(At * e)));
        if (rep.converged || ea <= 100 * floor) break;
        EXPECT_LE(ea, prev * (1 + 1e-9) + 1e-14) << "iteration " << k << " n " << s.n;
        prev = ea;
        ++steps;
      }
      EXPECT_GT(steps, 2) << "n " << s.n;
    }
  }
}

// `spmv_storage: float | double` (default double); anything else is an input error.
TEST(FloatSpmv, ParsesTheKey) {
  EXPECT_FALSE(loom::parse_pcg_options(loom::Params::from_string("tolerance: 1.0e-5\n", "<t>")).float_spmv);
  EXPECT_TRUE(loom::parse_pcg_options(loom::Params::from_string("spmv_storage: float\n", "<t>")).float_spmv);
  EXPECT_FALSE(loom::parse_pcg_options(loom::Params::from_string("spmv_storage: double\n", "<t>")).float_spmv);
  EXPECT_THROW(loom::parse_pcg_options(loom::Params::from_string("spmv_storage: half\n", "<t>")), loom::InputError);
}

// The level-0 transfer kernels of sa_amg (block_row.hpp: R r over 6x3 blocks, x += P x_c over
// 3x6 blocks) against the plain sums of their definitions, for float and double blocks, block
// rows of any length (including empty), the last block ending the array; the float instance
// on float values gives bit for bit what the double one gives on the same values, and
// restricting with R = Pᵀ equals the transpose of prolongating with P: y.(R r) = (P y).r.
TEST(FloatSpmv, TransferKernelsMatchTheirDefinition) {
  std::mt19937_64 rng(17);
  std::uniform_real_distribution<double> u(-1.0, 1.0);
  std::uniform_int_distribution<int> len(0, 7);
  const Index nf = 50, nc = 12;  // fine rows (3 DOFs), coarse rows (6 DOFs)
  // P: nf block rows of 3x6 blocks, sorted columns.
  std::vector<Index> prp{0}, pcol;
  for (Index i = 0; i < nf; ++i) {
    const int l = len(rng) % 4;
    for (int k = 0; k < l; ++k) pcol.push_back(static_cast<Index>((i / 5 + 2 * k) % nc));
    std::sort(pcol.begin() + prp.back(), pcol.end());
    pcol.erase(std::unique(pcol.begin() + prp.back(), pcol.end()), pcol.end());
    prp.push_back(static_cast<Index>(pcol.size()));
  }
  std::vector<float> pf(pcol.size() * 18);
  for (float& v : pf) v = static_cast<float>(u(rng));
  // R = Pᵀ: nc block rows of 6x3 blocks (each the transpose of a block of P).
  std::vector<Index> rrp, rcol;
  std::vector<float> rf;
  transpose_transfer(nf, nc, prp, pcol, pf, rrp, rcol, rf);
  const std::vector<double> pd(pf.begin(), pf.end()), rd(rf.begin(), rf.end());
  std::vector<double> r(3 * nf), xc(6 * nc);
  for (double& v : r) v = u(rng);
  for (double& v : xc) v = u(rng);
  // Restriction.
  std::vector<double> b(6 * nc), bd(6 * nc);
  for (Index I = 0; I < nc; ++I) {
    loom::block_row_restrict63(rrp.data(), rcol.data(), rf.data(), r.data(), I, b.data() + 6 * I);
    loom::block_row_restrict63(rrp.data(), rcol.data(), rd.data(), r.data(), I, bd.data() + 6 * I);
    for (int c = 0; c < 6; ++c) {
      double ref = 0, mag = 0;
      for (Index k = rrp[I]; k < rrp[I + 1]; ++k)
        for (int a = 0; a < 3; ++a) {
          const double t = rd[18 * k + 3 * c + a] * r[3 * rcol[k] + a];
          ref += t;
          mag += std::abs(t);
        }
      EXPECT_EQ(b[6 * I + c], bd[6 * I + c]) << "coarse row " << I;
      EXPECT_LE(std::abs(b[6 * I + c] - ref), 1e-14 * mag) << "coarse row " << I;
    }
  }
  // Prolongation (adds to x).
  std::vector<double> x(3 * nf), xd(3 * nf);
  for (std::size_t k = 0; k < x.size(); ++k) x[k] = xd[k] = u(rng);
  const std::vector<double> x0 = x;
  for (Index i = 0; i < nf; ++i) {
    loom::block_row_prolong36_add(prp.data(), pcol.data(), pf.data(), xc.data(), i, x.data() + 3 * i);
    loom::block_row_prolong36_add(prp.data(), pcol.data(), pd.data(), xc.data(), i, xd.data() + 3 * i);
    for (int a = 0; a < 3; ++a) {
      double ref = x0[3 * i + a], mag = std::abs(ref);
      for (Index k = prp[i]; k < prp[i + 1]; ++k)
        for (int c = 0; c < 6; ++c) {
          const double t = pd[18 * k + 6 * a + c] * xc[6 * pcol[k] + c];
          ref += t;
          mag += std::abs(t);
        }
      EXPECT_EQ(x[3 * i + a], xd[3 * i + a]) << "fine row " << i;
      EXPECT_LE(std::abs(x[3 * i + a] - ref), 1e-14 * mag) << "fine row " << i;
    }
  }
  // Adjoint: xc.(R r) = (P xc).r, with P xc = x - x0.
  double lhs = 0, rhs = 0, mag = 0;
  for (std::size_t k = 0; k < xc.size(); ++k) lhs += xc[k] * b[k];
  for (std::size_t k = 0; k < r.size(); ++k) {
    rhs += (x[k] - x0[k]) * r[k];
    mag += std::abs(x[k] - x0[k]) * std::abs(r[k]);
  }
  EXPECT_LE(std::abs(lhs - rhs), 1e-13 * mag);
  EXPECT_GT(mag, 0.0);
}

// IEEE half (half.hpp, sa_amg's level-0 transfers): every half widens to the float its bits
// define (checked against the formula sign * 2^(e-15) * (1 + m/1024), or m * 2^-24 for
// subnormals), and float_to_half rounds to the nearest half with ties to even, checked against
// a brute-force search over the sorted finite halves; the hardware conversions (F16C) and the
// portable code give the same bits.
TEST(FloatSpmv, HalfConversionsRoundToNearestEven) {
  std::vector<float> pos;  // the finite non-negative halves, increasing with their bits
  for (std::uint32_t b = 0; b < 0x10000u; ++b) {
    const loom::Half h{static_cast<std::uint16_t>(b)};
    const std::uint32_t e = (b >> 10) & 0x1fu, m = b & 0x3ffu;
    if (e == 0x1f) {
      EXPECT_TRUE(m ? std::isnan(loom::half_to_float_portable(h)) : std::isinf(loom::half_to_float_portable(h)));
      continue;
    }
    const double mag = e ? std::ldexp(1.0 + m / 1024.0, static_cast<int>(e) - 15) : std::ldexp(static_cast<double>(m), -24);
    const double ref = (b & 0x8000u) ? -mag : mag;
    ASSERT_EQ(static_cast<double>(loom::half_to_float_portable(h)), ref) << "bits " << b;
    ASSERT_EQ(static_cast<double>(loom::half_to_float(h)), ref) << "bits " << b;
    if (!(b & 0x8000u)) pos.push_back(static_cast<float>(mag));
  }
  ASSERT_EQ(pos.size(), 0x7c00u);
  auto nearest = [&](float x) -> std::uint16_t {  // brute force: the closest half, ties to even bits
    const double a = std::abs(static_cast<double>(x));
    const std::uint16_t sign = std::signbit(x) ? 0x8000 : 0;
    const double top = 65504.0 + 16.0;  // halfway to the next binade's first value: rounds to inf
    if (a >= top) return sign | 0x7c00;
    const auto it = std::lower_bound(pos.begin(), pos.end(), static_cast<float>(a));
    std::size_t hi = static_cast<std::size_t>(it - pos.begin());
    if (hi == pos.size()) return static_cast<std::uint16_t>(sign | (pos.size() - 1));
    if (hi == 0) return sign;
    const std::size_t lo = hi - 1;
    const double dl = a - pos[lo], dh = pos[hi] - a;
    const std::size_t pick = dl < dh ? lo : dh < dl ? hi : (lo % 2 == 0 ? lo : hi);
    return static_cast<std::uint16_t>(sign | pick);
  };
  std::mt19937_64 rng(5);
  std::vector<float> xs;
  std::uniform_real_distribution<double> expo(-27.0, 17.0), unit(0.0, 1.0);
  for (int t = 0; t < 200000; ++t) {
    const double v = std::exp2(expo(rng));
    xs.push_back(static_cast<float>(unit(rng) < 0.5 ? -v : v));
  }
  for (float h : pos) {  // each half, the midpoints to its neighbours and the floats beside them
    xs.push_back(h);
    xs.push_back(-h);
    xs.push_back(std::nextafter(h, 0.0f));
    xs.push_back(std::nextafter(h, 1e9f));
  }
  for (std::size_t k = 0; k + 1 < pos.size(); ++k) {
    const float mid = static_cast<float>(0.5 * (static_cast<double>(pos[k]) + pos[k + 1]));  // exact in float
    xs.push_back(mid);
    xs.push_back(std::nextafter(mid, 0.0f));
    xs.push_back(std::nextafter(mid, 1e9f));
  }
  xs.push_back(65519.0f);
  xs.push_back(65520.0f);
  xs.push_back(1e30f);
  for (float x : xs) {
    const std::uint16_t want = nearest(x);
    ASSERT_EQ(loom::float_to_half_portable(x).bits, want) << "x " << x;
    ASSERT_EQ(loom::float_to_half(x).bits, want) << "x " << x;
  }
}

// The transfer kernels on half values: the same bits as on their values widened to double
// (every half is a double), so the half path is the same kernel reading 2 bytes per value.
TEST(FloatSpmv, HalfTransferKernelsEqualTheWidenedDoubleKernels) {
  std::mt19937_64 rng(23);
  std::uniform_real_distribution<double> u(-2.0, 2.0);
  const Index nf = 40, nc = 9;
  std::vector<Index> prp{0}, pcol;
  for (Index i = 0; i < nf; ++i) {
    for (int k = 0; k < 1 + static_cast<int>(i % 4); ++k) pcol.push_back(static_cast<Index>((i / 5 + 2 * k) % nc));
    std::sort(pcol.begin() + prp.back(), pcol.end());
    pcol.erase(std::unique(pcol.begin() + prp.back(), pcol.end()), pcol.end());
    prp.push_back(static_cast<Index>(pcol.size()));
  }
  std::vector<loom::Half> ph(pcol.size() * 18);
  for (loom::Half& v : ph) v = loom::float_to_half(static_cast<float>(u(rng)));
  std::vector<double> pd(ph.size());
  for (std::size_t k = 0; k < ph.size(); ++k) pd[k] = loom::widen(ph[k]);
  // R as 6x3 blocks per coarse row, from the same values (here one block row per coarse
  // row holding P's blocks of that column, transposed).
  std::vector<Index> rrp, rcol;
  std::vector<loom::Half> rh;
  transpose_transfer(nf, nc, prp, pcol, ph, rrp, rcol, rh);
  std::vector<double> rd(rh.size());
  for (std::size_t k = 0; k < rh.size(); ++k) rd[k] = loom::widen(rh[k]);
  std::vector<double> r(3 * nf), xc(6 * nc);
  for (double& v : r) v = u(rng);
  for (double& v : xc) v = u(rng);
  for (Index I = 0; I < nc; ++I) {
    double bh[6], bd[6];
    loom::block_row_restrict63(rrp.data(), rcol.data(), rh.data(), r.data(), I, bh);
    loom::block_row_restrict63(rrp.data(), rcol.data(), rd.data(), r.data(), I, bd);
    for (int c = 0; c < 6; ++c) EXPECT_EQ(bh[c], bd[c]) << "coarse row " << I;
  }
  for (Index i = 0; i < nf; ++i) {
    double xh[3] = {1, 2, 3}, xd[3] = {1, 2, 3};
    loom::block_row_prolong36_add(prp.data(), pcol.data(), ph.data(), xc.data(), i, xh);
    loom::block_row_prolong36_add(prp.data(), pcol.data(), pd.data(), xc.data(), i, xd);
    for (int a = 0; a < 3; ++a) EXPECT_EQ(xh[a], xd[a]) << "fine row " << i;
  }
}

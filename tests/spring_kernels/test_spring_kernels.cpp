// The explicit steps' vector kernels (issue 16) against their portable loops.
#include <gtest/gtest.h>

#include <cmath>
#include <cstring>
#include <random>
#include <vector>

#include "loom/spring_groups.hpp"

namespace {

using loom::Index;

bool same_bits(double a, double b) { return std::memcmp(&a, &b, sizeof(double)) == 0; }

// A segment's force vectors (3 x Bk, uniform in [-1, 1]) with a -0 and a +0 among them
// (positions depend on `shift`, so that two arrays differ), for lengths that reach them.
std::vector<double> spring_vectors(std::mt19937& rng, loom::Index Bk, loom::Index len, int shift = 0) {
  std::uniform_real_distribution<double> U(-1.0, 1.0);
  std::vector<double> F(3 * Bk);
  for (double& f : F) f = U(rng);
  if (len > 2) F[1 + shift] = shift ? 0.0 : -0.0;
  if (len > 3) F[Bk + 2 - shift] = shift ? -0.0 : 0.0;
  return F;
}

// Three window arrays of n slots each (x, y, z sums; some +0), the slots before a and from
// `slots` on holding a -0 sentinel: -0 plus +0 reads +0, so a touched guard slot shows.
std::vector<double> guarded_window(std::mt19937& rng, loom::Index a, loom::Index slots, loom::Index n) {
  std::uniform_real_distribution<double> U(-1.0, 1.0);
  std::vector<double> A(3 * n);
  for (loom::Index q = 0; q < 3 * n; ++q) A[q] = (q % 5 == 0) ? 0.0 : U(rng);
  for (int e = 0; e < 3; ++e) {
    for (loom::Index q = 0; q < a; ++q) A[e * n + q] = -0.0;
    for (loom::Index q = slots; q < n; ++q) A[e * n + q] = -0.0;
  }
  return A;
}

// window_segment_scatter (AVX2 for stride 2 in double) against its
// portable loop, window_segment_scatter_from(0, ...), bit for bit: the vector kernel adds +0 to
// the odd slots, which leaves every value that is not -0 unchanged, and window sums are never -0
// (they start at +0; see spring_groups.hpp). Every length 0..41 (the vector part and every tail),
// lower and upper ranges overlapping (off 1, 2, 3) or not (off 64, 129), odd and even starts;
// the slots around the two ranges hold a sentinel and must keep it bit for bit (the kernel
// touches only the segment's own slots).
template <int Step>
void check_scatter() {
  constexpr Index Bk = 64;
  std::mt19937 rng(7);
  int cases = 0;
  for (Index len = 0; len <= 41; ++len)
    for (Index off : {1, 2, 3, 64, 129})
      for (Index a : {0, 1, 5}) {
        const Index slots = a + off + Step * (len > 0 ? len - 1 : 0) + 1;
        const Index n = slots + 16;   // a guard band after the last slot
        const std::vector<double> F = spring_vectors(rng, Bk, len);
        std::vector<double> A = guarded_window(rng, a, slots, n);
        std::vector<double> B = A;
        loom::window_segment_scatter<double, Step, Bk>(len, a, off, A.data(), A.data() + n, A.data() + 2 * n, F.data());
        loom::window_segment_scatter_from<double, Step, Bk>(0, len, a, off, B.data(), B.data() + n, B.data() + 2 * n,
                                                              F.data());
        for (Index q = 0; q < 3 * n; ++q)
          ASSERT_TRUE(same_bits(A[q], B[q])) << "step " << Step << " len " << len << " off " << off << " a " << a
                                             << " slot " << q << ": " << A[q] << " vs " << B[q];
        ++cases;
      }
  EXPECT_EQ(cases, 42 * 5 * 3);
}

TEST(SpringKernels, WindowScatterStride2EqualsPortableLoopBitwise) {
#if defined(__AVX2__)
  check_scatter<2>();
#else
  GTEST_SKIP() << "this build has no AVX2: window_segment_scatter is the portable loop itself";
#endif
}

// window_segment_scatter_overlap (one pass over a unit-stride segment whose ranges overlap,
// issue 16) against the two-pass portable loop, bit for bit: every length 2..41, every overlapping
// offset 1..len - 1, odd and even starts, -0 and +0 among the values; the guard slots around the
// segment keep their sentinel.
TEST(SpringKernels, WindowScatterOverlapEqualsTwoPassesBitwise) {
  constexpr Index Bk = 64;
  std::mt19937 rng(9);
  std::uniform_real_distribution<double> U(-1.0, 1.0);
  int cases = 0;
  for (Index len = 2; len <= 41; ++len)
    for (Index off = 1; off < len; ++off)
      for (Index a : {0, 1, 5}) {
        const Index slots = a + off + len;
        const Index n = slots + 16;
        std::vector<double> F(3 * Bk);
        for (double& f : F) f = U(rng);
        F[1] = -0.0;
        F[Bk] = 0.0;
        std::vector<double> A(3 * n);
        for (Index q = 0; q < 3 * n; ++q) A[q] = (q % 5 == 0) ? 0.0 : U(rng);
        for (int e = 0; e < 3; ++e) {
          for (Index q = 0; q < a; ++q) A[e * n + q] = -0.0;
          for (Index q = slots; q < n; ++q) A[e * n + q] = -0.0;
        }
        std::vector<double> B = A;
        loom::window_segment_scatter_overlap<double, Bk>(len, a, off, A.data(), A.data() + n, A.data() + 2 * n,
                                                         F.data());
        loom::window_segment_scatter_from<double, 1, Bk>(0, len, a, off, B.data(), B.data() + n, B.data() + 2 * n,
                                                         F.data());
        for (Index q = 0; q < 3 * n; ++q)
          ASSERT_TRUE(same_bits(A[q], B[q])) << "len " << len << " off " << off << " a " << a << " slot " << q << ": "
                                             << A[q] << " vs " << B[q];
        ++cases;
      }
  EXPECT_EQ(cases, 3 * (40 * 41 / 2));
}

}  // namespace

#include "ho_window.hpp"
#include "loom/kernels/ho.hpp"

namespace {

#if defined(LOOM_HO_FINALISE_AVX2)
// ho_finalise_block_avx2 against kernels::ho_finalise_vertex (velocity variant) on the same
// window sums, bit for bit: both perform v = v + fma(f, h g, w s), x = fma(h, v, x) with the
// same operands. Random states and sums, pinned vertices (w = 0) and deferred vertices (left
// unchanged) mixed in, every start offset within a group of 4 and every tail length.
TEST(SpringKernels, HoBlockFinalisationEqualsScalarBitwise) {
  std::mt19937 rng(11);
  std::uniform_real_distribution<double> U(-1.0, 1.0);
  const Index n = 80, ws = 3;
  int vectorised = 0;
  for (Index from = ws; from < ws + 4; ++from)
    for (Index to = from; to <= n; to += 5) {
      std::vector<double> x(3 * n), v(3 * n), w(n), win(9 * n);
      std::vector<std::uint8_t> deferred(n + 4, 0);
      for (double& e : x) e = U(rng);
      for (double& e : v) e = U(rng);
      for (double& e : win) e = 1e3 * U(rng);
      for (Index q = 0; q < n; ++q) {
        w[q] = (q % 7 == 3) ? 0.0 : 500.0 * (1.5 + U(rng));   // some pins
        deferred[q] = (q % 11 == 5) ? 1 : 0;
      }
      double* A[9];
      for (int e = 0; e < 9; ++e) A[e] = win.data() + e * n;
      for (Index q = 0; q < n; ++q) {   // the window holds the current x and v at slot q - ws
        if (q < ws) continue;
        for (int e = 0; e < 3; ++e) {
          A[e][q - ws] = x[3 * q + e];
          A[3 + e][q - ws] = v[3 * q + e];
        }
      }
      const double h = 1.3e-3, hg[3] = {0.1 * h, -9.81 * h, 0.02 * h}, gg[3] = {0, 0, 0};
      std::vector<double> xr = x, vr = v;
      for (Index q = from; q < to; ++q) {
        if (deferred[q]) continue;
        const Index l = q - ws;
        const double dq[3] = {w[q] * A[6][l], w[q] * A[7][l], w[q] * A[8][l]};
        const double pq[3] = {0, 0, 0};
        loom::kernels::ho_finalise_vertex<double, false>(xr.data() + 3 * q, vr.data() + 3 * q, dq, pq, w[q], h, hg, gg);
      }
      const Index end = loom::ho_finalise_block_avx2(from, to, ws, A[0], A[1], A[2], A[3], A[4], A[5], A[6], A[7],
                                                     A[8], w.data(), deferred.data(), x.data(), v.data(), h, hg);
      ASSERT_EQ(end, from + ((to - from) / 4) * 4);
      vectorised += static_cast<int>(end - from);
      for (Index q = end; q < to; ++q) {   // the tail is the caller's: the kernel leaves it untouched
        xr[3 * q] = x[3 * q], xr[3 * q + 1] = x[3 * q + 1], xr[3 * q + 2] = x[3 * q + 2];
        vr[3 * q] = v[3 * q], vr[3 * q + 1] = v[3 * q + 1], vr[3 * q + 2] = v[3 * q + 2];
      }
      for (Index q = 0; q < 3 * n; ++q) {
        ASSERT_TRUE(same_bits(x[q], xr[q])) << "from " << from << " to " << to << " x entry " << q;
        ASSERT_TRUE(same_bits(v[q], vr[q])) << "from " << from << " to " << to << " v entry " << q;
      }
    }
  EXPECT_GT(vectorised, 1000);
}
#endif

}  // namespace

#include <cfloat>
#include <cstdio>
#include <limits>

#include "loom/kernels/sqrt_recip_avx512.hpp"

namespace {

#if defined(__AVX512F__)
// loom::kernels::sqrt_recip_cr_pd against std::sqrt and the IEEE division (both correctly rounded), bit
// for bit, and against long double: random squared lengths over the whole range and over the
// steps' (1e-12 to 1e2), roots and reciprocals constructed to lie within about 2^-60 ulp of a
// rounding midpoint, powers of two and their neighbours, mantissas of all ones, the range's ends;
// lanes below kSqrtRecipMin (0, the min guard DBL_MIN, denormals) and above kSqrtRecipMax must
// come back in the mask. The largest error against long double is printed (it must be at most
// 0.5 ulp: correctly rounded).
void check_sqrt_recip_cr() {
  static_assert(std::numeric_limits<long double>::digits >= 64, "needs x87 long double");
  std::mt19937_64 rng(5);
  std::vector<double> in;
  auto mant = [&]() { return 1.0 + static_cast<double>(rng() >> 12) * 0x1p-52; };   // [1, 2)
  std::uniform_int_distribution<int> ex(-950, 950);
  for (int q = 0; q < 400000; ++q) in.push_back(std::ldexp(mant(), ex(rng)));
  std::uniform_real_distribution<double> lg(-12.0, 2.0);
  for (int q = 0; q < 400000; ++q) in.push_back(std::pow(10.0, lg(rng)));
  // a whose root lies next to a midpoint m = s + u/2: a = RN(m^2) and its neighbours
  for (int q = 0; q < 100000; ++q) {
    const double s = std::ldexp(mant(), ex(rng) / 2);
    const long double m = static_cast<long double>(s) + static_cast<long double>(std::nextafter(s, 1e300) - s) / 2;
    const double a = static_cast<double>(m * m);
    for (int k = -2; k <= 2; ++k) {
      double b = a;
      for (int t = 0; t < std::abs(k); ++t) b = std::nextafter(b, k > 0 ? 1e300 : 0.0);
      in.push_back(b);
    }
  }
  // s whose reciprocal lies next to a midpoint: s = RN(1 / (q + u/2)) and neighbours, a = s^2
  // (sqrt(RN(s^2)) = s in binary64)
  for (int q = 0; q < 100000; ++q) {
    const double r = std::ldexp(mant(), ex(rng) / 2);
    const long double m = static_cast<long double>(r) + static_cast<long double>(std::nextafter(r, 1e300) - r) / 2;
    const double s0 = static_cast<double>(1.0L / m);
    for (int k = -2; k <= 2; ++k) {
      double s = s0;
      for (int t = 0; t < std::abs(k); ++t) s = std::nextafter(s, k > 0 ? 1e300 : 0.0);
      in.push_back(s * s);
    }
  }
  for (int e = -940; e <= 940; e += 7)
    for (double base : {1.0, 2.0 - 0x1p-52, 4.0 - 0x1p-51}) {
      const double p = std::ldexp(base, e);
      in.push_back(p);
      in.push_back(std::nextafter(p, 0.0));
      in.push_back(std::nextafter(p, 1e300));
      in.push_back(std::nextafter(std::nextafter(p, 0.0), 0.0));
    }
  in.push_back(loom::kernels::kSqrtRecipMin);
  in.push_back(loom::kernels::kSqrtRecipMax);
  const std::vector<double> outside{0.0, DBL_MIN, 1e-310, std::nextafter(loom::kernels::kSqrtRecipMin, 0.0),
                                    std::nextafter(loom::kernels::kSqrtRecipMax, 1e308), 1e300,
                                    std::numeric_limits<double>::infinity(), 1e-320};
  while (in.size() % 8 != 0) in.push_back(1.0);
  long double worst_s = 0, worst_q = 0;
  std::size_t checked = 0;
  for (std::size_t b = 0; b < in.size(); b += 8) {
    alignas(64) double S[8], Q[8];
    __m512d s, q;
    const __mmask8 left = loom::kernels::sqrt_recip_cr_pd(_mm512_loadu_pd(in.data() + b), s, q);
    ASSERT_EQ(left, 0) << "block " << b;
    _mm512_store_pd(S, s);
    _mm512_store_pd(Q, q);
    for (int l = 0; l < 8; ++l) {
      const double a = in[b + l];
      const double rs = std::sqrt(a), rq = 1.0 / rs;
      ASSERT_TRUE(same_bits(S[l], rs)) << "sqrt(" << a << "): " << S[l] << " vs " << rs;
      ASSERT_TRUE(same_bits(Q[l], rq)) << "1/sqrt(" << a << "): " << Q[l] << " vs " << rq;
      const long double es = std::sqrt(static_cast<long double>(a));
      const long double eq = 1.0L / static_cast<long double>(S[l]);
      const long double us = std::nextafter(S[l], 1e308) - S[l], uq = std::nextafter(Q[l], 1e308) - Q[l];
      worst_s = std::max(worst_s, std::abs(static_cast<long double>(S[l]) - es) / us);
      worst_q = std::max(worst_q, std::abs(static_cast<long double>(Q[l]) - eq) / uq);
      ++checked;
    }
  }
  // long double carries 11 more bits: an error up to 0.5 ulp + 2^-11 ulp still means correctly rounded
  EXPECT_LE(worst_s, 0.5L + 0x1p-10L);
  EXPECT_LE(worst_q, 0.5L + 0x1p-10L);
  std::printf("sqrt_recip_cr_pd: %zu inputs, max error %.6Lf ulp (sqrt), %.6Lf ulp (reciprocal)\n", checked, worst_s,
              worst_q);
  for (std::size_t b = 0; b < outside.size(); b += 8) {
    __m512d s, q;
    const __mmask8 left = loom::kernels::sqrt_recip_cr_pd(_mm512_loadu_pd(outside.data() + b), s, q);
    EXPECT_EQ(left, 0xFF);
  }
}
#endif

TEST(SpringKernels, SqrtRecipAvx512IsCorrectlyRounded) {
#if defined(__AVX512F__)
  check_sqrt_recip_cr();
#else
  GTEST_SKIP() << "this build has no AVX-512F: kernels::sqrt_recip_cr_pd is not compiled";
#endif
}

}  // namespace

#include <map>
#include <utility>

namespace {

// Per slot, the sequence of additions (spring begin + r, sign) that a sweep over segs in this
// order performs (lower endpoint +, upper endpoint -; each segment's lower pass, then its upper).
std::map<Index, std::vector<std::pair<Index, int>>> slot_additions(const std::vector<loom::SpringSegment>& segs) {
  std::map<Index, std::vector<std::pair<Index, int>>> out;
  for (const auto& G : segs) {
    for (Index r = 0; r < G.len; ++r) out[G.i0 + G.step * r].push_back({G.begin + r, +1});
    for (Index r = 0; r < G.len; ++r) out[G.i0 + G.step * r + G.off].push_back({G.begin + r, -1});
  }
  return out;
}

void expect_valid_pairing(const std::vector<loom::SpringSegment>& before, const std::vector<loom::SpringSegment>& after) {
  ASSERT_EQ(before.size(), after.size());
  // the same segments, and every slot gets its additions in the same order
  EXPECT_EQ(slot_additions(before), slot_additions(after));
  for (std::size_t t = 0; t < after.size(); ++t) {
    if (!after[t].twin) continue;
    ASSERT_LT(t + 1, after.size());
    const auto &a = after[t], &b = after[t + 1];
    EXPECT_EQ(b.twin, 0);
    EXPECT_EQ(a.i0, b.i0);
    EXPECT_EQ(a.len, b.len);
    EXPECT_EQ(a.off, b.off);
    EXPECT_EQ(a.step, b.step);
    EXPECT_NE(a.begin, b.begin);
  }
}


// window_segment_scatter_twin (a twin pair's two scatters in one pass, issue 16) against the two
// portable two-pass scatters it replaces (F's, then F2's), bit for bit: stride 1 and 2, every
// length 1..41, offsets with the upper range overlapping the lower one (k < len), touching it
// and beyond (k >= len), odd offsets with stride 2 (disjoint slots), odd and even starts, -0 and
// +0 among the values; the slots around the pair's range keep their -0 sentinel (a vector loop
// that ran past the range would add +0 to them and show).
template <int Step>
void check_twin_scatter() {
  constexpr Index Bk = 64;
  std::mt19937 rng(11);
  int cases = 0;
  for (Index len = 1; len <= 41; ++len)
    for (Index off : {1, 2, 3, 4, 6, 7, 10, 19, 64, 82, 129})
      for (Index a : {0, 1, 5}) {
        const Index slots = a + off + Step * (len - 1) + 1;
        const Index n = slots + 16;
        const std::vector<double> F = spring_vectors(rng, Bk, len), F2 = spring_vectors(rng, Bk, len, 1);
        std::vector<double> A = guarded_window(rng, a, slots, n);
        std::vector<double> B = A;
        loom::window_segment_scatter_twin<double, Step, Bk>(len, a, off, A.data(), A.data() + n, A.data() + 2 * n,
                                                             F.data(), F2.data());
        loom::window_segment_scatter_from<double, Step, Bk>(0, len, a, off, B.data(), B.data() + n, B.data() + 2 * n,
                                                              F.data());
        loom::window_segment_scatter_from<double, Step, Bk>(0, len, a, off, B.data(), B.data() + n, B.data() + 2 * n,
                                                              F2.data());
        for (Index q = 0; q < 3 * n; ++q)
          ASSERT_TRUE(same_bits(A[q], B[q])) << "step " << Step << " len " << len << " off " << off << " a " << a
                                             << " slot " << q << ": " << A[q] << " vs " << B[q];
        ++cases;
      }
  EXPECT_EQ(cases, 41 * 11 * 3);
}

TEST(SpringKernels, WindowScatterTwinEqualsTwoScattersBitwise) {
  check_twin_scatter<1>();
  check_twin_scatter<2>();
}

}  // namespace

// pair_twin_segments (issue 16) makes segments over the same endpoints neighbours only where no
// slot's order of additions changes: a hand-built block (a move past a disjoint segment, a move
// blocked by a segment that shares slots, an adjacent pair), then random blocks checked against
// the per-slot addition sequences of the original order.
TEST(SpringKernels, TwinPairingKeepsEverySlotsOrder) {
  using loom::SpringSegment;
  // begin, len, i0, off, step
  const std::vector<SpringSegment> block{
      {0, 10, 0, 1, 1},    {10, 10, 100, 1, 1}, {20, 10, 0, 1, 1},  {30, 10, 100, 1, 1}, {40, 5, 200, 2, 2},
      {45, 5, 201, 3, 1},  {50, 5, 200, 2, 2},  {55, 3, 300, 5, 1}, {58, 3, 300, 5, 1}};
  std::vector<SpringSegment> s = block;
  loom::pair_twin_segments(s, 0);
  expect_valid_pairing(block, s);
  const Index order[] = {0, 20, 10, 30, 40, 45, 50, 55, 58};   // by begin
  const Index twin[] = {1, 0, 1, 0, 0, 0, 0, 1, 0};
  for (std::size_t t = 0; t < s.size(); ++t) {
    EXPECT_EQ(s[t].begin, order[t]) << t;
    EXPECT_EQ(s[t].twin, twin[t]) << t;
  }
  // only [from, end) is touched
  std::vector<SpringSegment> s2 = block;
  loom::pair_twin_segments(s2, 3);
  EXPECT_EQ(s2[0].twin, 0);
  EXPECT_EQ(s2[2].begin, 20);

  std::mt19937 rng(7);
  int paired = 0, moved = 0;
  for (int trial = 0; trial < 300; ++trial) {
    std::vector<SpringSegment> b;
    Index begin = 0;
    const int n = 2 + static_cast<int>(rng() % 12);
    for (int k = 0; k < n; ++k) {
      SpringSegment G{begin, 1 + static_cast<Index>(rng() % 6), static_cast<Index>(rng() % 40),
                      1 + static_cast<Index>(rng() % 8), 1 + static_cast<Index>(rng() % 2)};
      if (k > 0 && rng() % 2 == 0) {   // a copy of an earlier segment's endpoints
        const SpringSegment& e = b[rng() % b.size()];
        G = {begin, e.len, e.i0, e.off, e.step};
      }
      begin += G.len;
      b.push_back(G);
    }
    std::vector<SpringSegment> p = b;
    loom::pair_twin_segments(p, 0);
    expect_valid_pairing(b, p);
    for (std::size_t t = 0; t < p.size(); ++t) {
      paired += p[t].twin ? 1 : 0;
      moved += p[t].begin != b[t].begin ? 1 : 0;
    }
  }
  EXPECT_GT(paired, 100);   // the random blocks did exercise pairing and moves
  EXPECT_GT(moved, 50);
}

// Correctly rounded square root and reciprocal of 8 doubles without the divider (issue 16,
// candidate 2 of docs/benchmarks/ho.md): s = RN(sqrt(a)) and q = RN(1 / s), the values that
// vsqrtpd and vdivpd give, from vrsqrt14pd, FMAs and a final exact rounding test. AVX-512F only;
// a building block, not used by the steps (see ho.md for its cost against the divider).
//
// Why the result is correctly rounded (binary64, round to nearest, no underflow or overflow in
// the range below). Let u = next(s) - s and u- = s - prev(s) (the spacing above and below s;
// u- = u / 2 when s is a power of two).
//  1. y1 (one Newton step from vrsqrt14pd, relative error < 2^-14) approximates 1/sqrt(a) to
//     1.5 2^-28 + O(2^-53); s0 = RN(a y1), r = a - s0^2 (one FMA), s = RN(s0 + r y1 / 2) differs
//     from sqrt(a) by the final rounding plus about 1.5 eps^2 (eps ~ 2^-27.4) relative, under
//     2^-54 sqrt(a) < ulp/2: less than one spacing in all, so the correctly rounded root is s,
//     next(s) or prev(s).
//  2. sqrt(a) > s + u/2 iff a - s^2 > s u + u^2/4 iff a - s^2 > s u (a and s^2 are multiples of
//     u^2 here, so is s u). r = RN(a - s^2) by one FMA; RN is monotone and s u is a double, so
//     RN(r) > s u agrees with r > s u unless RN(r) = s u with r inexact; r is inexact only when
//     |r| >= 2^53 u^2 > s u (s < 2^53 u), and then RN(r) >= 2^53 u^2 > s u as well. Likewise
//     sqrt(a) < s - u-/2 iff a - s^2 <= -s u- (multiples of u-^2). Ties cannot occur.
//  3. q1 = RN(y1 + y1 (1 - s y1)) is within the final rounding plus about 2^-54 relative of
//     1/s, so again the correctly rounded reciprocal is q1 or a neighbour. 1/s > q + u/2 iff
//     1 - s q > s u / 2 (a double: s times a power of two), 1 - s q is a multiple of ulp(s) u
//     and inexact only when it is at least 2^53 times that, which exceeds s u / 2: the same
//     argument as in 2. 1/s is never a midpoint (s is not a power of two, or 1/s is exact).
// tests/spring_kernels (SpringKernels.SqrtRecipAvx512IsCorrectlyRounded) checks it bit for bit
// against std::sqrt and the division on random and constructed hard inputs (roots and
// reciprocals within 2^-60 ulp of a midpoint, powers of two and their neighbours, mantissas of
// all ones, the range's ends) and measures the error against long double.
#pragma once

#if defined(__AVX512F__)
#include <immintrin.h>

namespace loom::kernels {

/// Lanes with a in [kSqrtRecipMin, kSqrtRecipMax] are computed; the others (0, the min guard,
/// denormals, huge values, inf, NaN) are returned in the mask for the caller's exact fallback.
constexpr double kSqrtRecipMin = 0x1p-960;
constexpr double kSqrtRecipMax = 0x1p+960;

/// s = RN(sqrt(a)), q = RN(1 / s) for the lanes in range; returns the lanes NOT computed.
inline __mmask8 sqrt_recip_cr_pd(__m512d a, __m512d& s_out, __m512d& q_out) {
  const __m512d one = _mm512_set1_pd(1.0), half = _mm512_set1_pd(0.5);
  const __m512i ione = _mm512_set1_epi64(1);
  const __mmask8 ok = _mm512_cmp_pd_mask(a, _mm512_set1_pd(kSqrtRecipMin), _CMP_GE_OQ) &
                      _mm512_cmp_pd_mask(a, _mm512_set1_pd(kSqrtRecipMax), _CMP_LE_OQ);
  a = _mm512_mask_blend_pd(ok, one, a);   // a harmless value in the lanes left to the caller
  const auto next = [&](__m512d x) { return _mm512_castsi512_pd(_mm512_add_epi64(_mm512_castpd_si512(x), ione)); };
  const auto prev = [&](__m512d x) { return _mm512_castsi512_pd(_mm512_sub_epi64(_mm512_castpd_si512(x), ione)); };
  // 1/sqrt(a) to about 2^-27
  const __m512d y0 = _mm512_rsqrt14_pd(a);
  const __m512d t0 = _mm512_mul_pd(a, y0);
  const __m512d e0 = _mm512_fnmadd_pd(t0, y0, one);
  const __m512d y1 = _mm512_fmadd_pd(_mm512_mul_pd(half, y0), e0, y0);
  // sqrt(a) to within 0.75 of the spacing
  const __m512d s0 = _mm512_mul_pd(a, y1);
  const __m512d r0 = _mm512_fnmadd_pd(s0, s0, a);
  __m512d s = _mm512_fmadd_pd(r0, _mm512_mul_pd(half, y1), s0);
  {  // the exact rounding test (2.)
    const __m512d r = _mm512_fnmadd_pd(s, s, a);
    const __m512d sn = next(s), sp = prev(s);
    const __mmask8 up = _mm512_cmp_pd_mask(r, _mm512_mul_pd(s, _mm512_sub_pd(sn, s)), _CMP_GT_OQ);
    const __mmask8 dn = _mm512_cmp_pd_mask(r, _mm512_mul_pd(s, _mm512_sub_pd(sp, s)), _CMP_LE_OQ);
    s = _mm512_mask_mov_pd(s, up, sn);
    s = _mm512_mask_mov_pd(s, dn, sp);
  }
  // 1/s: one Newton step from y1, then the test (3.)
  const __m512d e1 = _mm512_fnmadd_pd(s, y1, one);
  __m512d q = _mm512_fmadd_pd(y1, e1, y1);
  {
    const __m512d r = _mm512_fnmadd_pd(s, q, one);
    const __m512d hs = _mm512_mul_pd(half, s);
    const __m512d qn = next(q), qp = prev(q);
    const __mmask8 up = _mm512_cmp_pd_mask(r, _mm512_mul_pd(hs, _mm512_sub_pd(qn, q)), _CMP_GT_OQ);
    const __mmask8 dn = _mm512_cmp_pd_mask(r, _mm512_mul_pd(hs, _mm512_sub_pd(qp, q)), _CMP_LT_OQ);
    q = _mm512_mask_mov_pd(q, up, qn);
    q = _mm512_mask_mov_pd(q, dn, qp);
  }
  s_out = s;
  q_out = q;
  return static_cast<__mmask8>(~ok);
}

}  // namespace loom::kernels
#endif

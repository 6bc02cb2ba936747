// IEEE 754 binary16 ("half") storage for values that the V-cycle only reads (sa_amg's level-0
// transfer operators P and R, NUMERICS.md 3.6): 2 bytes per value instead of 4, widened to
// double on load (every sum stays double). The conversions round to nearest, ties to even;
// with F16C (x86) the hardware instructions do it, elsewhere the portable code below, which
// gives the same bits (tests/sa_amg/test_float_spmv.cpp checks both ways on every finite half).
#pragma once

#if defined(__F16C__)
#include <immintrin.h>
#endif

#include <cstdint>
#include <cstring>

namespace loom {

struct Half {
  std::uint16_t bits = 0;
};
static_assert(sizeof(Half) == 2);

/// The float equal to h (exact: every half is a float).
inline float half_to_float_portable(Half h) {
  const std::uint32_t sign = static_cast<std::uint32_t>(h.bits & 0x8000u) << 16;
  const std::uint32_t e = (h.bits >> 10) & 0x1fu, m = h.bits & 0x3ffu;
  std::uint32_t f;
  if (e == 0x1f) {
    f = sign | 0x7f800000u | (m << 13);  // inf, nan
  } else if (e != 0) {
    f = sign | ((e + 112u) << 23) | (m << 13);  // normal: exponent bias 15 -> 127
  } else if (m == 0) {
    f = sign;  // +-0
  } else {  // subnormal: m * 2^-24, normalised
    int shift = 0;
    std::uint32_t mm = m;
    while (!(mm & 0x400u)) {
      mm <<= 1;
      ++shift;
    }
    f = sign | ((113u - static_cast<std::uint32_t>(shift)) << 23) | ((mm & 0x3ffu) << 13);
  }
  float out;
  std::memcpy(&out, &f, 4);
  return out;
}

/// x rounded to the nearest half (ties to even); overflow gives +-inf, nan stays nan.
inline Half float_to_half_portable(float x) {
  std::uint32_t f;
  std::memcpy(&f, &x, 4);
  const std::uint16_t sign = static_cast<std::uint16_t>((f >> 16) & 0x8000u);
  const std::uint32_t a = f & 0x7fffffffu;
  if (a >= 0x7f800000u) return Half{static_cast<std::uint16_t>(sign | 0x7c00u | (a > 0x7f800000u ? 0x200u : 0u))};
  if (a >= 0x477ff000u) return Half{static_cast<std::uint16_t>(sign | 0x7c00u)};  // rounds to >= 65520: inf
  if (a >= 0x38800000u) {  // normal half (|x| >= 2^-14)
    const std::uint32_t mant = a & 0x7fffffu;
    std::uint32_t h = ((((a >> 23) - 112u) << 10) | (mant >> 13));
    const std::uint32_t rest = mant & 0x1fffu;
    if (rest > 0x1000u || (rest == 0x1000u && (h & 1u))) ++h;  // may carry into the exponent: correct
    return Half{static_cast<std::uint16_t>(sign | h)};
  }
  if (a < 0x33000000u) return Half{sign};  // below half the smallest subnormal (2^-25): +-0
  // subnormal half: value = m * 2^-24, m = round(|x| * 2^24)
  const std::uint32_t e = a >> 23;                    // 102..112
  const std::uint32_t mant = (a & 0x7fffffu) | 0x800000u;  // 24-bit significand
  const std::uint32_t shift = 126u - e;               // |x| * 2^24 = mant * 2^(e - 127 - 23 + 24)
  std::uint32_t h = mant >> shift;
  const std::uint32_t rest = mant & ((1u << shift) - 1u), halfway = 1u << (shift - 1u);
  if (rest > halfway || (rest == halfway && (h & 1u))) ++h;
  return Half{static_cast<std::uint16_t>(sign | h)};
}

inline float half_to_float(Half h) {
#if defined(__F16C__)
  return _cvtsh_ss(h.bits);
#else
  return half_to_float_portable(h);
#endif
}

inline Half float_to_half(float x) {
#if defined(__F16C__)
  return Half{static_cast<std::uint16_t>(_cvtss_sh(x, _MM_FROUND_TO_NEAREST_INT))};
#else
  return float_to_half_portable(x);
#endif
}

/// A stored value as double (double, float or half storage).
inline double widen(double v) { return v; }
inline double widen(float v) { return v; }
inline double widen(Half v) { return half_to_float(v); }

}  // namespace loom

// Which OpenBLAS kernels CHOLMOD and PETSc run on (header-only, no static state, so that it can
// run before any library constructor; see framework/src/blas_kernels_preinit.cpp).
//
// OpenBLAS chooses its kernels from the CPU model when it is loaded. A CPU newer than its table
// gets the generic SSE3 kernels ("Prescott"): Debian 12's OpenBLAS 0.3.21 does not know the
// Intel Xeon of this project's machine (family 6, model 207), and CHOLMOD's factorisation of the
// 256^2 wool cloth took 4.8-5.5 s there against 2.1-2.2 s with its AVX-512 kernels (docs/plugins/
// solvers.md). So, unless the user has set OPENBLAS_CORETYPE, Loom names the kernel set from the
// instructions the CPU has, before it loads a plugin: AVX-512 F, DQ, BW, VL and CD: "SkylakeX";
// AVX2 and FMA: "Haswell"; otherwise nothing (OpenBLAS's own choice). On a CPU that OpenBLAS
// knows this names the set it would choose or one of the same width; the user's variable wins.
#pragma once

#include <cstdlib>

namespace loom {

/// The kernel set for this CPU by the rule above ("SkylakeX", "Haswell"), or nullptr.
inline const char* openblas_kernels_for_cpu() {
#if defined(__x86_64__) && (defined(__GNUC__) || defined(__clang__))
  __builtin_cpu_init();
  if (__builtin_cpu_supports("avx512f") && __builtin_cpu_supports("avx512dq") && __builtin_cpu_supports("avx512bw") &&
      __builtin_cpu_supports("avx512vl") && __builtin_cpu_supports("avx512cd"))
    return "SkylakeX";
  if (__builtin_cpu_supports("avx2") && __builtin_cpu_supports("fma")) return "Haswell";
#endif
  return nullptr;
}

/// Sets OPENBLAS_CORETYPE by that rule when it is unset; returns the name it set, or nullptr
/// when it set nothing. Call before OpenBLAS is loaded (it reads the variable once).
inline const char* choose_openblas_kernels() {
  if (std::getenv("OPENBLAS_CORETYPE") != nullptr) return nullptr;
  const char* name = openblas_kernels_for_cpu();
  if (name != nullptr && ::setenv("OPENBLAS_CORETYPE", name, 0) == 0) return name;
  return nullptr;
}

}  // namespace loom

// Linked into the benchmark executables (object library loom_blas_preinit): they link CHOLMOD
// and so OpenBLAS directly, which chooses its kernels in its constructor, before main(). So that
// they time the kernels `loom` chooses before it loads a plugin (loom/blas_kernels.hpp), a
// function in the executable's .preinit_array (run before every shared library's constructor)
// starts the program again with OPENBLAS_CORETYPE added to its environment when it is unset and
// the rule names a kernel set (setenv cannot be used there: the C library sets `environ` up only
// after the pre-initialisers). Once per process start; the user's variable is never replaced.
// Not in sanitizer builds, whose runtimes start there too (and whose timings mean nothing).
#include <unistd.h>

#include <cstdlib>
#include <cstring>

#include "loom/blas_kernels.hpp"

#if defined(__linux__) && defined(__ELF__) && !defined(__SANITIZE_ADDRESS__) && !defined(__SANITIZE_THREAD__)
#if defined(__has_feature)
#if __has_feature(address_sanitizer) || __has_feature(thread_sanitizer)
#define LOOM_NO_BLAS_PREINIT 1
#endif
#endif
#if !defined(LOOM_NO_BLAS_PREINIT)
namespace {
void loom_blas_preinit(int, char** argv, char** envp) {
  constexpr const char* kVar = "OPENBLAS_CORETYPE=";
  std::size_t n = 0;
  for (; envp != nullptr && envp[n] != nullptr; ++n)
    if (std::strncmp(envp[n], kVar, std::strlen(kVar)) == 0) return;   // the user's choice
  const char* name = loom::openblas_kernels_for_cpu();
  if (name == nullptr || argv == nullptr) return;
  static char entry[64];
  const std::size_t len = std::strlen(kVar), nl = std::strlen(name);
  if (len + nl + 1 > sizeof entry) return;
  std::memcpy(entry, kVar, len);
  std::memcpy(entry + len, name, nl + 1);
  char** env = static_cast<char**>(std::malloc((n + 2) * sizeof(char*)));
  if (env == nullptr) return;
  for (std::size_t k = 0; k < n; ++k) env[k] = envp[k];
  env[n] = entry;
  env[n + 1] = nullptr;
  ::execve("/proc/self/exe", argv, env);   // returns only on failure: go on with OpenBLAS's choice
  std::free(env);
}
}  // namespace
__attribute__((section(".preinit_array"), used)) void (*const loom_blas_preinit_entry)(int, char**, char**) =
    loom_blas_preinit;
#endif
#endif

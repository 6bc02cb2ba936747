/* A malloc counter to preload under bench_baraff_witkin (issue 15: is there allocation in a
 * step?). It counts calls to malloc (operator new ends there with glibc) and exports
 * loom_probe_mallocs(), which the benchmark looks up with dlsym and turns into the counter
 * `mallocs_per_step` over the timed steps. Not built by CMake (a probe, not a dependency):
 *
 *   gcc -O2 -shared -fPIC -o /tmp/malloc_count.so bench/baraff_witkin/malloc_count.c
 *   LD_PRELOAD=/tmp/malloc_count.so LOOM_BENCH_SIZES=64 OMP_NUM_THREADS=1 \
 *       build/bin/bench_baraff_witkin --benchmark_filter='bw_solver/wool64/' --benchmark_counters_tabular=true
 */
#include <stddef.h>

extern void* __libc_malloc(size_t);

static unsigned long long n_malloc = 0;

void* malloc(size_t s) {
  __atomic_add_fetch(&n_malloc, 1, __ATOMIC_RELAXED);
  return __libc_malloc(s);
}

unsigned long long loom_probe_mallocs(void) { return __atomic_load_n(&n_malloc, __ATOMIC_RELAXED); }

// HugePageAllocator: the allocator of sa_amg's large arrays (level matrices, their float and
// half copies, diagonal inverses, work vectors). An allocation of at least 2 MiB is a mapping
// of its own (Linux mmap; aligned_alloc elsewhere), aligned to 2 MiB and rounded up to whole
// 2 MiB pages; while a HugePageScope with `advise` true is
// active on the allocating thread, it is advised as transparent huge pages (Linux
// madvise(MADV_HUGEPAGE), which the default THP mode `madvise` needs) before its first
// touch, so the kernel backs it with 2 MiB pages. The V-cycle streams these arrays once or
// twice per PCG iteration (177 MB at 256^2); with 4 KiB pages every 4 KiB of the stream is a
// TLB miss and, in a virtual machine, a two-dimensional page walk (NUMERICS.md 3.6, "Huge
// pages"). Smaller allocations are plain operator new. The values and the arithmetic are the
// same either way: only where the pages come from changes.
#pragma once

#include <cstddef>
#include <cstdint>
#include <cstdlib>
#include <new>
#include <vector>

#if defined(__linux__)
#include <sys/mman.h>
#endif

namespace loom::amg {

inline constexpr std::size_t kHugePageBytes = std::size_t{2} << 20;

namespace detail {
inline bool& huge_page_advice() {
  thread_local bool advise = false;
  return advise;
}
}  // namespace detail

/// While alive, allocations of HugePageAllocator on this thread are advised (or not) as huge
/// pages; restores the previous setting on exit.
class HugePageScope {
 public:
  explicit HugePageScope(bool advise) : previous_(detail::huge_page_advice()) { detail::huge_page_advice() = advise; }
  ~HugePageScope() { detail::huge_page_advice() = previous_; }
  HugePageScope(const HugePageScope&) = delete;
  HugePageScope& operator=(const HugePageScope&) = delete;

 private:
  bool previous_;
};

template <class T>
struct HugePageAllocator {
  using value_type = T;
  HugePageAllocator() noexcept = default;
  template <class U>
  HugePageAllocator(const HugePageAllocator<U>&) noexcept {}

  /// Whether an allocation of n elements takes the 2 MiB-aligned path (decided by the size
  /// alone, so deallocate() frees it the way it was allocated).
  static bool large(std::size_t n) noexcept { return n >= kHugePageBytes / sizeof(T); }
  /// Bytes of a large allocation: whole 2 MiB pages.
  static std::size_t rounded(std::size_t n) noexcept {
    return (n * sizeof(T) + kHugePageBytes - 1) / kHugePageBytes * kHugePageBytes;
  }

  T* allocate(std::size_t n) {
    if (n > static_cast<std::size_t>(-1) / sizeof(T) - kHugePageBytes) throw std::bad_array_new_length();
    if (!large(n)) return static_cast<T*>(::operator new(n * sizeof(T), std::align_val_t{alignof(T)}));
    const std::size_t bytes = rounded(n);
#if defined(__linux__)
    // A mapping of its own (not malloc's heap, whose freed ranges keep an earlier block's
    // advice): map 2 MiB more, keep the aligned middle.
    void* raw = mmap(nullptr, bytes + kHugePageBytes, PROT_READ | PROT_WRITE, MAP_PRIVATE | MAP_ANONYMOUS, -1, 0);
    if (raw == MAP_FAILED) throw std::bad_alloc();
    const auto r = reinterpret_cast<std::uintptr_t>(raw);
    const std::uintptr_t a = (r + kHugePageBytes - 1) / kHugePageBytes * kHugePageBytes;
    if (a > r) munmap(raw, a - r);
    if (a - r < kHugePageBytes) munmap(reinterpret_cast<void*>(a + bytes), kHugePageBytes - (a - r));
    void* p = reinterpret_cast<void*>(a);
#if defined(MADV_HUGEPAGE)
    if (detail::huge_page_advice()) (void)madvise(p, bytes, MADV_HUGEPAGE);  // advice only: failure is harmless
#endif
#else
    void* p = std::aligned_alloc(kHugePageBytes, bytes);
    if (!p) throw std::bad_alloc();
#endif
    return static_cast<T*>(p);
  }
  void deallocate(T* p, std::size_t n) noexcept {
    if (!large(n)) {
      ::operator delete(p, std::align_val_t{alignof(T)});
      return;
    }
#if defined(__linux__)
    munmap(p, rounded(n));
#else
    std::free(p);
#endif
  }
  template <class U>
  bool operator==(const HugePageAllocator<U>&) const noexcept {
    return true;
  }
};

template <class T>
using HugeVector = std::vector<T, HugePageAllocator<T>>;

}  // namespace loom::amg

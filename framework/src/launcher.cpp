#include "loom/launcher.hpp"

#include <cerrno>
#include <cstdlib>
#include <initializer_list>

namespace loom {

int launcher_rank() {
  for (const char* var : {"OMPI_COMM_WORLD_RANK", "PMI_RANK", "PMIX_RANK", "MV2_COMM_WORLD_RANK", "SLURM_PROCID"}) {
    const char* v = std::getenv(var);
    if (!v || !*v) continue;
    char* end = nullptr;
    errno = 0;
    const long r = std::strtol(v, &end, 10);
    if (errno == 0 && *end == '\0' && r >= 0 && r <= 1 << 30) return static_cast<int>(r);
  }
  return 0;
}

bool is_output_rank() { return launcher_rank() == 0; }

}  // namespace loom

#!/usr/bin/env bash
# ThreadSanitizer run of the threaded plugins' tests (CMake preset "tsan", build-tsan/): clang
# with LLVM's OpenMP runtime and its Archer tool (OMP_TOOL_LIBRARIES, set by the test preset),
# which tells TSan about OpenMP's barriers and reductions. Debian's libomp itself is not built
# with TSan, so the preset sets ignore_noninstrumented_modules=1: reports inside libomp's own
# mutexes are not races of Loom's code; any report in Loom's code fails the run.
# Needs clang and libomp-14-dev (apt-get install clang libomp-14-dev). Not part of CI (about
# 40 min to build on 2 busy cores); see docs/ARCHITECTURE.md "Threads".
set -euo pipefail
root=$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)
cd "$root"
if [ ! -f build-tsan/build.ninja ]; then
  cmake --preset tsan >&2
fi
cmake --build --preset tsan >&2
ctest --preset tsan "$@"

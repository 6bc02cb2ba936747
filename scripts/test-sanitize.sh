#!/usr/bin/env bash
# Builds the framework, the CLI, their tests and the plugins those tests load with
# AddressSanitizer + UndefinedBehaviorSanitizer (CMake preset "sanitize", build-sanitize/) and
# runs the CLI, parser and framework tests under them. Any memory error or undefined behaviour
# fails the run. Extra arguments go to ctest. scripts/setup.sh must have installed the packages.
set -euo pipefail
root=$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)
cd "$root"
if [ ! -f build-sanitize/build.ninja ]; then
  cmake --preset sanitize >&2
fi
cmake --build --preset sanitize >&2
export OMPI_ALLOW_RUN_AS_ROOT=1 OMPI_ALLOW_RUN_AS_ROOT_CONFIRM=1
ctest --preset sanitize "$@"

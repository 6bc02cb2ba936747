#!/usr/bin/env bash
# Runs the whole Loom test suite: set-up (packages, build) then CTest.
# Extra arguments go to ctest, e.g. scripts/test.sh -R gnatv
set -euo pipefail
root=$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)
"$root/scripts/setup.sh"
cd "$root"
# MPI tests run as root in CI containers: OpenMPI refuses that without these.
export OMPI_ALLOW_RUN_AS_ROOT=1 OMPI_ALLOW_RUN_AS_ROOT_CONFIRM=1
export OMP_PROC_BIND=${OMP_PROC_BIND:-false}
ctest --preset default "$@"

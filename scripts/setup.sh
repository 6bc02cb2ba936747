#!/usr/bin/env bash
# Loom set-up: installs the Debian 12 packages Loom needs (only those missing) and builds
# Loom into build/ with the CMake preset "default". Safe to run again: it only does what is
# left to do. Used by ./loom (first use) and scripts/test.sh.
set -euo pipefail
root=$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)

packages=(build-essential cmake ninja-build pkg-config
          libeigen3-dev libyaml-cpp-dev libgtest-dev libgmock-dev libbenchmark-dev
          libsuitesparse-dev libopenblas-dev petsc-dev openmpi-bin python3-matplotlib python3-yaml
          libglm-dev libstb-dev libegl-dev libgles-dev libegl-mesa0 libgl1-mesa-dri libglfw3-dev)
missing=()
for p in "${packages[@]}"; do
  dpkg-query -W -f='${Status}' "$p" 2>/dev/null | grep -q "install ok installed" || missing+=("$p")
done
if ((${#missing[@]})); then
  echo "loom setup: installing Debian packages: ${missing[*]}" >&2
  sudo=""
  if [ "$(id -u)" -ne 0 ]; then sudo=sudo; fi
  $sudo apt-get update -qq
  DEBIAN_FRONTEND=noninteractive $sudo apt-get install -y -qq --no-install-recommends "${missing[@]}" >&2
fi

cd "$root"
if [ ! -f build/build.ninja ]; then
  echo "loom setup: configuring build/ (cmake --preset default)" >&2
  cmake --preset default >&2
fi
echo "loom setup: building (cmake --build --preset default)" >&2
cmake --build --preset default >&2

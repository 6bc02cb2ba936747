#!/usr/bin/env bash
# usage: run.sh BUILD_DIR TOY_SOURCE_DIR WORK_DIR
set -euo pipefail
build=$1; toy=$2; work=$3
rm -rf "$work"; mkdir -p "$work"
prefix=$work/prefix
cmake --install "$build" --prefix "$prefix" > "$work/install.log"
test -x "$prefix/bin/loom"
test -f "$prefix/include/loom/plugin.hpp"
test -f "$prefix/lib/cmake/Loom/LoomConfig.cmake"
cmake -S "$toy" -B "$work/toy-build" -G Ninja -DCMAKE_PREFIX_PATH="$prefix" -DCMAKE_BUILD_TYPE=Release > "$work/toy-configure.log"
cmake --build "$work/toy-build" > "$work/toy-build.log"
test -f "$work/toy-build/plugins/loom_material_toy_springless.so"
test -f "$work/toy-build/plugins/loom_integrator_toy_euler.so"
cat > "$work/scene.yaml" <<'YAML'
mesh: {grid: {nx: 3, ny: 3}}
material: {type: toy_springless, mass: 2.0}
integrator: {type: toy_euler, dt: 0.01, substeps: 2}
pins: [top_edge]
frames: 3
YAML
# The installed loom finds the toy plugins through LOOM_PLUGIN_PATH, and lists them.
LOOM_PLUGIN_PATH="$work/toy-build/plugins" "$prefix/bin/loom" plugins | tee "$work/plugins.txt"
grep -q "toy_springless" "$work/plugins.txt"
# Its declared keys: the framework's (type) and its own (mass, with default, range and units).
LOOM_PLUGIN_PATH="$work/toy-build/plugins" "$prefix/bin/loom" plugins --params toy_springless | tee "$work/params.txt"
grep -q "^mass  *number  *1  *> 0  *kg" "$work/params.txt"
grep -q "^type " "$work/params.txt"
# A typo in its key gets the declared key as a suggestion.
sed 's/mass: 2.0/mas: 2.0/' "$work/scene.yaml" > "$work/typo.yaml"
if LOOM_PLUGIN_PATH="$work/toy-build/plugins" "$prefix/bin/loom" validate "$work/typo.yaml" 2> "$work/typo.err"; then
  echo "a typo in the toy material's key was accepted"; exit 1
fi
grep -q "did you mean 'mass'" "$work/typo.err"
LOOM_PLUGIN_PATH="$work/toy-build/plugins" "$prefix/bin/loom" run "$work/scene.yaml" --out "$work/out" --quiet
test -f "$work/out/frame_00003.obj"
# free fall of the 3 free vertices after 6 forward-Euler steps of 0.01 s: y = -9.81 h^2 n(n-1)/2
python3 - "$work/out/frame_00003.obj" <<'PY'
import sys
ys = [float(l.split()[2]) for l in open(sys.argv[1]) if l.startswith('v ')]
expect = 0.0 - 9.81 * 0.01**2 * 6 * 5 / 2
assert abs(ys[0] - expect) < 1e-9, (ys[0], expect)
assert abs(ys[8] - 1.0) < 1e-15, ys[8]
print("toy plugin run ok:", ys[0], expect)
PY
echo "out-of-tree plugin test passed"

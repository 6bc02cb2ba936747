#!/usr/bin/env bash
# The GPU check of the CUDA backend (issue 17), as one script for a bare CUDA machine with
# a short time budget (about 15 minutes of device time in all, machine start included).
#
# Prepare on the build machine (no GPU needed; nvcc is slow, build only these targets):
#   cmake --preset default -DLOOM_GPU_TESTS=ON -DLOOM_BUILD_BENCH=ON
#   cmake --build build --target loom loom_backend_cuda loom_material_mass_spring loom_material_gnatv \
#       loom_integrator_harmonic_oscillation loom_integrator_rk4 loom_integrator_baraff_witkin \
#       loom_integrator_symplectic_euler loom_solver_eigen_pcg loom_solver_eigen_ldlt test_cuda_gpu \
#       test_cuda_pcg_gpu table1_gpu
#   bash tools/gpu-bundle.sh .gpu        (packs build/ into .gpu/; tools/README.md says where it comes from)
# On the GPU machine, from the repository root (the scenes, materials and data/ are read from it):
#   bash scripts/gpu-check.sh [BUNDLE=.gpu] [OUT=$OUT or gpu-results] [SECONDS_PER_SCENE=90] [TOTAL_SECONDS=480]
# TOTAL_SECONDS bounds the whole check: each part's timeout is cut to what is left, and scenes
# that no longer fit are listed as `no_time` (the device tool lends minutes, not hours).
# Order: the tests, then the benchmarks, then the scenes. To rerun a part on a short lease:
#   GPU_CHECK_PARTS="tests bench scenes" (default: all three), GPU_CHECK_SCENES='scenes/drape_*.yaml'
#   (default: scenes/*.yaml).
#
# Writes into OUT:
#   nvidia-smi.txt                the device
#   test_cuda_gpu.{txt,xml}       the `gpu` tests (CUDA against CPU: HO, RK4, symplectic Euler, Baraff-Witkin;
#                                 the material boundary, bending, colliders, device memory)
#   test_cuda_pcg_gpu.{txt,xml}   the `gpu` PCG test (CPU and CUDA filtered_pcg give the same iterates)
#   scenes.csv                    every shipped scene with backend: cuda (self_collision removed), one frame
#                                 of 20 steps, against backend: cpu: status, max |x_gpu - x_cpu| relative to
#                                 max |x_cpu| and to the largest displacement (agrees: <= 1e-10 of the
#                                 positions); Baraff-Witkin scenes with filtered_pcg at 1e-11 against
#                                 eigen_ldlt; scenes/<name>/ holds the logs
#   table1_gpu.{json,txt}         the GPU Table 1 benchmark (HO, RK4, symplectic Euler; double, float; copy bandwidth) and
#                                 the Baraff-Witkin wool steps
#   summary.txt                   one line per part with its exit status
# Exit status: 0 when the tests pass (not skipped) and every accepted scene agrees, else 1.
set -uo pipefail
bundle=${1:-.gpu}
out=${2:-${OUT:-gpu-results}}
per_scene=${3:-90}
total=${4:-480}
deadline=$(( $(date +%s) + total ))
left() { echo $(( deadline - $(date +%s) )); }
cap() { local l; l=$(left); [ "$l" -lt 1 ] && l=1; [ "$1" -lt "$l" ] && echo "$1" || echo "$l"; }  # min(ARG, left), >= 1 (timeout 0 never stops)
[ -x "$bundle/run.sh" ] || { echo "gpu-check: $bundle/run.sh not found: make the bundle first (tools/gpu-bundle.sh)" >&2; exit 2; }
[ -d scenes ] && [ -d data ] || { echo "gpu-check: run from the repository root (scenes/ and data/ not found)" >&2; exit 2; }
# The test binaries read the repository through the source path they were built in: where
# that path does not exist here, link it to this checkout (tools/gpu-bundle.sh records it).
if [ -s "$bundle/source_dir" ]; then
  src=$(cat "$bundle/source_dir")
  if [ ! -e "$src" ]; then
    mkdir -p "$(dirname "$src")" && ln -s "$PWD" "$src" && echo "gpu-check: linked $src -> $PWD"
  fi
fi
mkdir -p "$out/scenes"
summary="$out/summary.txt"
: > "$summary"
status=0
run() { bash "$bundle/run.sh" "$@"; }
note() { echo "$*" | tee -a "$summary"; }

{ nvidia-smi || echo "nvidia-smi failed"; } > "$out/nvidia-smi.txt" 2>&1
note "start $(date -u +%FT%TZ) on $(hostname)"

parts=${GPU_CHECK_PARTS:-tests bench scenes}
has_part() { [[ " $parts " == *" $1 "* ]]; }
note "parts: $parts"

# ---- 1. the gpu tests (they skip, with the reason, when no device is usable)
has_part tests && for t in test_cuda_gpu test_cuda_pcg_gpu; do
  if [ ! -x "$bundle/bin/$t" ]; then
    note "$t: not in the bundle (build it with -DLOOM_GPU_TESTS=ON, then tools/gpu-bundle.sh)"
    status=1
    continue
  fi
  timeout "$(cap 300)" bash "$bundle/run.sh" "$t" --gtest_output=xml:"$out/$t.xml" > "$out/$t.txt" 2>&1
  rc=$?
  skipped=$(grep -c -E '^\[  SKIPPED \]|no usable CUDA device' "$out/$t.txt" || true)
  note "$t: exit $rc, $(grep -E '^\[  PASSED  \]|^\[  FAILED  \]' "$out/$t.txt" | head -2 | tr '\n' ' ') skipped lines: $skipped"
  if [ "$rc" -ne 0 ] || [ "$skipped" -gt 0 ]; then status=1; fi
done

# ---- 2. benchmarks: Table 1 on the GPU (HO, RK4, SE, double and float, copy bandwidth) and BW wool
if has_part bench; then
  timeout "$(cap 240)" bash "$bundle/run.sh" table1_gpu --benchmark_repetitions=3 --benchmark_report_aggregates_only=true \
    --benchmark_min_time=0.2 --benchmark_out_format=json --benchmark_out="$out/table1_gpu.json" > "$out/table1_gpu.txt" 2>&1
  note "table1_gpu: exit $?"
fi
# ---- 3. shipped scenes, backend cuda against backend cpu, one frame of 20 steps
# max over the vertices of |a - b| (OBJ v lines), relative to max |b| and to max |b - b0|.
compare() {  # compare GPU_OBJ CPU_OBJ CPU_FRAME0_OBJ
  awk 'FNR == 1 { f++ } $1 == "v" { k = FNR; for (c = 2; c <= 4; c++) { if (f == 1) a[k, c] = $c; else if (f == 2) b[k, c] = $c; else z[k, c] = $c } }
       END { d = 0; m = 0; u = 0
             for (key in b) { e = a[key] - b[key]; if (e < 0) e = -e; if (e > d) d = e
                              s = b[key]; if (s < 0) s = -s; if (s > m) m = s
                              w = b[key] - z[key]; if (w < 0) w = -w; if (w > u) u = w }
             printf "%.3e,%.3e", (m > 0 ? d / m : d), (u > 0 ? d / u : d) }' "$1" "$2" "$3"
}
echo "scene,status,rel_to_positions,rel_to_displacement,note" > "$out/scenes.csv"
for scene in $(has_part scenes && ls ${GPU_CHECK_SCENES:-scenes/*.yaml}); do
  name=$(basename "$scene" .yaml)
  if [ "$(left)" -lt 20 ]; then
    echo "$name,no_time,,,\"the check's $total s were spent before this scene\"" >> "$out/scenes.csv"
    continue
  fi
  d="$out/scenes/$name"
  mkdir -p "$d"
  # output.every=1: a scene that writes every k-th frame would otherwise write frame 0 alone
  common=(--frames 1 --set integrator.substeps=20 --set output.lossless=true --set output.every=1
          --set self_collision=null --quiet --overwrite)
  extra_gpu=()
  extra_cpu=()
  if grep -q 'type: baraff_witkin' "$scene"; then  # both solves tight, so they agree to rounding
    # 1e-11, not tighter: on an H200 the device PCG's relative residual stalled at 1.2e-12
    # (wool 128^2) and 7.4e-12 (256^2), the rounding floor of a double PCG on those systems.
    extra_gpu=(--set solver.type=filtered_pcg --set solver.filtered_pcg.tolerance=1e-11
               --set solver.filtered_pcg.max_iterations=20000)
    extra_cpu=(--set solver.type=eigen_ldlt)
  fi
  timeout "$(cap "$per_scene")" bash "$bundle/run.sh" loom run "$scene" --out "$d/gpu" --set backend=cuda "${common[@]}" "${extra_gpu[@]}" > "$d/gpu.log" 2>&1
  g=$?
  if [ "$g" -eq 2 ]; then  # refused (bad input for the backend): the message names the fix
    echo "$name,refused,,,\"$(grep -m1 'error' "$d/gpu.log" | tr -d '"' | cut -c1-300)\"" >> "$out/scenes.csv"
    continue
  fi
  if [ "$g" -ne 0 ]; then
    echo "$name,gpu_failed_exit_$g,,,\"$(tail -1 "$d/gpu.log" | tr -d '"' | cut -c1-300)\"" >> "$out/scenes.csv"
    status=1
    continue
  fi
  timeout "$(cap "$per_scene")" bash "$bundle/run.sh" loom run "$scene" --out "$d/cpu" "${common[@]}" "${extra_cpu[@]}" > "$d/cpu.log" 2>&1
  c=$?
  if [ "$c" -ne 0 ]; then
    echo "$name,cpu_failed_exit_$c,,,\"$(tail -1 "$d/cpu.log" | tr -d '"' | cut -c1-300)\"" >> "$out/scenes.csv"
    status=1
    continue
  fi
  gl=$(ls "$d"/gpu/frame_*.obj | tail -1)
  cl=$(ls "$d"/cpu/frame_*.obj | tail -1)
  c0=$(ls "$d"/cpu/frame_*.obj | head -1)
  if [ "$cl" = "$c0" ] || [ "$(basename "$gl")" != "$(basename "$cl")" ]; then  # nothing after the start to compare
    echo "$name,not_compared,,,\"no frame after the start, or different last frames ($gl, $cl)\"" >> "$out/scenes.csv"
    status=1
    continue
  fi
  r=$(compare "$gl" "$cl" "$c0")
  ok=$(echo "$r" | awk -F, '{ print ($1 <= 1e-10) ? "agrees" : "differs" }')
  [ "$ok" = agrees ] || status=1
  echo "$name,$ok,$r," >> "$out/scenes.csv"
done
note "scenes: $(grep -c ',agrees,' "$out/scenes.csv") agree, $(grep -c ',differs,' "$out/scenes.csv") differ, $(grep -c ',refused,' "$out/scenes.csv") refused, $(grep -c '_failed_' "$out/scenes.csv") failed, $(grep -c ',no_time,' "$out/scenes.csv") not run (no time left), $(grep -c ',not_compared,' "$out/scenes.csv") not compared"

note "end $(date -u +%FT%TZ), status $status"
exit "$status"

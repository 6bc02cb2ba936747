#!/bin/sh
# Every shipped draped-ball scene through the real loom CLI with `--set backend=cuda`, the CUDA
# module built for Thrust's OpenMP system (tests/cuda: omp_module/loom_backend_cuda.so, found
# first on LOOM_PLUGIN_PATH), so the device code runs on the CPU: self_collision removed, one
# frame of a few steps, positions written lossless and compared with the same run on backend
# cpu (relative to the largest |x|; Baraff-Witkin with filtered_pcg at 1e-13 on both). The
# mesh-collider scene (draped_mesh_sphere_gnatv_bw) runs and is compared like the others.
# usage: cli_scenes_omp.sh LOOM REPO_ROOT [STEPS=10]
loom="$1"; root="$2"; steps=${3:-10}
tmp=$(mktemp -d); trap 'rm -rf "$tmp"' EXIT
fail=0
compare() {  # max |a - b| / max |b| over the OBJ v lines of two files
  awk 'FNR == 1 { f++ } $1 == "v" { for (c = 2; c <= 4; c++) { if (f == 1) a[FNR, c] = $c; else b[FNR, c] = $c } }
       END { d = 0; m = 0; for (k in b) { e = a[k] - b[k]; if (e < 0) e = -e; if (e > d) d = e
                                           s = b[k]; if (s < 0) s = -s; if (s > m) m = s }
             printf "%.3e", (m > 0 ? d / m : d) }' "$1" "$2"
}
for scene in "$root"/scenes/draped_*.yaml; do
  name=$(basename "$scene" .yaml)
  common="--frames 1 --set integrator.substeps=$steps --set output.lossless=true --set self_collision=null --quiet --overwrite"
  extra=""
  if grep -q 'type: baraff_witkin' "$scene"; then
    extra="--set solver.type=filtered_pcg --set solver.filtered_pcg.tolerance=1e-13 --set solver.filtered_pcg.max_iterations=20000"
  fi
  # shellcheck disable=SC2086
  out=$("$loom" run "$scene" --out "$tmp/$name.cuda" --set backend=cuda $common $extra 2>&1); rc=$?
  [ "$rc" -eq 0 ] || { echo "$name: backend cuda failed (exit $rc): $out"; fail=1; continue; }
  # shellcheck disable=SC2086
  out=$("$loom" run "$scene" --out "$tmp/$name.cpu" $common $extra 2>&1) || { echo "$name: backend cpu failed: $out"; fail=1; continue; }
  g=$(ls "$tmp/$name.cuda"/frame_*.obj | tail -1); c=$(ls "$tmp/$name.cpu"/frame_*.obj | tail -1)
  [ -n "$g" ] && [ -n "$c" ] && [ "$g" != "$c" ] || { echo "$name: no frames written"; fail=1; continue; }
  r=$(compare "$g" "$c")
  if awk -v r="$r" 'BEGIN { exit !(r <= 1e-10) }'; then
    echo "$name: cuda (OpenMP stand-in) agrees with cpu after $steps steps: $r relative"
  else
    echo "$name: cuda differs from cpu after $steps steps: $r relative"; fail=1
  fi
done
# The guard with the lazy host copy (host_sync_every: 0, the default): the device checks every
# step, and a divergence is reported at the same step, vertex and speed as on backend cpu.
div="--set integrator.dt=0.004 --set integrator.substeps=5 --frames 20 --quiet --overwrite"
# shellcheck disable=SC2086
gd=$("$loom" run "$root/scenes/hanging_cloth.yaml" --out "$tmp/div.cuda" --set backend=cuda $div 2>&1); grc=$?
# shellcheck disable=SC2086
cd_=$("$loom" run "$root/scenes/hanging_cloth.yaml" --out "$tmp/div.cpu" $div 2>&1); crc=$?
if [ "$grc" -eq 3 ] && [ "$crc" -eq 3 ] && [ "$gd" = "$cd_" ] && echo "$gd" | grep -q "diverged at step"; then
  echo "divergence: the same report on cuda and cpu: $(echo "$gd" | head -1 | cut -c1-90)"
else
  echo "divergence: cuda (exit $grc) and cpu (exit $crc) differ: [$gd] [$cd_]"; fail=1
fi
# loom run --resume on backend cuda: the device integrator takes the restart point's x and v (the
# framework calls prepare() again, Simulation::state_changed), so a run resumed at frame 2 of 4
# writes frame 4 bit for bit as the whole run does (before 2026-12-02 it went on from the scene's
# initial state on the device: frame 4 then differed by 16 mm on hanging_10x10_k2000).
for sc in hanging_10x10_k2000 kang_cho_fig7_ho_k2000; do
  res="--set backend=cuda --set output.lossless=true --quiet --overwrite"
  # shellcheck disable=SC2086
  "$loom" run "$root/scenes/$sc.yaml" --out "$tmp/$sc.full" --frames 4 $res > "$tmp/$sc.log" 2>&1 &&
    "$loom" run "$root/scenes/$sc.yaml" --out "$tmp/$sc.part" --frames 2 $res >> "$tmp/$sc.log" 2>&1 &&
    "$loom" run --resume "$tmp/$sc.part" --frames 4 --quiet >> "$tmp/$sc.log" 2>&1 || {
      echo "$sc: a cuda run or its resume failed: $(cat "$tmp/$sc.log")"; fail=1; continue; }
  if cmp -s "$tmp/$sc.full/frame_00004.obj" "$tmp/$sc.part/frame_00004.obj"; then
    echo "$sc: resumed at frame 2 of 4 on cuda (OpenMP stand-in): frame 4 bit for bit the whole run's"
  else
    echo "$sc: resumed cuda run differs from the whole run at frame 4: $(compare "$tmp/$sc.part/frame_00004.obj" "$tmp/$sc.full/frame_00004.obj") relative"
    fail=1
  fi
done
exit $fail

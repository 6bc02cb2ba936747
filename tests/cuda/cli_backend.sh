#!/bin/sh
# `backend: cuda` through the real loom CLI and the real loom_backend_cuda module (built by nvcc).
# Without a usable GPU: exit code 2 and one clear error naming what is missing and the fix.
# With a GPU: the run succeeds.
# usage: cli_backend.sh LOOM SCENE
loom="$1"; scene="$2"
out=$("$loom" run "$scene" 2>&1); rc=$?
if command -v nvidia-smi >/dev/null 2>&1 && nvidia-smi -L >/dev/null 2>&1; then
  [ "$rc" -eq 0 ] || { echo "GPU present but the run failed (exit $rc): $out"; exit 1; }
  echo "ran on the GPU"; exit 0
fi
[ "$rc" -eq 2 ] || { echo "expected exit code 2 without a GPU, got $rc: $out"; exit 1; }
echo "$out" | grep -q "backend: cuda needs a usable NVIDIA GPU" || { echo "unexpected message: $out"; exit 1; }
echo "$out" | grep -q "set backend: cpu" || { echo "the message does not name the fix: $out"; exit 1; }
[ "$(echo "$out" | grep -c 'error')" -eq 1 ] || { echo "expected one error line: $out"; exit 1; }
echo "no GPU: clear error, as expected"
# The shipped Baraff-Witkin draped ball on cuda with the solver list [cholmod, filtered_pcg] (the
# scene's own list until it chose filtered_pcg alone): the list picks the first solver the cuda
# backend has (filtered_pcg), and the scene (sphere collider, self-collision removed) reaches the
# device check instead of being refused.
root=$(dirname "$0")/../..
out=$("$loom" validate "$root/scenes/draped_ball_gnatv_bw.yaml" --set backend=cuda --set self_collision=null \
  --set 'solver.type=[cholmod, filtered_pcg]' 2>&1); rc=$?
echo "$out" | grep -q "using filtered_pcg" || { echo "draped_ball_gnatv_bw on cuda did not choose filtered_pcg: $out"; exit 1; }
if [ "$rc" -ne 0 ]; then
  echo "$out" | grep -q "backend: cuda needs a usable NVIDIA GPU" || { echo "draped_ball_gnatv_bw on cuda refused: $out"; exit 1; }
fi
echo "draped_ball_gnatv_bw with backend cuda: filtered_pcg chosen, no refusal"

#!/usr/bin/env bash
# Regenerate the images in docs/images from the current code, by group:
#   scripts/make_doc_images.sh [renders] [draped] [drape] [figures] [studies] [kawabata] [table1] [all]
# Default: renders (a few seconds). The others take minutes; table1 is a benchmark (run it on a
# quiet machine). Needs a build (cmake --preset default; figures and table1 need
# -DLOOM_BUILD_BENCH=ON) and python3-matplotlib. Work files go to out/doc_images/.
set -euo pipefail
root=$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)
cd "$root"
loom=build/bin/loom
img=docs/images
work=out/doc_images
mkdir -p "$work"
groups=("$@")
[ ${#groups[@]} -eq 0 ] && groups=(renders)
[ "${groups[*]}" = all ] && groups=(renders draped drape figures studies kawabata table1)
[ -x "$loom" ] || { echo "make_doc_images: $loom is missing: build first (cmake --preset default && cmake --build --preset default)" >&2; exit 2; }

say() { echo "make_doc_images: $*" >&2; }

# montage OUT IN... : the images side by side (matplotlib)
montage() {
  local out=$1; shift
  /usr/bin/python3 - "$out" "$@" <<'PY'
import sys
import matplotlib
matplotlib.use("Agg")
import matplotlib.image as mpimg
import numpy as np
ims = [mpimg.imread(p)[..., :3] for p in sys.argv[2:]]
h = min(i.shape[0] for i in ims)
mpimg.imsave(sys.argv[1], np.concatenate([i[:h] for i in ims], axis=1))
PY
}

for g in "${groups[@]}"; do
  case $g in
    renders)
      # RENDERING.md: frame 60 of the README's first scene, 2/1 twill, 480 x 270, camera fitted
      # to the whole sequence, ground and shadow (the defaults).
      say "hanging_cloth_frame60.png"
      "$loom" run scenes/hanging_cloth.yaml --quiet --overwrite --out "$work/hanging_cloth"
      "$loom" render "$work/hanging_cloth" --quiet --out "$work/hanging_cloth/render" \
        --set render.width=480 --set render.height=270 --set render.video=off \
        --set render.fabric=../materials/fabrics/twill_2_1.yaml
      cp "$work/hanging_cloth/render/frame_00060.png" "$img/hanging_cloth_frame60.png"
      ;;
    draped)
      # RENDERING.md: the wool cloth on the spinning ball at frame 45 (several minutes).
      say "draped_ball_gnatv_bw_frame45.png"
      "$loom" run scenes/draped_ball_gnatv_bw.yaml --quiet --overwrite --frames 45 --set output.every=45 --out "$work/draped"
      "$loom" render "$work/draped" --quiet --out "$work/draped/render" --set render.video=off
      cp "$work/draped/render/frame_00045.png" "$img/draped_ball_gnatv_bw_frame45.png"
      ;;
    drape)
      # docs/plugins/bending.md: denim, knit, polyester after 5 s, side by side.
      say "drape_denim_knit_polyester.png"
      pngs=()
      for s in denim knit polyester; do
        "$loom" run "scenes/drape_$s.yaml" --quiet --overwrite --out "$work/drape_$s" --set output.every=300
        "$loom" render "$work/drape_$s" --quiet --out "$work/drape_$s/render" \
          --set render.width=400 --set render.height=300 --set render.video=off
        pngs+=("$work/drape_$s/render/frame_00300.png")
      done
      montage "$img/drape_denim_knit_polyester.png" "${pngs[@]}"
      ;;
    figures)
      # RENDERING.md: Fig. 6, 10, 11 (bench/render/render_figures.cpp).
      say "fig6, fig10, fig11"
      cmake --build build --target render_figures >&2
      build/bin/render_figures "$img"
      ;;
    studies)
      # STUDIES.md: the four work-precision plots.
      for pair in "hanging_10x10_k2000 hanging_k2000 study_hanging_k2000" "hanging_10x10_k2000 hanging_k1e6 study_hanging_k1e6" \
                  "wool_hanging_32 wool_rk4_vs_bw study_wool" "hanging_cloth default_scene study_default"; do
        set -- $pair
        say "$3.png"
        "$loom" study "scenes/$1.yaml" "studies/$2.yaml" --quiet --out "$work/$3"
        cp "$work/$3/study.png" "$img/$3.png"
      done
      ;;
    kawabata)
      say "kawabata_wool.png"
      python3 scripts/kawabata.py run scenes/kawabata/wool_*.yaml --out "$work/kawabata" --plot "$img/kawabata_wool.png"
      ;;
    table1)
      say "table1.png (a benchmark: run on a quiet machine)"
      cmake --build build --target table1 >&2
      python3 scripts/table1.py --run --json "$work/table1.json" --out "$img/table1.png"
      ;;
    *)
      echo "make_doc_images: unknown group '$g' (renders, draped, drape, figures, studies, kawabata, table1, all)" >&2
      exit 2
      ;;
  esac
done
say "done: ${groups[*]}"

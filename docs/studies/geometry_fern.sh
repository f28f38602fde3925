#!/usr/bin/env bash
# docs/geometry.md's runs, rerunnable: fern × styles, the paper's norm regulariser against
# mean-square, 300 steps at 252 px (texture scale 64), on the CPU.
#   bash docs/studies/geometry_fern.sh FERN.ply OUT_DIR [nine|relief]
# FERN.ply: `gast fit ../shared/data/datasets/fern --holdout-every 8 --resolution 504 --iterations 1000 --out FERN.ply`
# nine: the nine styles with the built-in relief depth; relief: assets/relief_blocks.png with its exact depth.
set -euo pipefail
fern=$1 out=$2 which=${3:-nine}
shared=${GAST_SHARED:-$(dirname "$0")/../../../shared}
gast=${GAST:-cargo run --release -q -p gast --}
common=(--cameras "$shared/data/datasets/fern" --resolution 252 --texture-scale 64 --cycles 3 --device cpu
  --weights "$shared/data/weights/vgg19-conv3.safetensors" --preview-views 4 --seed 1)
ms=(--param-regulariser mean-square --lambda-opacity 10 --lambda-scale 10 --lambda-rotation 10)
mkdir -p "$out"
run() { local name=$1; shift; $gast stylize "$@" --out "$out/$name" > "$out/$name.log" 2>&1
  echo "$name: $(grep -E 'depth against|inverse depth changed' "$out/$name.log" | tr '\n' ' ')"; }
if [ "$which" = relief ]; then
  r=(assets/relief_blocks.png --style-depth assets/relief_blocks_depth.png)
  run colour_only "$fern" "${r[@]}" "${common[@]}" --mode color-only
  run norm "$fern" "${r[@]}" "${common[@]}"
  for l in 3 10 30; do
    run "ms$l" "$fern" "${r[@]}" "${common[@]}" --param-regulariser mean-square --lambda-opacity $l --lambda-scale $l --lambda-rotation $l
  done
else
  for s in block2 fire galaxy hydrangea mosaic particle starry stone wave; do
    run "${s}_norm" "$fern" "$shared/data/styles/$s.jpg" "${common[@]}" --depth-provider heuristic
    run "${s}_ms10" "$fern" "$shared/data/styles/$s.jpg" "${common[@]}" --depth-provider heuristic "${ms[@]}"
  done
fi

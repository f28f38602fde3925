#!/usr/bin/env bash
# docs/img/'s depth strips, remade from `gast stylize` run folders (one row a run):
# the style, view 0's depth colour-matched and after (the reference's JET map, near red),
# and view 0's RGB after, each at half the run's size.
#   bash docs/studies/depth_strip.sh OUT.jpg RUN_DIR...
# Needs ImageMagick (`convert`, `montage`); no labels (no fonts needed): the columns are as above.
set -euo pipefail
out=$1; shift
tmp=$(mktemp -d); trap 'rm -rf "$tmp"' EXIT
rows=()
for run in "$@"; do
  name=$(basename "$run")
  h=$(identify -format %h "$run/view0_after.png")
  half=$((h / 2))
  montage "$run/style.png" "$run/view0_colour_matched_depth_jet.png" "$run/view0_after_depth_jet.png" \
    "$run/view0_after.png" -geometry "x$half+2+2" -tile 4x1 -background white "$tmp/$name.png"
  rows+=("$tmp/$name.png")
done
convert "${rows[@]}" -gravity west -append -quality 82 "$out.tmp.jpg"
mv "$out.tmp.jpg" "$out"
echo "$out: $(identify -format '%wx%h' "$out"), $(stat -c %s "$out") bytes"

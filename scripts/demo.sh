#!/usr/bin/env bash
# The embedded-default demo: a synthetic spinning-lidar drive -> map-mode hierarchy with normals -> PLY ->
# independent verification -> per-level summary. Usage: scripts/demo.sh PATH/TO/hpds OUT_DIR
set -euo pipefail
hpds=$1
out=$2
rm -rf "$out"
mkdir -p "$out"
echo "== 1. synthetic lidar: 32 beams x 1800 azimuths, 10 frames driving down an urban street"
"$hpds" synth -o "$out/stream" --frames 10 --scene urban --seed 1
echo
echo "== 2. map-mode sampling with normals (cell 4 m, max depth 8, output spacing 0.15 m)"
"$hpds" sample "$out"/stream/frame_*.pcd --poses "$out/stream/poses.txt" --mode map --normals \
  --cell-size 4 --max-depth 8 --spacing 0.15 -o "$out/map.ply" --stats "$out/stats.json"
echo
echo "== 3. independent check of the written sampling (k-d tree, not the sampler's grids)"
"$hpds" verify "$out/map.ply" --cell-size 4
echo
echo "== 4. pictures: top and side views coloured by level and by normal"
"$hpds" render "$out/map.ply" -o "$out/pictures" --color level,normal --view top,side
echo
echo "demo output: $out/map.ply (open it in CloudCompare or MeshLab), $out/stats.json, $out/pictures/*.png"

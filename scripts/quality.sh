#!/usr/bin/env bash
# make quality: sampling quality, measured. Normal accuracy against exact ground truth, feature-sensitive levels,
# blue-noise analysis against grid baselines, and pictures; tables and plots under OUT_DIR.
# Usage: scripts/quality.sh BUILD_DIR OUT_DIR [JOBS]
set -euo pipefail
here=$(cd "$(dirname "$0")" && pwd)
build=$1
out=$2
jobs=${3:-2}
hpds=$build/hpds
# Debian's interpreter: python3-matplotlib is installed for it, whatever python3 comes first on PATH.
python=/usr/bin/python3
mkdir -p "$out"

echo "== 1. normal accuracy against ground truth: 4 synthetic scenes, hpds vs PCL pipelines at equal count"
"$build/bench/normal_accuracy" --out "$out" --threads "$jobs"
"$python" "$here/plot_quality.py" normals "$out"

echo
echo "== 2. feature-sensitive insertion orders on a sweep beside a sculpture"
"$build/bench/feature_sensitivity" --out "$out" --threads "$jobs"
"$python" "$here/plot_quality.py" features "$out"

echo
echo "== 3. blue-noise analysis on a plane (the paper's figure 5): hpds vs grid baselines at equal count"
rm -rf "$out/plane" "$out/stream" "$out/analysis" "$out/render"
"$build/bench/plane_sampling" --out "$out/plane"
"$hpds" analyze "$out/plane/plane_sampling.ply" --cell-size 4 -o "$out/plane/analysis" \
  --input "$out/plane/plane_input.ply" --patch 0,0,12 --threads "$jobs"

echo
echo "== 4. blue-noise analysis of lidar ground: map-mode sampling of a 10-frame drive vs the same baselines"
"$hpds" synth -o "$out/stream" --frames 10 --scene urban --seed 1
"$hpds" sample "$out"/stream/frame_*.pcd --poses "$out/stream/poses.txt" --mode map --normals \
  --cell-size 4 --max-depth 8 --spacing 0.15 -o "$out/map.ply" > "$out/sample.log"
"$hpds" analyze "$out/map.ply" --cell-size 4 -o "$out/analysis" --input "$out"/stream/frame_*.pcd \
  --poses "$out/stream/poses.txt" --threads "$jobs"
"$hpds" render "$out/map.ply" -o "$out/render" --prefix street --crop 5,-8,-1,25,8,6 > /dev/null
"$hpds" render "$out/map.ply" -o "$out/render" --prefix map --view top > /dev/null

echo
echo "quality results in $out:"
echo "  normal_accuracy.md (.csv .json), normal_error_cdf.png, normal_error_bars.png, pictures/*_error_top.png"
echo "  feature_levels.md (.csv), feature_levels.png, feature_sculpture.png"
echo "  plane/analysis/compare.png (figure 5 on a plane), analysis/compare.png (lidar ground), */levels.png"
echo "  render/*.png (top/front/side views by level, normal, feature)"

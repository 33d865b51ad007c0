#!/usr/bin/env bash
# The measurements of docs/scaling.md: a synthetic drive sampled by one `hpds sample --mode map` run and by the
# tiled map build with 0 (no Dask), 1 and 2 local Dask workers, in alternating rounds so that every configuration
# sees the same state of a shared machine. Prints one line per run (wall and CPU time of the whole process tree,
# its largest resident set) and the build's own statistics from manifest.json.
# Usage: scripts/scaling.sh BUILD_DIR WORK_DIR [ROUNDS]
set -euo pipefail
build=$(realpath "$1") work=$2 rounds=${3:-3}
export PATH=/usr/bin:/bin:$PATH PYTHONPATH=$build/python
flags=(--spacing 0.1 --max-depth 7 --normals)
mkdir -p "$work" && cd "$work"
[ -f drive/poses.txt ] || "$build/hpds" synth -o drive --frames 40 --beams 32 --azimuth-steps 1800 --speed 1.0
frames=(drive/frame_*.pcd)
for round in $(seq "$rounds"); do
  rm -f single.ply
  /usr/bin/time -f "round $round single    wall %e s  cpu %U+%S s  maxrss %M KB" \
    "$build/hpds" sample "${frames[@]}" --poses drive/poses.txt --mode map "${flags[@]}" -o single.ply 2>&1 >/dev/null |
    tail -n 1
  for w in 0 1 2; do
    rm -rf "tiled$w"
    /usr/bin/time -f "round $round workers $w wall %e s  cpu %U+%S s  maxrss %M KB" \
      python3 -m hpds.map_build "${frames[@]}" --poses drive/poses.txt -o "tiled$w" --tile-size 16 --workers "$w" \
      "${flags[@]}" 2>&1 >/dev/null | tail -n 1
    python3 - "tiled$w/manifest.json" <<'PY'
import json, sys
m = json.load(open(sys.argv[1])); r = m["run"]; c = r["task_cpu_seconds"]
print("    build %.1f s, task cpu %.1f s (bucketing %.1f, tiles %.1f, outputs %.1f), critical path %.1f s, "
      "peak tile %.1f MB, %d tiles, %d samples" % (r["seconds"]["total"], c["bucketing"] + c["tiles"] + c["outputs"],
      c["bucketing"], c["tiles"], c["outputs"], c["critical_path"], r["peak_tile_memory_bytes"] / 1e6,
      len(m["tiles"]), m["counts"]["samples_written"]))
PY
  done
  uptime
done

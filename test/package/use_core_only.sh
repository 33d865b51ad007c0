#!/usr/bin/env bash
# Builds examples/core_only (C++ only, find_package(hpds COMPONENTS core)) against an installed prefix and runs it on
# a generated cloud: a floor and a wall of points 2 cm apart. Checks that PCL was not looked up, that the samples
# are fewer than the points, that every sample is an input point, and that most floor samples have a normal.
# Usage: use_core_only.sh SOURCE_DIR PREFIX WORK_DIR [extra cmake arguments]
set -euo pipefail
src=$1 prefix=$2 work=$3
shift 3
fail() { echo "use_core_only: $* (files kept in $work)" >&2; exit 1; }
rm -rf "$work"
mkdir -p "$work"

cmake -S "$src/examples/core_only" -B "$work/build" -DCMAKE_PREFIX_PATH="$prefix" -DCMAKE_BUILD_TYPE=Release "$@" \
  > "$work/configure.log" 2>&1 || { cat "$work/configure.log"; fail "examples/core_only does not configure"; }
if grep -q PCL "$work/configure.log"; then cat "$work/configure.log"; fail "PCL was looked up for a core-only project"; fi
cmake --build "$work/build" -j2 > "$work/build.log" 2>&1 || { cat "$work/build.log"; fail "examples/core_only does not build"; }

# 50 x 50 floor points at z = 0 (x from 2 m, so none is the no-return origin) and, 1 m away, a 50 x 50 wall at x = 4.
{
  echo "# floor and wall"
  awk 'BEGIN { for (i = 0; i < 50; ++i) for (j = 0; j < 50; ++j) {
    printf "%.3f %.3f 0\n", 2 + 0.02 * i, 0.02 * j; printf "4 %.3f %.3f\n", 0.02 * j, 1 + 0.02 * i } }'
} > "$work/points.xyz"
"$work/build/downsample_xyz" "$work/points.xyz" "$work/samples.xyz" > "$work/run.log" || fail "downsample_xyz failed"
read -r points _ _ samples _ < "$work/run.log"
[ "$points" -eq 5000 ] || fail "read $points points, not 5000"
[ "$samples" -gt 0 ] && [ "$samples" -lt "$points" ] || fail "expected 0 < samples < $points, got $samples"
[ "$(wc -l < "$work/samples.xyz")" -eq "$samples" ] || fail "samples.xyz does not hold $samples lines"
# Every sample is one of the input points (x y z as written in the input, to the input's 3 decimals).
awk 'NR == FNR { if ($1 != "#") seen[sprintf("%.3f %.3f %.3f", $1, $2, $3)] = 1; next }
     !(sprintf("%.3f %.3f %.3f", $1, $2, $3) in seen) { bad++ } END { exit bad > 0 }' \
  "$work/points.xyz" "$work/samples.xyz" || fail "a sample is not an input point"
# The floor's normals are vertical.
awk '$3 == 0 { n++; if ($6 > 0.99 || $6 < -0.99) v++ } END { exit !(n > 0 && v >= 0.9 * n) }' "$work/samples.xyz" ||
  fail "fewer than 90 % of the floor samples have a vertical normal"
# A malformed line is an error naming it, not a skipped point.
printf '1 2 3\n4 5\n' > "$work/bad.xyz"
if "$work/build/downsample_xyz" "$work/bad.xyz" "$work/bad_out.xyz" 2> "$work/bad.log"; then fail "a malformed line was accepted"; fi
grep -q "bad.xyz:2" "$work/bad.log" || fail "the error does not name the line: $(cat "$work/bad.log")"
echo "use_core_only: OK ($samples samples of $points points)"

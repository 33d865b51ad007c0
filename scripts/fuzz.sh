#!/usr/bin/env bash
# `make fuzz`: builds the libFuzzer targets of fuzz/ with clang (ASan + UBSan), writes the project's own seed
# corpora, then runs every target for FUZZ_SECONDS on its corpus (kept in $FUZZ_BUILD/corpus/<target> between runs).
# Prints one line per target (runs, corpus size, outcome); exits non-zero if any target crashed. Crashing inputs
# land in $FUZZ_BUILD/artifacts/<target>/ and belong in test/regressions/ once fixed.
#   FUZZ_TARGETS="pcd ply"   run only these;   FUZZ_JOBS=2   run that many targets at once (default 1)
set -euo pipefail
cd "$(dirname "$0")/.."
export PATH=/usr/bin:/bin:$PATH
BUILD=${FUZZ_BUILD:-build/fuzz}
SECONDS_EACH=${FUZZ_SECONDS:-60}
JOBS=${JOBS:-2}
FUZZ_JOBS=${FUZZ_JOBS:-1}

mkdir -p "$BUILD"
if [ ! -f "$BUILD/CMakeCache.txt" ]; then
  CC=clang CXX=clang++ cmake -S fuzz -B "$BUILD" -DCMAKE_BUILD_TYPE=RelWithDebInfo > "$BUILD/configure.log" 2>&1 ||
    { cat "$BUILD/configure.log"; exit 1; }
fi
all=(pcd ply kitti_bin poses config_yaml map cloud_conversion)
# fuzz_cloud_conversion exists only where the ROS message headers are installed.
known=$(cmake --build "$BUILD" --target help)
built=()
for t in "${all[@]}"; do
  if grep -qw "fuzz_$t" <<< "$known"; then built+=("$t"); fi
done
read -r -a targets <<< "${FUZZ_TARGETS:-${built[*]}}"
cmake --build "$BUILD" -j"$JOBS" --target make_seeds $(printf 'fuzz_%s ' "${targets[@]}")
"$BUILD/make_seeds" "$BUILD/seeds" > /dev/null

# Inputs above these sizes add run time, not coverage: headers are small and the bodies repeat.
declare -A max_len=([pcd]=16384 [ply]=16384 [kitti_bin]=4096 [poses]=4096 [config_yaml]=4096 [map]=16384
                    [cloud_conversion]=4096)
run_one() {
  local t=$1
  local corpus="$BUILD/corpus/$t" artifacts="$BUILD/artifacts/$t/" log="$BUILD/logs/$t.log"
  mkdir -p "$corpus" "$artifacts" "$BUILD/logs"
  local dict=()
  [ -f "fuzz/$t.dict" ] && dict=(-dict="fuzz/$t.dict")
  local rc=0
  ASAN_OPTIONS=detect_leaks=1:allocator_may_return_null=0 UBSAN_OPTIONS=halt_on_error=1:print_stacktrace=1 \
    "$BUILD/fuzz_$t" "$corpus" "$BUILD/seeds/$t" -max_total_time="$SECONDS_EACH" -max_len="${max_len[$t]}" \
    -timeout=25 -rss_limit_mb=2560 -print_final_stats=1 -artifact_prefix="$artifacts" "${dict[@]}" \
    > "$log" 2>&1 || rc=$?
  local runs
  runs=$(grep -E '^stat::number_of_executed_units' "$log" | awk '{print $2}' || true)
  local files
  files=$(find "$corpus" -type f | wc -l)
  if [ $rc -eq 0 ]; then
    printf 'fuzz_%-17s %10s runs in %ss, corpus %s files: OK\n' "$t" "${runs:-?}" "$SECONDS_EACH" "$files"
  else
    printf 'fuzz_%-17s %10s runs: CRASH (exit %s), see %s and %s\n' "$t" "${runs:-?}" "$rc" "$log" "$artifacts"
    grep -E 'ERROR|SUMMARY|invariant violated|uncaught' "$log" | head -5 | sed 's/^/    /'
  fi
  return $rc
}

failed=0
pids=()
for t in "${targets[@]}"; do
  run_one "$t" &
  pids+=($!)
  if [ ${#pids[@]} -ge "$FUZZ_JOBS" ]; then
    wait "${pids[0]}" || failed=1
    pids=("${pids[@]:1}")
  fi
done
for p in "${pids[@]}"; do wait "$p" || failed=1; done
exit $failed

#!/usr/bin/env bash
# hpds::core must configure, build and pass its tests on a machine without PCL and without ROS: configure a second
# build with PCL hidden from find_package and the node off, build the core and its API test, run it. That build is a
# static one (BUILD_SHARED_LIBS=OFF), installed into a prefix and used by examples/core_only: a static hpds::core
# brings its private dependency (yaml-cpp) to the program that links it. Also checks
# that no core source or header includes PCL or ROS headers (ROS's headers are in /usr/include on Debian, so a
# stray include would compile here without this check).
# Usage: core_without_pcl.sh SOURCE_DIR WORK_DIR
set -euo pipefail
src=$(realpath "$1") work=$(realpath -m "$2")
fail() { echo "core_without_pcl: $*" >&2; exit 1; }

if grep -rnE '#include *[<"](pcl/|ros/|sensor_msgs/|tf2|rosbag/|nodelet/)' "$src/hpds_core/src" "$src/hpds_core/include/hpds" \
     --exclude-dir=pcl --exclude=pcl.hpp; then
  fail "the lines above put PCL or ROS headers into hpds::core"
fi

rm -rf "$work"
mkdir -p "$work"
cmake -S "$src" -B "$work" -DCMAKE_BUILD_TYPE=Release -DCMAKE_DISABLE_FIND_PACKAGE_PCL=ON -DHPDS_BUILD_NODE=OFF \
  -DBUILD_SHARED_LIBS=OFF -DHPDS_BUILD_PYTHON=OFF \
  > "$work/hpds-configure.log" 2>&1 || { cat "$work/hpds-configure.log"; fail "does not configure without PCL"; }
targets=$(cmake --build "$work" --target help)
if grep -qE '(^|\.\.\. )hpds_pcl$' <<< "$targets"; then fail "hpds_pcl is configured although PCL is hidden"; fi
cmake --build "$work" -j2 --target hpds_core test_api > "$work/hpds-build.log" 2>&1 || { tail -n 50 "$work/hpds-build.log"; fail "the core does not build without PCL"; }
test_api=$(find "$work" -name test_api -type f -perm -u+x | head -n 1)
[ -n "$test_api" ] || fail "test_api was not built"
"$test_api" --gtest_brief=1 || fail "test_api fails in the build without PCL"
ls "$work"/hpds_core/libhpds_core.a > /dev/null 2>&1 || fail "hpds_core is not a static library in this build"
cmake --install "$work" --prefix "$work/prefix" > "$work/install.log" 2>&1 || { cat "$work/install.log"; fail "cmake --install failed"; }
"$src/test/package/use_core_only.sh" "$src" "$work/prefix" "$work/core_example" || fail "examples/core_only against the static prefix"
echo "core_without_pcl: OK"

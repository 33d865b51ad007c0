#!/usr/bin/env bash
# The installed package as its users get it: `cmake --install` the build into a fresh prefix, check what lands there,
# then build examples/ against it as a separate project (find_package(hpds)) and run it on a real frame (a
# synthetic one when ../shared is absent).
# Usage: install_and_use.sh BUILD_DIR SOURCE_DIR NODE_BUILT(ON|OFF) [SANITIZERS(OFF|address,undefined|thread)]
# A sanitized build installs instrumented libraries: a program using them must be built with the same sanitizers
# (the runtime has to come first), as a user of such a build would.
# The prefix is made under the system's temporary folder, outside the source tree: roslaunch looks for launch files
# anywhere below the package's source folder and would find the installed copies too. Removed when the test passes.
set -euo pipefail
build=$1 src=$(realpath "$2") node=$3 sanitized=${4:-OFF}
work=$(mktemp -d "${TMPDIR:-/tmp}/hpds-install-test.XXXXXX")
prefix=$work/prefix
fail() { echo "install_and_use: $* (files kept in $work)" >&2; exit 1; }

cmake --install "$build" --prefix "$prefix" > "$work/install.log" || { cat "$work/install.log"; fail "cmake --install failed"; }
# Nothing lands outside the prefix asked for: staged with DESTDIR, every file is under the stage's copy of it
# (catkin installed its workspace setup files to the prefix of configure time, /usr/local, whatever --prefix said).
DESTDIR="$work/stage" cmake --install "$build" --prefix "$prefix" > "$work/stage.log" ||
  { cat "$work/stage.log"; fail "cmake --install with DESTDIR failed"; }
stray=$(cd "$work/stage" && find . \( -type f -o -type l \) -not -path "./${prefix#/}/*" | head -n 5)
[ -z "$stray" ] || fail "cmake --install --prefix $prefix writes outside it: $stray"
grep -E "^-- (Installing|Up-to-date): " "$work/install.log" | grep -v -- ": $prefix/" | head -n 5 | grep -q . &&
  fail "cmake --install --prefix $prefix writes outside it: $(grep -E '^-- (Installing|Up-to-date): ' "$work/install.log" | grep -v -- ": $prefix/" | head -n 5)"
rm -rf "$work/stage"

# What a user of the library, the tool and the ROS package finds in the prefix.
config=$(cd "$prefix" && find . -path '*/cmake/hpds/hpdsConfig.cmake' | head -n 1)
[ -n "$config" ] || fail "no hpdsConfig.cmake in the prefix"
libdir=${config#./}
libdir=${libdir%/cmake/hpds/hpdsConfig.cmake}
for f in include/hpds/hpds.hpp include/hpds/pcl.hpp include/hpds/config/Config.hpp include/hpds/pipeline/Pipeline.hpp \
         "$libdir/cmake/hpds/hpdsConfig.cmake" "$libdir/cmake/hpds/hpdsConfigVersion.cmake" \
         "$libdir/cmake/hpds/hpdsTargets.cmake" bin/hpds share/doc/hpds/LICENSE; do
  [ -e "$prefix/$f" ] || fail "$f is not installed"
done
ls "$prefix/$libdir"/libhpds_core.* > /dev/null 2>&1 || fail "libhpds_core is not installed"
# Each target names the include folder once.
if grep -E 'INTERFACE_INCLUDE_DIRECTORIES "([^"]*/include);\1"' "$prefix/$libdir/cmake/hpds/hpdsTargets.cmake"; then
  fail "an installed target lists its include folder twice"
fi
ls "$prefix/$libdir"/libhpds_pcl.* > /dev/null 2>&1 || fail "libhpds_pcl is not installed"
[ ! -e "$prefix/include/hpds/eval" ] || fail "the evaluation headers are installed (they belong to no installed library)"
if find "$prefix" -name 'test_*' -type f | grep -q .; then fail "test binaries are installed"; fi
if [ "$node" = ON ]; then
  for f in lib/hpds/hpds_node lib/hpds/hpds "$libdir/libhpds_nodelet.so" share/hpds/package.xml \
           share/hpds/hpds_node/nodelet_plugins.xml share/hpds/launch/hpds.launch share/hpds/launch/replay.launch \
           share/hpds/config/hpds.yaml share/hpds/LICENSE; do
    [ -e "$prefix/$f" ] || fail "$f is not installed (ROS package)"
  done
fi
# The installed tool runs from the prefix (its libraries found through the install RPATH).
"$prefix/bin/hpds" --help > /dev/null || fail "the installed hpds tool does not run"
# `hpds analyze` plots with the script installed beside it, not the source tree's (which a user may not have).
"$prefix/bin/hpds" analyze --help | tr -s ' \n' ' ' | grep -q "default: $prefix/share/hpds/scripts/plot_quality.py" ||
  fail "installed hpds analyze does not use the installed plot script: $("$prefix/bin/hpds" analyze --help | grep -A1 plot-script)"

# The ROS package as a ROS user gets it from an install space: the package, its launch files, the nodelet plugin and
# `rosrun hpds hpds` resolve from the prefix alone (no source tree, no devel space on the paths). catkin_make install
# puts the same files into the workspace's install space.
if [ "$node" = ON ]; then
  (
    # What a catkin install space's setup.bash sets up (a standalone build installs no setup files).
    export ROS_PACKAGE_PATH=$prefix/share:/usr/share CMAKE_PREFIX_PATH=$prefix
    cd "$work"
    [ "$(rospack find hpds)" = "$prefix/share/hpds" ] || fail "rospack finds hpds at $(rospack find hpds)"
    rospack plugins --attrib=plugin nodelet | grep -q "^hpds $prefix/share/hpds/hpds_node/nodelet_plugins.xml" ||
      fail "the nodelet plugin is not registered from the install space"
    [ "$(roslaunch --nodes hpds hpds.launch | tr -d '\n')" = "/hpds" ] || fail "roslaunch hpds hpds.launch does not resolve"
    roslaunch --args /hpds hpds hpds.launch | grep -q " $prefix/lib/hpds/hpds_node " ||
      fail "hpds.launch does not start the installed node: $(roslaunch --args /hpds hpds hpds.launch)"
    rosrun hpds hpds --help > /dev/null || fail "rosrun hpds hpds does not run"
  ) || exit 1
fi

# pkg-config users of the ROS package's hpds.pc (written by catkin_package) get this prefix, not the configure-time
# one, and flags without a stray backslash.
if [ "$node" = ON ] && command -v pkg-config > /dev/null; then
  pc_flags=$(PKG_CONFIG_PATH=$prefix/lib/pkgconfig pkg-config --cflags --libs hpds) || fail "pkg-config hpds fails"
  case " $pc_flags " in *" -I$prefix/include "*) ;; *) fail "pkg-config hpds gives $pc_flags";; esac
  case " $pc_flags " in *" -L$prefix/lib "*) ;; *) fail "pkg-config hpds gives $pc_flags";; esac
  case "$pc_flags" in *'\'*) fail "pkg-config hpds gives a backslash: $pc_flags";; esac
fi

# The share/hpds/cmake config catkin writes (for find_package(catkin COMPONENTS hpds)) takes the versions the package's
# own takes: find_package(hpds 0.2) found it when lib/cmake/hpds refused, defining no target. Nor does it keep the
# configure-time prefix.
if [ "$node" = ON ]; then
  catkin_config=$prefix/share/hpds/cmake/hpdsConfig.cmake
  [ -f "$catkin_config" ] || fail "share/hpds/cmake/hpdsConfig.cmake is not installed (catkin packages need it)"
  if grep -q "/usr/local" "$catkin_config"; then fail "$catkin_config names /usr/local, not the prefix"; fi
  grep -q "$prefix" "$catkin_config" || fail "$catkin_config does not name the prefix"
fi
mkdir -p "$work/version"
cat > "$work/version/CMakeLists.txt" <<'CMAKE'
cmake_minimum_required(VERSION 3.16)
project(hpds_version_check CXX)
find_package(hpds ${WANT} ${EXACT} QUIET COMPONENTS core)
message(STATUS "hpds found=${hpds_FOUND} dir=${hpds_DIR} ")
if(hpds_FOUND AND NOT TARGET hpds::core)
  message(FATAL_ERROR "hpds found without hpds::core")
endif()
CMAKE
for want in "0.1" "0.1.0 EXACT" "0.2" "1.0" "0.0.1"; do
  rm -rf "$work/version/build"
  cmake -S "$work/version" -B "$work/version/build" -DCMAKE_PREFIX_PATH="$prefix" "-DWANT=${want% EXACT}" \
    "-DEXACT=$([ "${want% EXACT}" = "$want" ] || echo EXACT)" \
    > "$work/version.log" 2>&1 || { cat "$work/version.log"; fail "find_package(hpds $want) failed to configure"; }
  found=$(sed -n 's/.*hpds found=\([A-Za-z0-9]*\) .*/\1/p' "$work/version.log")
  case "$want" in
    "0.1"|"0.1.0 EXACT") expected=1 ;;
    *) expected=0 ;;
  esac
  if [ "$expected" = 1 ]; then
    [ "$found" = 1 ] || { cat "$work/version.log"; fail "find_package(hpds $want) did not find the package"; }
    grep -q "dir=$prefix/lib.*/cmake/hpds " "$work/version.log" ||
      { cat "$work/version.log"; fail "find_package(hpds $want) found another config than lib/cmake/hpds"; }
  else
    [ "$found" = 0 ] || { cat "$work/version.log"; fail "find_package(hpds $want) took version $(cat "$prefix"/lib*/cmake/hpds/hpdsConfigVersion.cmake | sed -n 's/^set(PACKAGE_VERSION \"\(.*\)\")/\1/p')"; }
  fi
done

# Without PCL on the user's machine (hidden here), hpds::pcl says what it needs: at find time, and in the failure of
# a REQUIRED pcl component (it was a compile error on <pcl/point_cloud.h>).
cat > "$work/version/CMakeLists.txt" <<'CMAKE'
cmake_minimum_required(VERSION 3.16)
project(hpds_pcl_check C CXX)
find_package(hpds ${WANT})
CMAKE
rm -rf "$work/version/build"
cmake -S "$work/version" -B "$work/version/build" -DCMAKE_PREFIX_PATH="$prefix" -DCMAKE_DISABLE_FIND_PACKAGE_PCL=ON \
  > "$work/nopcl.log" 2>&1 || { cat "$work/nopcl.log"; fail "find_package(hpds) without PCL failed"; }
grep -q "hpds::pcl is unusable: install PCL (Debian: libpcl-dev)" "$work/nopcl.log" ||
  { cat "$work/nopcl.log"; fail "find_package(hpds) without PCL does not say so"; }
rm -rf "$work/version/build"
if cmake -S "$work/version" -B "$work/version/build" -DCMAKE_PREFIX_PATH="$prefix" -DCMAKE_DISABLE_FIND_PACKAGE_PCL=ON \
     "-DWANT=REQUIRED;COMPONENTS;pcl" > "$work/nopcl.log" 2>&1; then
  cat "$work/nopcl.log"; fail "find_package(hpds REQUIRED COMPONENTS pcl) succeeded without PCL"
fi
grep -q "pcl component needs PCL 1.10 or later (Debian: libpcl-dev)" "$work/nopcl.log" ||
  { cat "$work/nopcl.log"; fail "a REQUIRED pcl component without PCL does not name the cure"; }

# pkg-config for the core alone: a program built with its flags only (no CMake) links and runs.
if command -v pkg-config > /dev/null; then
  core_pc=$(cd "$prefix" && find . -name hpds_core.pc | head -n 1)
  [ -n "$core_pc" ] || fail "hpds_core.pc is not installed"
  PKG_CONFIG_PATH=$prefix/${core_pc%/hpds_core.pc} pkg-config --cflags --libs hpds_core > "$work/core_pc.flags" ||
    fail "pkg-config hpds_core fails"
  if grep -qiE "pcl|vtk|openni" "$work/core_pc.flags"; then fail "pkg-config hpds_core names PCL: $(cat "$work/core_pc.flags")"; fi
  cat > "$work/core_pc.cpp" <<'CPP'
#include <hpds/hpds.hpp>
#include <cstdio>
int main() {
  std::vector<Eigen::Vector3f> points;
  for (int i = 0; i < 100; ++i)
    for (int j = 0; j < 100; ++j) points.emplace_back(2.0f + 0.01f * i, 0.01f * j, -1.0f);
  const hpds::Samples s = hpds::downsample(points);
  std::printf("%zu\n", s.size());
  return s.size() > 0 && s.size() < points.size() ? 0 : 1;
}
CPP
  san=()
  [ "$sanitized" = OFF ] || san=(-fsanitize="$sanitized")
  # shellcheck disable=SC2046
  g++ -std=c++17 "${san[@]}" "$work/core_pc.cpp" -o "$work/core_pc" $(cat "$work/core_pc.flags") \
    > "$work/core_pc.log" 2>&1 || { cat "$work/core_pc.log"; fail "a program built with pkg-config hpds_core does not build"; }
  LD_LIBRARY_PATH=$prefix/${core_pc%/pkgconfig/hpds_core.pc} "$work/core_pc" > /dev/null ||
    fail "a program built with pkg-config hpds_core does not run"
  # pkg-config's -I (not CMake's -isystem) shows a consumer's strict warnings in our headers: every core header,
  # in one file, must be clean under them (Hierarchy.hpp gave -Wsign-conversion warnings).
  (cd "$prefix/include" && find hpds -name '*.hpp' ! -path 'hpds/pcl/*' ! -name pcl.hpp | sort |
    sed 's/.*/#include <&>/') > "$work/all_headers.cpp"
  # (Eigen's own headers warn there too: only ours are checked.)
  # shellcheck disable=SC2046
  g++ -std=c++17 -fsyntax-only -Wall -Wextra -Wpedantic -Wshadow -Wsign-conversion "$work/all_headers.cpp" \
    $(cat "$work/core_pc.flags") > "$work/all_headers.log" 2>&1 || { cat "$work/all_headers.log"; fail "core headers do not compile"; }
  if grep -E "include/hpds/.*warning" "$work/all_headers.log"; then
    fail "the installed core headers warn under -Wall -Wextra -Wpedantic -Wshadow -Wsign-conversion"
  fi
fi

# A separate project against the prefix, built as strictly as a user's -Werror project may be (the example indexed
# PCL's fields with an int, and failed there).
strict="-Wall -Wextra -Wpedantic -Wshadow -Wconversion -Wsign-conversion -Wold-style-cast -Werror"
example_flags=(-DCMAKE_CXX_FLAGS="$strict")
san_flags=()
if [ "$sanitized" != OFF ]; then
  example_flags=(-DCMAKE_CXX_FLAGS="$strict -fsanitize=$sanitized" -DCMAKE_EXE_LINKER_FLAGS=-fsanitize=$sanitized)
  san_flags=(-DCMAKE_CXX_FLAGS=-fsanitize=$sanitized -DCMAKE_EXE_LINKER_FLAGS=-fsanitize=$sanitized)
fi
cmake -S "$src/examples" -B "$work/example" -DCMAKE_PREFIX_PATH="$prefix" -DCMAKE_BUILD_TYPE=Release \
  "${example_flags[@]}" > "$work/example-configure.log" 2>&1 || { cat "$work/example-configure.log"; fail "examples/ does not configure"; }
cmake --build "$work/example" -j2 > "$work/example-build.log" 2>&1 || { cat "$work/example-build.log"; fail "examples/ does not build"; }

frame=$src/../shared/data/lidar/hdl32_a.pcd
if [ ! -f "$frame" ]; then
  echo "install_and_use: ../shared/data/lidar is absent: using a synthetic frame instead of hdl32_a.pcd"
  "$prefix/bin/hpds" synth -o "$work/synth" --frames 1 > /dev/null
  frame=$work/synth/frame_000000.pcd
fi
"$work/example/downsample_pcd" "$frame" "$work/out.pcd" | tee "$work/run.log"
read -r points _ _ samples _ < "$work/run.log"
[ -s "$work/out.pcd" ] || fail "no output PCD"
[ "$samples" -gt 0 ] && [ "$samples" -lt "$points" ] || fail "expected 0 < samples < points, got $samples of $points"
# A file without intensity is read quietly (PCL warns about a missing field when asked to fill one).
xyz_only=$src/../shared/data/lidar/velodyne_vlp32.pcd
if [ -f "$xyz_only" ]; then
  "$work/example/downsample_pcd" "$xyz_only" "$work/out_xyz.pcd" > /dev/null 2> "$work/xyz_only.err" ||
    fail "the example failed on $xyz_only: $(cat "$work/xyz_only.err")"
  if grep -q "Failed to find match" "$work/xyz_only.err"; then fail "PCL warned on an x y z file: $(cat "$work/xyz_only.err")"; fi
fi
# Intensity of another type than float32 (the VLP-16's is uint8) is kept: PCL alone would have zeroed it, warning.
vlp16=$src/../shared/data/lidar/velodyne_vlp16.pcd
if [ -f "$vlp16" ]; then
  "$work/example/downsample_pcd" "$vlp16" "$work/out_vlp16.pcd" > /dev/null 2> "$work/vlp16.err" ||
    fail "the example failed on $vlp16: $(cat "$work/vlp16.err")"
  if grep -q "Failed to find match" "$work/vlp16.err"; then fail "PCL warned on the VLP-16 frame: $(cat "$work/vlp16.err")"; fi
  /usr/bin/python3 - "$work/out_vlp16.pcd" <<'PY' || fail "the example's output lost the VLP-16's intensity"
import struct, sys
data = open(sys.argv[1], "rb").read()
head, body = data.split(b"DATA binary\n", 1)
fields = dict(l.split(None, 1) for l in head.decode().splitlines() if l and not l.startswith("#"))
names, sizes = fields["FIELDS"].split(), [int(s) for s in fields["SIZE"].split()]
counts = [int(c) for c in fields["COUNT"].split()]
step = sum(s * c for s, c in zip(sizes, counts))
at = sum(s * c for n, s, c in zip(names, sizes, counts) if names.index(n) < names.index("intensity"))
values = {struct.unpack_from("<f", body, i * step + at)[0] for i in range(int(fields["POINTS"]))}
assert len(values) > 10, "intensity values: %s" % sorted(values)[:20]
PY
fi
# The output must not be the input: the example refuses it.
if "$work/example/downsample_pcd" "$work/out.pcd" "$work/out.pcd" 2> /dev/null; then fail "the example overwrote its input"; fi

# A project that asks for hpds::core alone: C++ only (no C for VTK's MPI), and PCL is not looked up for it.
"$src/test/package/use_core_only.sh" "$src" "$prefix" "$work/core_example" "${example_flags[@]}" ||
  fail "the core-only example failed against the prefix"
# A catkin package that asks for hpds as a component (find_package(catkin REQUIRED COMPONENTS hpds)): catkin takes the
# config CMake finds first, lib/cmake/hpds, whose hpds_INCLUDE_DIRS / hpds_LIBRARIES were unset, so a package
# built against an install space did not compile (hpds/hpds.hpp not found).
if [ "$node" = ON ]; then
  mkdir -p "$work/catkin_user"
  cat > "$work/catkin_user/CMakeLists.txt" <<'CMAKE'
cmake_minimum_required(VERSION 3.16)
project(catkin_user C CXX)
set(CMAKE_CXX_STANDARD 17)
find_package(catkin REQUIRED COMPONENTS hpds)
message(STATUS "catkin_INCLUDE_DIRS=${catkin_INCLUDE_DIRS}")
message(STATUS "catkin_LIBRARIES=${catkin_LIBRARIES}")
include_directories(${catkin_INCLUDE_DIRS})
add_executable(use_hpds use_hpds.cpp)
target_link_libraries(use_hpds ${catkin_LIBRARIES})
CMAKE
  cp "$work/core_pc.cpp" "$work/catkin_user/use_hpds.cpp" 2> /dev/null || cat > "$work/catkin_user/use_hpds.cpp" <<'CPP'
#include <hpds/hpds.hpp>
int main() { return hpds::downsample(std::vector<Eigen::Vector3f>(3, Eigen::Vector3f(1, 2, 3))).size() == 1 ? 0 : 1; }
CPP
  # catkin's scripts need Debian's Python (with the ROS modules), as a catkin workspace's build does.
  PATH=/usr/bin:$PATH cmake -S "$work/catkin_user" -B "$work/catkin_user/build" -DCMAKE_PREFIX_PATH="$prefix" \
    -DPYTHON_EXECUTABLE=/usr/bin/python3 "${san_flags[@]}" \
    > "$work/catkin_user.log" 2>&1 || { cat "$work/catkin_user.log"; fail "a catkin package asking for hpds does not configure"; }
  grep -q "catkin_INCLUDE_DIRS=$prefix/include" "$work/catkin_user.log" ||
    { cat "$work/catkin_user.log"; fail "catkin_INCLUDE_DIRS lacks $prefix/include"; }
  grep -q "catkin_LIBRARIES=.*hpds::core" "$work/catkin_user.log" ||
    { cat "$work/catkin_user.log"; fail "catkin_LIBRARIES lacks hpds::core"; }
  cmake --build "$work/catkin_user/build" > "$work/catkin_user-build.log" 2>&1 ||
    { cat "$work/catkin_user-build.log"; fail "a catkin package asking for hpds does not build"; }
  "$work/catkin_user/build/use_hpds" > /dev/null || fail "a catkin package's program using hpds fails"
fi
echo "install_and_use: OK ($samples samples of $points points)"
rm -rf "$work"

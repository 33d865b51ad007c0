#!/usr/bin/env bash
# The launch files resolve (no master needed): each hpds.launch variant starts the expected nodes and commands,
# replay.launch adds the player. The rostests run hpds.launch for real; this covers replay.launch and the args.
set -euo pipefail
fail() { echo "launch_check: $*" >&2; exit 1; }
nodes() { roslaunch --nodes hpds "$@" | sort | tr '\n' ' '; }
args() { roslaunch --args "$1" hpds "${@:2}"; }

[ "$(nodes hpds.launch)" = "/hpds " ] || fail "hpds.launch: $(nodes hpds.launch)"
args /hpds hpds.launch | grep -q "lib/hpds/hpds_node ~input:=/velodyne_points" || fail "node command: $(args /hpds hpds.launch)"
args /hpds hpds.launch manager:=standalone | grep -q "nodelet standalone hpds/HpdsNodelet" || fail "standalone"
args /hpds hpds.launch manager:=m | grep -q "nodelet load hpds/HpdsNodelet m" || fail "load"
[ "$(nodes hpds.launch manager:=m start_manager:=true)" = "/hpds /m " ] || fail "start_manager"
[ "$(nodes hpds.launch manager:=m)" = "/hpds " ] || fail "manager not started unless asked"
[ "$(nodes replay.launch bag:=x.bag)" = "/hpds /player " ] || fail "replay.launch: $(nodes replay.launch bag:=x.bag)"
args /player replay.launch bag:=/d/x.bag rate:=2 | grep -q "play --clock -d 2.0 -r 2 /d/x.bag" || fail "player args"

# Only replay.launch's bag is required: an argument with an empty default would be listed as required too.
required() { roslaunch "$@" --ros-args | sed -n '/^Required Arguments:/,/^Optional Arguments:/p' | grep '^  ' | sort | tr -d '\n'; }
[ -z "$(required hpds hpds.launch)" ] || fail "hpds.launch lists required arguments: $(required hpds hpds.launch)"
[ "$(required hpds replay.launch)" = "  bag: bag file to play" ] || fail "replay.launch required: $(required hpds replay.launch)"
! roslaunch hpds hpds.launch --ros-args | grep -q undocumented || fail "hpds.launch has undocumented arguments"

# spacing and normals reach the parameters; left at "config", the config file's values stay.
params() { roslaunch --dump-params hpds "$@"; }
p=$(params hpds.launch spacing:=0.25 normals:=false)
echo "$p" | grep -qx "/hpds/output/spacing: 0.25" || fail "spacing:=0.25 -> $(echo "$p" | grep spacing)"
echo "$p" | grep -qx "/hpds/output/level: -1" || fail "spacing:= must make the spacing choose the level"
echo "$p" | grep -qx "/hpds/normals/enabled: false" || fail "normals:=false -> $(echo "$p" | grep enabled)"
p=$(params hpds.launch config:="$(dirname "$0")/params_scan.yaml")
echo "$p" | grep -qx "/hpds/output/level: 4" || fail "config's output level overridden without spacing:="
p=$(params replay.launch bag:=x.bag spacing:=0.3 normals:=true)
echo "$p" | grep -qx "/hpds/output/spacing: 0.3" || fail "replay.launch spacing:="
echo "$p" | grep -qx "/hpds/normals/enabled: true" || fail "replay.launch normals:="

# Every repository file a launch file's comments point to exists.
root=$(cd "$(dirname "$0")/../.." && pwd)
for launch in "$root"/launch/*.launch; do
  for ref in $(grep -oE '[A-Za-z_./-]+\.(md|yaml)' "$launch" | grep '/' | sort -u); do
    [ -e "$root/$ref" ] || fail "$(basename "$launch") points to $ref, which does not exist"
  done
done
echo "launch_check: ok"

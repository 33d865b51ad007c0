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
echo "launch_check: ok"

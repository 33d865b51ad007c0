#!/usr/bin/env bash
# `hpds replay` on the synthetic bag: writes the bag the node is compared with (test_replay/cli.bag), checks the
# drop counts in --stats and that two runs give byte-identical PLY files (determinism).
# Usage: replay_cli_test.sh HPDS MAKE_REPLAY_BAG WORKDIR CONFIG
set -euo pipefail
hpds=$1 make_bag=$2 work=$3 config=$4
rm -rf "$work" && mkdir -p "$work"
"$make_bag" "$work/input.bag" 6
common=(--topic /velodyne_points --config "$config")
"$hpds" replay "$work/input.bag" "${common[@]}" -o "$work/cli.bag" --stats "$work/stats.json"
grep -q '"processed": 6' "$work/stats.json" || { echo "expected 6 processed frames"; cat "$work/stats.json"; exit 1; }
grep -q '"data_size": 1' "$work/stats.json" || { echo "expected the truncated cloud counted"; cat "$work/stats.json"; exit 1; }
# The outputs' normals of every frame are estimated while the frame is processed: counted as normals, not insertion.
/usr/bin/python3 - "$work/stats.json" <<'PY' || { cat "$work/stats.json"; exit 1; }
import json, sys
s = json.load(open(sys.argv[1]))["seconds"]
assert s["normals"] > 0.0 and s["insert"] > 0.0, "seconds: %s" % s
PY
# The input's tf goes into the output bag with its connection headers: /tf_static stays latched (rosbag play then
# latches it, so a tf listener started after playback began still gets the static transforms).
/usr/bin/python3 - "$work/input.bag" "$work/cli.bag" <<'PY' || exit 1
import sys, rosbag
def latching(path):
    with rosbag.Bag(path) as b:
        return sorted({bytes(c.header.get("latching", b"0")).decode() for c in b._get_connections(["/tf_static"])})
inp, out = latching(sys.argv[1]), latching(sys.argv[2])
assert inp == ["1"], "input /tf_static latching: %s" % inp
assert out == inp, "output /tf_static latching %s, input %s" % (out, inp)
# Each output topic numbers its messages from 0, as roscpp numbers the live node's (all were 0).
with rosbag.Bag(sys.argv[2]) as b:
    seqs = {}
    for topic, msg, _ in b.read_messages():
        if msg._type == "sensor_msgs/PointCloud2":
            seqs.setdefault(topic, []).append(msg.header.seq)
assert seqs and all(v == list(range(len(v))) for v in seqs.values()), "header.seq per topic: %s" % seqs
PY
# --stats of a bag counts the ~output messages' points and their invalid normals (both were 0 for bags).
/usr/bin/python3 - "$work/cli.bag" "$work/stats.json" <<'PY' || exit 1
import json, math, sys, rosbag
from sensor_msgs import point_cloud2
points = invalid = 0
with rosbag.Bag(sys.argv[1]) as b:
    for topic, msg, _ in b.read_messages():
        if topic.endswith("/output"):
            points += msg.width * msg.height
            invalid += sum(1 for (nx,) in point_cloud2.read_points(msg, field_names=["normal_x"]) if math.isnan(nx))
s = json.load(open(sys.argv[2]))
assert points > 0 and s["output_points"] == points, "output_points %s, the bag's ~output %d" % (s["output_points"], points)
assert s["invalid_normals"] == invalid, "invalid_normals %s, the bag's ~output %d" % (s["invalid_normals"], invalid)
PY
"$hpds" replay "$work/input.bag" "${common[@]}" -o "$work/map1.ply" > /dev/null
"$hpds" replay "$work/input.bag" "${common[@]}" -o "$work/map2.ply" --threads 2 > /dev/null
cmp "$work/map1.ply" "$work/map2.ply" || { echo "replay is not deterministic"; exit 1; }
# A relocalisation in the bag's tf (poses 40 m off from frame 3 on): processed, said on stderr and counted; the
# bag without one says nothing of the kind.
"$make_bag" "$work/jump.bag" 6 3 > /dev/null
"$hpds" replay "$work/jump.bag" "${common[@]}" -o "$work/jump.ply" --stats "$work/jump.json" > /dev/null 2> "$work/jump.log"
grep -q "the sensor moved 4[0-9.]* m in 0.1 s between two frames" "$work/jump.log" || { cat "$work/jump.log"; exit 1; }
[ "$(grep -c "the sensor moved" "$work/jump.log")" = 1 ] || { echo "expected one pose jump"; cat "$work/jump.log"; exit 1; }
grep -q '"pose_jumps": 1' "$work/jump.json" || { echo "expected pose_jumps 1"; cat "$work/jump.json"; exit 1; }
grep -q '"pose_jumps": 0' "$work/stats.json" || { echo "expected pose_jumps 0"; cat "$work/stats.json"; exit 1; }
"$hpds" replay "$work/input.bag" "${common[@]}" -o "$work/nojump.ply" > /dev/null 2> "$work/nojump.log"
if grep -q "the sensor moved" "$work/nojump.log"; then cat "$work/nojump.log"; exit 1; fi
# The PLY records its sampling: verify takes the cell and levels from its header.
"$hpds" verify "$work/map1.ply" > "$work/verify.log" || { cat "$work/verify.log"; exit 1; }
grep -q "as its header records: level-0 cell" "$work/verify.log" || { cat "$work/verify.log"; exit 1; }
# --sensor-frame (ros.sensor_frame): the clouds are in the sensor's own frame here, so naming it changes nothing; a
# frame tf does not have drops every frame; clouds in the fixed frame itself without it are said to have the sensor
# at that frame's origin.
"$hpds" replay "$work/input.bag" "${common[@]}" --sensor-frame /velodyne -o "$work/map3.ply" > /dev/null
cmp "$work/map1.ply" "$work/map3.ply" || { echo "--sensor-frame of the clouds' own frame changed the map"; exit 1; }
if "$hpds" replay "$work/input.bag" "${common[@]}" --sensor-frame nowhere -o "$work/map4.ply" > "$work/sf.log" 2>&1; then
  echo "a sensor frame tf does not have must drop every frame"; exit 1
fi
grep -q "6 without transform" "$work/sf.log" || { cat "$work/sf.log"; exit 1; }
"$hpds" replay "$work/input.bag" "${common[@]}" --fixed-frame velodyne -o "$work/map5.ply" > /dev/null 2> "$work/fixed.log"
grep -q "clouds arrive in the fixed frame 'velodyne' itself" "$work/fixed.log" || { cat "$work/fixed.log"; exit 1; }
# Scan mode into one PLY, and a fixed frame that the bag does not have: every frame dropped, exit status 1 with an
# error line, and the existing outputs of an earlier run (bag and PLY) left as they were.
"$hpds" replay "$work/input.bag" "${common[@]}" --mode scan -o "$work/scan.ply" --stats "$work/scan.json" > "$work/scan.log"
# Its --stats counts the PLY's points and the NaN normals among them.
/usr/bin/python3 - "$work/scan.ply" "$work/scan.json" <<'PY' || exit 1
import json, sys
data = open(sys.argv[1], "rb").read()
header = data[:data.index(b"end_header\n")].decode().splitlines()
count = int(next(l.split()[2] for l in header if l.startswith("element vertex")))
s = json.load(open(sys.argv[2]))
assert count > 0 and s["output_points"] == count, "output_points %s, the PLY %d" % (s["output_points"], count)
PY
# Scan mode looks no transform up: its summary names no target frame.
grep -q "^messages: .* 6 processed" "$work/scan.log" || { cat "$work/scan.log"; exit 1; }
grep -q "without transform" "$work/scan.log" && { echo "scan-mode summary names a transform"; cat "$work/scan.log"; exit 1; }
# With --output-frame it looks transforms up, and says so, but keeps no map.
"$hpds" replay "$work/input.bag" "${common[@]}" --mode scan --output-frame velodyne -o "$work/scan_of.ply" > "$work/scan_of.log"
grep -q "0 without transform to 'velodyne'" "$work/scan_of.log" || { cat "$work/scan_of.log"; exit 1; }
grep -q "other fields than the map" "$work/scan_of.log" && { echo "scan-mode summary names a map"; cat "$work/scan_of.log"; exit 1; }
# Its frames stay apart in the one PLY (the field `frame`, as `hpds sample` writes for several frames): each verifies
# on its own at the config's cell (4 m); without the field the frames read as one sampling, full of violations.
head -c 2000 "$work/scan.ply" | grep -aq "^property uint frame$" || { echo "scan-mode PLY without a frame field"; exit 1; }
"$hpds" verify "$work/scan.ply" --cell-size 4 --max-depth 7 > "$work/verify.log" ||
  { echo "scan-mode PLY does not verify frame by frame"; cat "$work/verify.log"; exit 1; }
"$hpds" verify "$work/scan.ply" --cell-size 4 --max-depth 7 --frame 5 > /dev/null ||
  { echo "the last frame of the scan-mode PLY cannot be checked alone"; exit 1; }
cp "$work/cli.bag" "$work/prev.bag"
for out in prev.bag scan.ply; do
  before=$(md5sum < "$work/$out")
  if "$hpds" replay "$work/input.bag" "${common[@]}" --fixed-frame nowhere -o "$work/$out" > "$work/none.log" 2>&1; then
    echo "a replay without transforms must fail"; exit 1
  fi
  grep -q "hpds: error: no frame processed: .*6 without transform to 'nowhere'.*nothing written" "$work/none.log" ||
    { cat "$work/none.log"; exit 1; }
  [ "$(md5sum < "$work/$out")" = "$before" ] || { echo "a failed replay changed the existing $out"; exit 1; }
done
ls "$work" | grep -q hpds-tmp && { echo "a failed replay left a temporary file"; ls "$work"; exit 1; }
# The input bag is never an output: refused before it is opened, and left intact.
before=$(md5sum < "$work/input.bag")
if "$hpds" replay "$work/input.bag" "${common[@]}" -o "$work/./input.bag" > "$work/self.log" 2>&1; then
  echo "replaying a bag onto itself must be refused"; exit 1
fi
grep -q "is the input '$work/input.bag'" "$work/self.log" || { cat "$work/self.log"; exit 1; }
[ "$(md5sum < "$work/input.bag")" = "$before" ] || { echo "the input bag changed"; exit 1; }
echo "replay_cli_test: ok"

#!/usr/bin/env bash
# `hpds synth --bag`: the bag a user without a lidar plays into replay.launch.
#   write:  writes WORKDIR/synth.bag beside the PCD folder and reads it back with rosbag: one cloud per frame on the
#           topic, in the sensor frame, with the synthetic fields, stamps one frame period apart, each with its
#           /tf odom -> sensor at the same stamp equal to poses.txt; --topic / --frame-id; the output-path rules.
#   replay: `hpds replay` of that bag in map mode (fixed frame odom) processes every frame and drops none.
# Usage: synth_bag_test.sh HPDS WORKDIR write|replay
set -euo pipefail
hpds=$1 work=$2 step=$3
frames=5

fail() { echo "synth_bag_test: $*" >&2; exit 1; }

if [ "$step" = write ]; then
  rm -rf "$work" && mkdir -p "$work"
  "$hpds" synth -o "$work/synth" --frames $frames --beams 16 --azimuth-steps 900 --bag "$work/synth.bag" \
    > "$work/synth.log" || { cat "$work/synth.log"; fail "hpds synth --bag failed"; }
  grep -q "^wrote $work/synth.bag (/velodyne_points in frame velodyne, /tf odom -> velodyne)" "$work/synth.log" ||
    { cat "$work/synth.log"; fail "no line naming the bag"; }
  "$hpds" synth -o "$work/custom" --frames 2 --beams 4 --azimuth-steps 90 --bag "$work/custom.bag" \
    --topic /points --frame-id lidar_top > /dev/null

  # The bag's types come from its own message definitions (genpy), so no message package needs to be installed.
  /usr/bin/python3 - "$work" $frames <<'PY' || fail "the bag read back is not as expected"
import math, sys
import rosbag

work, frames = sys.argv[1], int(sys.argv[2])

def check(path, topic, frame_id, count, height, width, poses=None):
    with rosbag.Bag(path) as bag:
        topics = bag.get_type_and_topic_info().topics
        assert set(topics) == {topic, "/tf"}, topics
        assert topics[topic].msg_type == "sensor_msgs/PointCloud2", topics[topic]
        assert topics["/tf"].msg_type == "tf2_msgs/TFMessage", topics["/tf"]
        clouds = list(bag.read_messages(topics=[topic]))
        tfs = list(bag.read_messages(topics=["/tf"]))
    assert len(clouds) == count, "%d clouds, expected %d" % (len(clouds), count)
    assert len(tfs) == count, "%d /tf messages, expected %d" % (len(tfs), count)
    stamps = []
    for i, (_, msg, t) in enumerate(clouds):
        h = msg.header
        assert h.frame_id == frame_id, h.frame_id
        assert h.seq == i, "seq %d of cloud %d" % (h.seq, i)
        assert t == h.stamp, "bag time %s, stamp %s" % (t, h.stamp)
        stamps.append(h.stamp.to_sec())
        fields = [(f.name, f.offset, f.datatype, f.count) for f in msg.fields]
        # float32 = 7, uint16 = 4: the synthetic record with its 2 padding bytes after ring (point_step 24).
        assert fields == [("x", 0, 7, 1), ("y", 4, 7, 1), ("z", 8, 7, 1), ("intensity", 12, 7, 1),
                          ("ring", 16, 4, 1), ("time", 20, 7, 1)], fields
        assert (msg.height, msg.width, msg.point_step) == (height, width, 24), (msg.height, msg.width)
        assert msg.row_step == width * 24 and len(msg.data) == height * width * 24 and not msg.is_bigendian
    assert stamps[0] > 0, "a zero stamp means 'latest' to tf"
    for a, b in zip(stamps, stamps[1:]):
        assert b > a and abs(b - a - 0.1) < 1e-6, "stamps %r: not 10 Hz" % stamps
    for i, (_, msg, t) in enumerate(tfs):
        assert len(msg.transforms) == 1, msg
        tr = msg.transforms[0]
        assert (tr.header.frame_id, tr.child_frame_id) == ("odom", frame_id), tr
        assert abs(tr.header.stamp.to_sec() - stamps[i]) < 1e-9 and t == tr.header.stamp, tr.header
        if poses:
            p = tr.transform.translation
            assert math.dist((p.x, p.y, p.z), poses[i]) < 1e-6, "frame %d: %s vs %s" % (i, p, poses[i])

# poses.txt: KITTI rows (3x4 row-major); the translation is the last column.
poses = []
for line in open(work + "/synth/poses.txt"):
    v = [float(x) for x in line.split()]
    poses.append((v[3], v[7], v[11]))
assert len(poses) == frames and poses[-1] != poses[0], poses
check(work + "/synth.bag", "/velodyne_points", "velodyne", frames, 16, 900, poses)
check(work + "/custom.bag", "/points", "lidar_top", 2, 4, 90)
PY

  # hpds never destroys data: the bag is an output like any other, checked before any work.
  before=$(md5sum < "$work/synth/poses.txt")
  ln -s "$work/synth/poses.txt" "$work/link.bag"
  if "$hpds" synth -o "$work/synth" --frames $frames --bag "$work/link.bag" > "$work/self.log" 2>&1; then
    fail "a bag that is the run's own poses.txt must be refused"
  fi
  grep -q "hpds: error: .*is also the output of --bag" "$work/self.log" || { cat "$work/self.log"; exit 1; }
  [ "$(md5sum < "$work/synth/poses.txt")" = "$before" ] || fail "a refused run changed poses.txt"
  if "$hpds" synth -o "$work/other" --frames 1 --bag "$work/synth.pcd" > "$work/ext.log" 2>&1; then
    fail "--bag without .bag must be refused"
  fi
  grep -q "hpds: error: --bag: .* must end in .bag" "$work/ext.log" || { cat "$work/ext.log"; exit 1; }
  [ ! -e "$work/other" ] || fail "a refused run created its output folder"
  # --topic and --frame-id only mean something with --bag: a usage error (exit 2) without it.
  set +e
  "$hpds" synth -o "$work/other" --frames 1 --topic /points > "$work/usage.log" 2>&1
  rc=$?
  set -e
  [ $rc = 2 ] && grep -q "requires --bag" "$work/usage.log" || { cat "$work/usage.log"; fail "--topic alone: rc $rc"; }
  ls "$work" | grep -q hpds-tmp && { ls "$work"; fail "a temporary file was left"; }
  echo "synth_bag_test write: ok"
elif [ "$step" = replay ]; then
  [ -f "$work/synth.bag" ] || fail "no $work/synth.bag: ros.synth_bag writes it"
  "$hpds" replay "$work/synth.bag" --topic /velodyne_points --mode map --fixed-frame odom --spacing 0.2 \
    -o "$work/replay.bag" --stats "$work/replay.json" > "$work/replay.log" || { cat "$work/replay.log"; exit 1; }
  /usr/bin/python3 - "$work/replay.json" $frames <<'PY' || { cat "$work/replay.json"; fail "frames went unprocessed"; }
import json, sys
m = json.load(open(sys.argv[1]))["messages"]
frames = int(sys.argv[2])
assert m["received"] == frames and m["processed"] == frames, m
assert m["empty"] == 0 and m["not_pointcloud2"] == 0, m
dropped = dict(m["dropped"])
malformed = dropped.pop("malformed")
assert not any(malformed.values()) and not any(dropped.values()), m["dropped"]
PY
  grep -q "^messages: $frames on /velodyne_points, $frames processed, 0 malformed, 0 without transform to 'odom'" \
    "$work/replay.log" || { cat "$work/replay.log"; fail "unexpected replay summary"; }
  echo "synth_bag_test replay: ok"
else
  fail "unknown step '$step' (write or replay)"
fi

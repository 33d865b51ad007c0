// `hpds replay BAG --topic T ... -o OUT.bag|OUT.ply`: the ROS node's processing, offline, without a master.
//
// Contract
// - Reads sensor_msgs/PointCloud2 messages of --topic from the bag in bag order and runs them through the same
//   FrameProcessor as the node (validation, tf lookup at the message stamp, pipeline, outputs), so a bag replayed
//   here and through the node (without drops) gives the same samples. Deterministic: same bag and options, same
//   output bytes.
// - Transforms (map mode, or scan mode with --output-frame) come from the bag's /tf and /tf_static, all loaded
//   into a tf2::BufferCore before the first cloud: a transform recorded shortly after its cloud is still found.
// - Output by extension: .bag gets <ns>/output, <ns>/new_samples, <ns>/local_map, <ns>/level_<D> (what the node
//   publishes, at the input message's bag time) plus the input /tf and /tf_static; .ply gets the final map's
//   output levels (map mode) or every frame's ~output concatenated (scan mode).
// - Settings: --config takes the node's YAML (config keys plus an optional `ros:` section); sampling flags
//   override it, then the ROS flags (--fixed-frame, ...). Invalid values fail before the bag is read.
// - Messages that the node would drop (malformed, no transform, other fields than the map) are dropped and
//   counted the same way, and gaps in the recorded header.seq as lost_upstream; the counts are printed and written
//   to --stats. A replay that processes no frame fails (exit 1, the counts in the error) and writes nothing.
// - Output paths are checked before the bag is opened (OutputPaths.hpp: the bag is never its own output) and written
//   atomically: an existing output is replaced only by a complete one.
// This header is ROS-free so that the CLI main can include it.
#pragma once

#include <CLI/CLI.hpp>

namespace hpds::cli {

void addReplayCommand(CLI::App &app);

}  // namespace hpds::cli

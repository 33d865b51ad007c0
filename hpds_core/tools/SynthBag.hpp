// `hpds synth --bag OUT.bag`: the synthetic stream as a bag that `roslaunch hpds replay.launch` plays as it is, for a
// user with neither a lidar nor a recording.
//
// Contract
// - Per frame, in frame order and at its stamp (kSynthBagStart + frame.stamp, so one frame_period apart):
//   `/tf` (tf2_msgs/TFMessage) with one transform kSynthBagFixedFrame -> frame_id, the frame's sensor_to_fixed,
//   then sensor_msgs/PointCloud2 on `topic` in `frame_id` with the frame's points as they are (hpds_node's
//   toRosCloud: the same fields, offsets and padding as the PCD frames) and header.seq counting from 0.
// - Written atomically (AtomicFile): nothing at the target until commit(); dropped before it, the writer leaves
//   the target as it was and no temporary behind. The path is checked by the caller (OutputPaths.hpp).
// This header is ROS-free: the writer is compiled into the `hpds` executable only in a build with ROS, as `hpds
// replay` is, and handed to the synth command as a function (Commands.hpp).
#pragma once

#include <memory>
#include <string>

#include "hpds/points/Frame.hpp"

namespace hpds::cli {

/// The frame the synthetic poses are given in: replay.launch's default fixed_frame.
inline constexpr const char *kSynthBagFixedFrame = "odom";
/// [s] stamp of frame 0. Not 0: tf reads a zero stamp as "the latest transform".
inline constexpr double kSynthBagStart = 1000.0;

struct SynthBagOptions {
  std::string path;                        ///< the bag (--bag)
  std::string topic = "/velodyne_points";  ///< PointCloud2 topic (--topic)
  std::string frame_id = "velodyne";       ///< the clouds' frame and the tf child frame (--frame-id)
};

class SynthBagWriter {
 public:
  virtual ~SynthBagWriter() = default;
  /// Appends one frame (its /tf and its cloud, see the contract).
  virtual void write(const Frame &frame) = 0;
  /// Closes the bag and syncs it: every write error is reported here, the target is still untouched.
  virtual void finish() = 0;
  /// Puts the bag in place; after finish().
  virtual void commit() = 0;
};

/// Opens the bag under a temporary name; std::runtime_error naming --bag when it cannot be created.
using SynthBagOpener = std::unique_ptr<SynthBagWriter> (*)(const SynthBagOptions &options);

/// The ROS implementation (SynthBag.cpp); defined only where `hpds` is built with ROS (HPDS_WITH_ROS).
[[nodiscard]] std::unique_ptr<SynthBagWriter> openSynthBag(const SynthBagOptions &options);

}  // namespace hpds::cli

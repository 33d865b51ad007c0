// Frame: one sensor sweep as it enters the pipeline.
//
// Contract
// - `points` are in metres, with x/y/z fields of any float or integer type plus any other fields: in the sensor frame,
//   or in a frame where the sensor stood at `viewpoint` (below).
// - `sensor_to_fixed` maps sensor coordinates into the fixed (map) frame; identity in scan mode or without poses.
// - `viewpoint` is where the sensor was among `points` (a PCD's VIEWPOINT: a cloud saved in another frame keeps its
//   sensor position there, and PCL's normal estimation faces it). sensor_to_fixed * viewpoint is the position that
//   normals of this frame's samples are oriented toward and map eviction measures from; input.min_range/max_range
//   are measured from `viewpoint`. It must be finite.
// - `stamp` is seconds (any epoch); it is carried to outputs, never interpreted.
#pragma once

#include <Eigen/Geometry>
#include <cstddef>
#include <vector>

#include "hpds/points/PointBuffer.hpp"

namespace hpds {

/// Eigen::Isometry3d is aligned as the compiler's vector flags say: 16 bytes at x86-64's baseline (the library's), 32
/// with -mavx, 64 with -mavx512f. A program built with -march=native laid a Frame out otherwise than the library
/// (sensor_to_fixed at byte 96 instead of 80), which then read the pose from the wrong bytes. Aligned to 64 here, the
/// member has one offset, and Frame one size, whatever the flags of either side.
inline constexpr std::size_t kPoseMemberAlignment = 64;

struct Frame {
  PointBuffer points;
  double stamp = 0.0;
  alignas(kPoseMemberAlignment) Eigen::Isometry3d sensor_to_fixed = Eigen::Isometry3d::Identity();
  Eigen::Vector3d viewpoint = Eigen::Vector3d::Zero();
};

/// A Frame of bare positions (sensor frame, metres) for Pipeline::addFrame, e.g. from a driver's callback: x y z
/// (float32, or float64 for the Vector3d overload) and a uint32 field `index`, the point's position in `points`,
/// so that every sample's record (Hierarchy::record, readAsDouble on the field "index") names its input point.
/// The hpds::downsample one-call API builds its frames with it. std::invalid_argument for 2^32 points or more.
[[nodiscard]] Frame frameFromPoints(const std::vector<Eigen::Vector3f> &points,
                                    const Eigen::Isometry3d &sensor_to_fixed = Eigen::Isometry3d::Identity(),
                                    double stamp = 0.0);
[[nodiscard]] Frame frameFromPoints(const std::vector<Eigen::Vector3d> &points,
                                    const Eigen::Isometry3d &sensor_to_fixed = Eigen::Isometry3d::Identity(),
                                    double stamp = 0.0);

}  // namespace hpds

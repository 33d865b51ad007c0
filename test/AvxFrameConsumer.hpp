// What test_eigen_alignment asks of a translation unit built with -mavx (AvxFrameConsumer.cpp). Only plain types
// cross between the two, so that this header means the same on both sides.
#pragma once

#include <Eigen/Core>
#include <cstddef>
#include <string>
#include <vector>

namespace avx_consumer {

struct FrameLayout {
  std::size_t size, pose_offset, viewpoint_offset, isometry_alignment;
};
/// hpds::Frame as that translation unit lays it out.
FrameLayout frameLayout();
/// Samples of a map built from one frame of `points` posed by `translation`, through hpds::Pipeline.
std::size_t mapSamples(const std::vector<Eigen::Vector3f> &points, const Eigen::Vector3d &translation);
/// hpds::readKittiPoses(path) from there: its error, or "".
std::string readPosesError(const std::string &path);

}  // namespace avx_consumer

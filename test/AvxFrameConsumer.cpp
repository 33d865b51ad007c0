// A translation unit built with -mavx, as a user's program built with -march=native is: Eigen aligns
// Eigen::Isometry3d to 32 bytes here and to 16 in the library. test_eigen_alignment calls it.
#include "AvxFrameConsumer.hpp"

#include <stdexcept>

#include "hpds/io/PoseFile.hpp"
#include "hpds/pipeline/Pipeline.hpp"

namespace avx_consumer {

FrameLayout frameLayout() {
  hpds::Frame f;
  const auto *base = reinterpret_cast<const char *>(&f);
  return {sizeof(hpds::Frame), static_cast<std::size_t>(reinterpret_cast<const char *>(&f.sensor_to_fixed) - base),
          static_cast<std::size_t>(reinterpret_cast<const char *>(&f.viewpoint) - base), alignof(Eigen::Isometry3d)};
}

std::size_t mapSamples(const std::vector<Eigen::Vector3f> &points, const Eigen::Vector3d &translation) {
  hpds::HpdsConfig config;
  config.mode = hpds::Mode::Map;
  config.normals.enabled = false;
  hpds::Pipeline pipeline(config);
  Eigen::Isometry3d pose = Eigen::Isometry3d::Identity();
  pose.translation() = translation;
  hpds::Frame frame = hpds::frameFromPoints(points, pose, 1.0);
  pipeline.addFrame(frame);
  return pipeline.hierarchy().sampleCount();
}

std::string readPosesError(const std::string &path) {
  try {
    const std::vector<Eigen::Isometry3d> poses = hpds::readKittiPoses(path);
    return poses.empty() ? "no pose" : "";
  } catch (const std::invalid_argument &e) {
    return e.what();
  }
}

}  // namespace avx_consumer
